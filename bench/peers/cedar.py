"""cedar-solve (PyPI ``cedar-solve`` 0.5.1, the maintained tetra3) as a benchmark peer.

cedar-solve 0.5.1 pins numpy < 2 and an old Pillow, so it lives in its own venv,
``bench/out/venv-cedar`` (``python -m bench.peers.cedar setup`` makes it: ``python -m venv`` +
``pip install cedar-solve==0.5.1``; Pillow 8.4 may build from source and needs a C compiler
with zlib and libjpeg headers). ``cedar_worker.py`` runs there and times each
``solve_from_centroids`` call in-process; this module talks to it over a pipe.

Database: ``Tetra3.generate_database(star_catalog=<path>/hip_main.dat)`` reading the same star
list skyfix uses, written in the published ``hip_main.dat`` layout (pattern_max_error 0.001,
its default), no proper-motion propagation (positions already at the benchmark epoch).

Answer: cedar reports only RA/Dec of the image centre, Roll and FOV. Roll is the angle of
celestial north counter-clockwise from image up, i.e. ``(360 - our roll) mod 360`` where our roll
is the position angle of image-up east of north, so the attitude is
``matrix_from_radec_roll(RA, Dec, (360 - Roll) % 360)``. Its match list (catalogue ids with the
centroids they were paired with) is mapped back to centroid indices by position; it can pair a
false star with a catalogue star, which the shared scoring counts as a wrong answer.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from service.core.attitude import matrix_from_radec_roll, matrix_to_quat

from ..common import OUT, TIMEOUT_MS, Answer, DbReport, dir_bytes, pin_threads
from . import StarRows

VERSION = "0.5.1"
VENV = Path(os.environ.get("SKYFIX_CEDAR_VENV", OUT / "venv-cedar"))
WORKER = Path(__file__).with_name("cedar_worker.py")


def python() -> Path:
    return VENV / "bin" / "python"


def available() -> tuple[bool, str]:
    if not python().is_file():
        return False, f"no cedar-solve venv at {VENV}; run `python -m bench.peers.cedar setup`"
    ok = subprocess.run([str(python()), "-c", "import tetra3"], capture_output=True, text=True)
    if ok.returncode:
        return False, f"cedar-solve does not import in {VENV}: {ok.stderr.strip()[-200:]}"
    return True, ""


def setup(venv: Path = VENV, version: str = VERSION) -> None:
    """Create the venv and install cedar-solve into it (idempotent)."""
    if not (venv / "bin" / "python").is_file():
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install", "--quiet", f"cedar-solve=={version}"],
                   check=True)


class CedarWorker:
    """The worker process: one per benchmark run, databases loaded one at a time."""

    def __init__(self, log: Path | None = None) -> None:
        env = pin_threads(dict(os.environ))
        self._err = open(log, "a") if log else None  # noqa: SIM115
        self.proc = subprocess.Popen([str(python()), str(WORKER)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=self._err or subprocess.DEVNULL, text=True, env=env, bufsize=1)
        self.report: DbReport | None = None

    def call(self, msg: dict[str, Any]) -> dict[str, Any]:
        assert self.proc.stdin and self.proc.stdout
        self.proc.stdin.write(json.dumps(msg) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"cedar worker exited (code {self.proc.poll()})")
        out = json.loads(line)
        if "error" in out:
            raise RuntimeError(f"cedar worker: {out['error']}")
        return out

    def close(self) -> None:
        if self.proc.stdin and not self.proc.stdin.closed:
            self.proc.stdin.close()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        if self.proc.stdout:
            self.proc.stdout.close()
        if self._err is not None:
            self._err.close()

    def prepare(self, key: str, rows: StarRows, max_fov: float, min_fov: float | None, mag: float,
                workdir: Path, reuse: bool = True) -> DbReport:
        workdir.mkdir(parents=True, exist_ok=True)
        tag = f"{key}-{rows.digest()}-{max_fov:.4f}-{min_fov}-{mag}"
        path, side = workdir / f"cedar-{key}.npz", workdir / f"cedar-{key}.json"
        meta = json.loads(side.read_text()) if side.is_file() else {}
        if not (reuse and path.is_file() and meta.get("tag") == tag):
            cat = workdir / f"cedar-{key}" / "hip_main.dat"
            cat.parent.mkdir(parents=True, exist_ok=True)
            self.call({"cmd": "catalog", "path": str(cat),
                       "rows": [[int(h), float(a), float(d), float(m)]
                                for h, a, d, m in zip(rows.hip, rows.ra_deg, rows.dec_deg, rows.mag)]})
            out = self.call({"cmd": "build", "catalog": str(cat), "save_as": str(path), "max_fov": max_fov,
                             "min_fov": min_fov, "mag": mag})
            meta = {"tag": tag, "build_s": round(out["seconds"], 3)}
            side.write_text(json.dumps(meta))
        opens = []
        for _ in range(3):
            out = self.call({"cmd": "load", "path": str(path)})
            opens.append(out["seconds"] * 1e3)
        self.report = DbReport(
            solver="cedar-solve", preset=key, path=str(path), build_s=meta["build_s"], size_bytes=dir_bytes(path),
            open_ms=round(float(np.median(opens)), 3),
            note=f"{out['stars']} stars, {out['patterns']} patterns, FOV {max_fov:.2f}"
                 + (f"-{min_fov:.2f}" if min_fov else "") + f" deg, mag {mag}")
        return self.report


class CedarSolver:
    kind = "peer"

    def __init__(self, worker: CedarWorker, match_max_error: float = 0.002, timeout_ms: float = TIMEOUT_MS) -> None:
        self.worker, self.mme, self.timeout_ms = worker, match_max_error, timeout_ms
        self.method = self.name = "cedar-solve"

    def solve(self, centroids: Any, camera: Any, noise_px: float) -> Answer:
        xy = np.asarray(centroids.xy, float)
        # cedar: (y, x) from the image's top-left corner, image centre at (h/2, w/2)
        yx = np.column_stack([xy[:, 1] - camera.cy + camera.height / 2, xy[:, 0] - camera.cx + camera.width / 2])
        r = self.worker.call({"cmd": "solve", "yx": yx.tolist(), "size": [camera.height, camera.width],
                              "fov": camera.fov_deg, "fov_err": None, "timeout_ms": self.timeout_ms,
                              "match_max_error": self.mme})
        if not r["ok"]:
            return Answer(False, r["ms"], status=str(r.get("status")))
        m = matrix_from_radec_roll(r["ra"], r["dec"], (360.0 - r["roll"]) % 360.0)
        pairs = []
        for cid, (y, x) in zip(r["ids"], r["yx"]):
            d = np.hypot(yx[:, 0] - y, yx[:, 1] - x)
            pairs.append((int(np.argmin(d)), int(cid)))
        return Answer(True, r["ms"], matrix_to_quat(m).tolist(), pairs, "solved")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["setup"]:
        t0 = time.time()
        setup()
        print(f"cedar-solve {VERSION} ready in {VENV} ({time.time() - t0:.0f} s)")
        return 0
    ok, why = available()
    print("cedar-solve available" if ok else why)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
