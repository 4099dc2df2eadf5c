"""cedar-solve worker: runs inside its own venv (cedar-solve 0.5.1 pins numpy < 2), driven over
stdin/stdout by ``bench.peers.cedar.CedarSolver``. Standalone: imports only cedar-solve.

Protocol: one JSON object per line in, one per line out.

- ``{"cmd": "catalog", "path": ..., "rows": [[hip, ra_deg, dec_deg, vmag], ...]}`` writes a
  star list in the published ``hip_main.dat`` layout (pipe-separated; HIP in field 1, Vmag in
  5, RA/Dec in degrees in 8/9, proper motions in 12/13, zero here: the positions are already at
  the benchmark's epoch) so that ``generate_database`` reads exactly the stars skyfix uses.
- ``{"cmd": "build", "catalog": path, "save_as": path, "max_fov": deg, "min_fov": deg|null,
  "mag": V}`` -> ``{"seconds": s}``: ``Tetra3.generate_database`` (no proper-motion propagation).
- ``{"cmd": "load", "path": path}`` -> ``{"seconds": s, "patterns": n, "props": {...}}``.
- ``{"cmd": "solve", "yx": [[y, x], ...], "size": [h, w], "fov": deg, "fov_err": deg|null,
  "timeout_ms": ms, "match_max_error": e}`` -> ``{"ok": bool, "ms": in-process wall time of
  solve_from_centroids, "t_solve": cedar's own T_solve, "ra", "dec", "roll", "fov",
  "ids": [...], "yx": [[y, x], ...]}``. Centroids are brightest first, (y, x) from the top-left
  corner of the image (cedar's convention: the image centre is (h/2, w/2)).
"""

import json
import os
import sys
import time

for _k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_k] = "1"

import numpy as np  # noqa: E402
import tetra3  # noqa: E402

T3 = None


def _catalog(msg):
    with open(msg["path"], "w") as fh:
        for hip, ra, dec, mag in msg["rows"]:
            fields = ["H", str(int(hip)), "", "", "", "%.3f" % mag, "", "", "%.9f" % ra, "%.9f" % dec,
                      "", "", "0", "0"]
            fh.write("|".join(fields) + "\n")
    return {"rows": len(msg["rows"])}


def _build(msg):
    global T3
    t = tetra3.Tetra3(load_database=None)
    t0 = time.perf_counter()
    t.generate_database(max_fov=msg["max_fov"], min_fov=msg.get("min_fov"), save_as=msg["save_as"],
                        star_catalog=msg["catalog"], star_max_magnitude=msg["mag"],
                        epoch_proper_motion=None)
    T3 = t
    return {"seconds": time.perf_counter() - t0}


def _load(msg):
    global T3
    t0 = time.perf_counter()
    T3 = tetra3.Tetra3(load_database=msg["path"])
    secs = time.perf_counter() - t0
    props = {k: np.asarray(v).tolist() for k, v in T3.database_properties.items()}
    return {"seconds": secs, "patterns": int(T3.num_patterns), "props": props,
            "stars": int(len(T3.star_table))}


def _solve(msg):
    yx = np.asarray(msg["yx"], dtype=np.float64).reshape(-1, 2)
    t0 = time.perf_counter()
    r = T3.solve_from_centroids(yx, msg["size"], fov_estimate=msg["fov"], fov_max_error=msg.get("fov_err"),
                                solve_timeout=msg["timeout_ms"], match_max_error=msg["match_max_error"],
                                return_matches=True)
    ms = (time.perf_counter() - t0) * 1e3
    out = {"ok": r.get("RA") is not None, "ms": ms, "t_solve": r.get("T_solve"), "status": r.get("status")}
    if out["ok"]:
        out.update(ra=float(r["RA"]), dec=float(r["Dec"]), roll=float(r["Roll"]), fov=float(r["FOV"]),
                   ids=[int(i) for i in r["matched_catID"]],
                   yx=[[float(a), float(b)] for a, b in r["matched_centroids"]])
    return out


HANDLERS = {"catalog": _catalog, "build": _build, "load": _load, "solve": _solve}


def main():
    for line in sys.stdin:
        if not line.strip():
            continue
        msg = json.loads(line)
        try:
            out = HANDLERS[msg["cmd"]](msg)
        except Exception as exc:  # report, keep serving
            out = {"error": "%s: %s" % (type(exc).__name__, exc)}
        sys.stdout.write(json.dumps(out) + "\n")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
