"""A camera whose field is off: frames identified and time, skyfix as given, skyfix searching
focal lengths (``fov_max_error_deg``) and tetra3rs, on the same frames in one run.

    python -m bench.bench_fov --frames 40 --camera seed000,seed004 --error 0,1,3,9 [--real]

Frames from the simulator (1 px, 2 false stars, the camera's magnitude limit); each solver is
told a camera whose horizontal field is ``error`` percent too wide. ``--real`` adds the real
images' centroid lists (their own cameras, the field likewise too wide; right = the reference
solution's attitude within 0.1 deg). skyfix runs ``auto`` on the default database with
``fov_max_error_deg`` = 12% of the field (1 deg for an 8.6-deg camera); tetra3rs (when
installed) at its default and at tolerance 0.002 on a database of the camera's stars, given the
same wrong camera model. Prints a Markdown table: right / frames, wrong, median / mean / p99 ms,
and the fitted field's median relative error.
"""

from __future__ import annotations

import argparse  # noqa: E402
import time  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from service.core.camera import Camera  # noqa: E402
from service.core.navdb import ensure_default_database, open_database  # noqa: E402
from service.core.pipeline import SolveOptions, solve  # noqa: E402
from service.core.presets import PRESETS  # noqa: E402
from service.core.sim import SimConfig, simulate_frames  # noqa: E402
from service.core.warmup import warm_up  # noqa: E402

from . import common  # noqa: F401  (pins threads before numpy)
from .common import judge  # noqa: E402

SEARCH_SHARE = 0.12
"""``fov_max_error_deg`` as a share of the camera's field (1 deg of seed 000's 8.6)."""


def _too_wide(camera: Camera, percent: float) -> Camera:
    return Camera.from_fov(camera.fov_deg * (1 + percent / 100), camera.width, camera.height, cx=camera.cx,
                           cy=camera.cy, distortion=camera.distortion)


def _row(label: str, rows: list[Any]) -> str:
    ms = np.array([r[2] for r in rows])
    fov = [r[3] for r in rows if r[0] and not r[1] and np.isfinite(r[3])]
    return (f"| {label} | {sum(r[0] and not r[1] for r in rows)}/{len(rows)} | {sum(r[1] for r in rows)} | "
            f"{np.median(ms):.2f} / {ms.mean():.2f} / {np.percentile(ms, 99):.1f} | "
            f"{f'{np.median(np.abs(fov)):.1e}' if fov else '-'} |")


Outcome = tuple[bool, bool, float, float]
"""(right, wrong, ms, fitted field's relative error or nan) of one frame."""


def _skyfix(db: Any, frames: Sequence[Any], percent: float, search: bool) -> list[Outcome]:
    out = []
    for cents, cam, q, hip, blends in frames:
        told = _too_wide(cam, percent)
        error = SEARCH_SHARE * cam.fov_deg if search else None
        opts = SolveOptions(centroid_sigma_px=1.0, fov_max_error_deg=error)
        t0 = time.perf_counter()
        sol = solve(cents, told, db, options=opts)
        ms = (time.perf_counter() - t0) * 1e3
        ans = common.Answer(sol.solved, ms, sol.quaternion, [(s.centroid, s.hip) for s in sol.stars])
        j = judge(ans, q, hip, blends)
        fov = (sol.fov_deg / cam.fov_deg - 1) if sol.solved and sol.fov_deg else float("nan")
        out.append((j.solved, j.solved and j.wrong, ms, fov))
    return out


def _peer(solver: Any, frames: Sequence[Any], percent: float) -> list[Outcome]:
    out = []
    for cents, cam, q, hip, blends in frames:
        ans = solver.solve(cents, _too_wide(cam, percent), 1.0)
        j = judge(ans, q, hip, blends)
        out.append((j.solved, j.solved and j.wrong, ans.ms, float("nan")))
    return out


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--camera", default="seed000,seed004")
    ap.add_argument("--error", default="0,1,3,9", help="percent the told field is too wide, comma-separated")
    ap.add_argument("--real", action="store_true")
    ap.add_argument("--no-peers", action="store_true")
    args = ap.parse_args(argv)
    db = open_database(ensure_default_database())
    warm_up(db)
    print(f"{common.machine_line(common.machine_info())}\n")
    print("| camera | field told | solver | right / frames | wrong | ms median / mean / p99 "
          "| fitted field, median rel. error |")
    print("|---|---|---|---|---|---|---|")
    groups: list[tuple[str, list[Any], Any]] = []
    for key in args.camera.split(","):
        p = PRESETS[key]
        config = SimConfig(mag_limit=p.mag_limit, centroid_noise_px=1.0, false_stars=2)
        frames = [(f.centroids, p.camera, f.quaternion, f.hip.tolist(), f.blends)
                  for f in simulate_frames(p.camera, args.frames, config, rng=3)]
        groups.append((key, frames, p))
    if args.real:
        real = common.real_frames()
        groups.append(("real", [(f.centroids, f.camera, f.quaternion, f.hip, None) for f in real], None))
    for key, frames, preset in groups:
        peers: list[Any] = []
        if not args.no_peers and preset is not None:
            from bench.bench_peers import Peers
            from bench.peers import StarRows

            store = Peers(["tetra3rs", "tetra3rs-0.002"], Path("/tmp/bench_fov_cedar.log"))
            cdb = common.build_skyfix_db(preset, ["maxangle"], Path("bench/out/db") / key, reuse=True)[0]
            rows = StarRows.from_table(open_database(cdb).stars)
            peers, _, _ = store.prepare(key, rows, preset.camera.fov_deg, None, preset.mag_limit,
                                        Path("bench/out/db/peers"), True)
        for percent in (float(e) for e in args.error.split(",")):
            told = f"+{percent:g}%"
            print(_row(f"{key} | {told} | skyfix as given", _skyfix(db, frames, percent, False)), flush=True)
            searched = _skyfix(db, frames, percent, True)
            print(_row(f"{key} | {told} | skyfix fov_max_error", searched), flush=True)
            for peer in peers:
                print(_row(f"{key} | {told} | {peer.name}", _peer(peer, frames, percent)), flush=True)


if __name__ == "__main__":
    main()
