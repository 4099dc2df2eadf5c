"""Shared harness of the identification benchmarks (``bench_methods``, ``bench_peers``).

Importing this module pins BLAS/OpenMP/Rayon to one thread *before* numpy is imported, so
every timing is of one single-threaded process: import it first in an entry point.

What lives here: scenarios (paper camera x sweep x value -> simulated frames), the skyfix
database build/open measurements, the skyfix solver wrapper, scoring of any solver's answer
against the simulator's truth (one rule for skyfix and the peers), statistics, markdown and
machine facts.
"""

from __future__ import annotations

import os

THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS",
               "VECLIB_MAXIMUM_THREADS", "RAYON_NUM_THREADS")


def pin_threads(env: dict[str, str] | None = None) -> dict[str, str]:
    """Set every threading knob to 1 in ``env`` (default: this process's environment)."""
    env = os.environ if env is None else env
    for k in THREAD_VARS:
        env[k] = "1"
    return env


pin_threads()

import datetime as dt  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Iterable, Sequence  # noqa: E402
from dataclasses import asdict, dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from service.core.attitude import quat_to_matrix  # noqa: E402
from service.core.camera import Camera  # noqa: E402
from service.core.evaluate import WRONG_BORESIGHT_ARCSEC, attitude_error  # noqa: E402
from service.core.navdb import BuildConfig, build_database, open_database  # noqa: E402
from service.core.pipeline import SolveOptions, solve  # noqa: E402
from service.core.presets import PRESETS, Preset  # noqa: E402
from service.core.sim import SimConfig, SimFrame, random_points, simulate_frames  # noqa: E402,F401

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "out"
REAL_DIR = Path(os.environ.get("SKYFIX_REAL_DATA", ROOT.parent / "shared" / "data" / "real"))

WRONG_ROLL_ARCSEC = 3600.0
"""A solved frame whose roll about the boresight is off by more than this is a wrong answer
(cross-boresight: ``WRONG_BORESIGHT_ARCSEC``, 360"). Right answers at 2 px noise stay far
below both; a misidentification is off by degrees."""

TIMEOUT_MS = 500.0
"""Time budget of one solve, for every solver (skyfix's ``SolveOptions.timeout_ms`` default)."""


# ---- scenarios ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Sweep:
    name: str
    label: str
    values: tuple[float, ...]
    base: dict[str, float]
    """The other two noise knobs held fixed during this sweep."""


SWEEPS: dict[str, Sweep] = {
    "noise": Sweep("noise", "centroid noise (px, 1 sigma per axis)",
                   tuple(0.25 * i for i in range(9)), {"false_stars": 2, "mag_noise": 0.0}),
    "false": Sweep("false", "false stars per frame", (0, 1, 2, 3, 4, 5),
                   {"centroid_noise_px": 0.5, "mag_noise": 0.0}),
    "magnoise": Sweep("magnoise", "magnitude noise (mag, 1 sigma)", (0.0, 0.25, 0.5, 0.75, 1.0),
                      {"centroid_noise_px": 0.5, "false_stars": 2}),
}
_SWEEP_FIELD = {"noise": "centroid_noise_px", "false": "false_stars", "magnoise": "mag_noise"}


@dataclass(frozen=True)
class Scenario:
    """One point of a sweep on one paper camera."""

    preset: str
    sweep: str
    value: float
    noise_px: float
    false_stars: int
    mag_noise: float

    @property
    def label(self) -> str:
        return f"{self.noise_px:g} px, {self.false_stars} false, {self.mag_noise:g} mag"

    def sim_config(self) -> SimConfig:
        p = PRESETS[self.preset]
        return SimConfig(mag_limit=p.mag_limit, centroid_noise_px=self.noise_px, mag_noise=self.mag_noise,
                         false_stars=self.false_stars)

    def seed(self, base: int) -> int:
        """Same frames for every solver and every run with the same ``base`` seed."""
        h = hashlib.sha256(f"{base}/{self.preset}/{self.sweep}/{self.value:g}".encode()).digest()
        return int.from_bytes(h[:8], "little")

    def frames(self, n: int, base_seed: int) -> list[SimFrame]:
        return simulate_frames(PRESETS[self.preset].camera, n, self.sim_config(), rng=self.seed(base_seed))


def scenarios(preset: str, sweep: str, values: Sequence[float] | None = None) -> list[Scenario]:
    sw = SWEEPS[sweep]
    out = []
    for v in (sw.values if values is None else values):
        knobs = {"centroid_noise_px": 0.0, "false_stars": 0, "mag_noise": 0.0, **sw.base, _SWEEP_FIELD[sweep]: v}
        out.append(Scenario(preset, sweep, float(v), float(knobs["centroid_noise_px"]), int(knobs["false_stars"]),
                            float(knobs["mag_noise"])))
    return out


def matched_sigma(noise_px: float, floor: float = 0.1) -> float:
    """``SolveOptions.centroid_sigma_px`` matched to the simulated centroid noise (floored at
    0.1 px: a real centroider is never better than that)."""
    return max(float(noise_px), floor)


# ---- results and scoring -----------------------------------------------------------------
@dataclass
class Answer:
    """What any solver said about one frame, in skyfix's conventions."""

    solved: bool
    ms: float
    """In-process wall time of the solve call, ms (database already loaded)."""
    quaternion: Sequence[float] | None = None
    """ICRS -> camera, [w, x, y, z], camera +x right, +y down, +z boresight."""
    matches: list[tuple[int, int]] | None = None
    """(centroid index, HIP) pairs the solver claims; None if it reports none."""
    status: str = ""


@dataclass
class Judged:
    solved: bool
    wrong: bool
    wrong_attitude: bool
    wrong_star: bool
    cross_arcsec: float | None
    roll_arcsec: float | None
    ms: float
    n_matched: int


def judge(ans: Answer, q_true: Sequence[float], hip_true: Sequence[int] | None,
          blends: dict[int, tuple[int, ...]] | None = None) -> Judged:
    """One rule for every solver: a solved frame is wrong when its attitude is off (cross-
    boresight > 360" or roll > 3600") or any star it matched is not the truth's (a false star
    matched to a catalogue star counts; a blend matches any of its members)."""
    if not ans.solved or ans.quaternion is None:
        return Judged(False, False, False, False, None, None, ans.ms, 0)
    cross, roll = attitude_error(ans.quaternion, q_true)
    bad_att = cross > WRONG_BORESIGHT_ARCSEC or roll > WRONG_ROLL_ARCSEC
    bad_star = False
    if hip_true is not None and ans.matches:
        for idx, hip in ans.matches:
            ok = {int(h) for h in (blends or {}).get(idx, ())}
            if 0 <= idx < len(hip_true) and hip_true[idx] is not None and int(hip_true[idx]) >= 0:
                ok.add(int(hip_true[idx]))
            if int(hip) not in ok:
                bad_star = True
                break
    return Judged(True, bad_att or bad_star, bad_att, bad_star, cross, roll, ans.ms,
                  len(ans.matches or ()))


def _pct(a: Sequence[float], q: float) -> float | None:
    return float(np.percentile(np.asarray(a, float), q)) if len(a) else None


def summarize(js: Sequence[Judged]) -> dict[str, Any]:
    """Rates, wrong answers, attitude error (right answers only) and solve time (all frames)."""
    n = len(js)
    solved = [j for j in js if j.solved]
    right = [j for j in solved if not j.wrong]
    ms = [j.ms for j in js]
    return {
        "frames": n,
        "solved": len(solved),
        "right": len(right),
        "rate": len(right) / n if n else None,
        "solved_rate": len(solved) / n if n else None,
        "wrong": sum(j.wrong for j in solved),
        "wrong_attitude": sum(j.wrong_attitude for j in solved),
        "wrong_star": sum(j.wrong_star and not j.wrong_attitude for j in solved),
        "cross_arcsec_median": _pct([j.cross_arcsec for j in right], 50),
        "cross_arcsec_p95": _pct([j.cross_arcsec for j in right], 95),
        "roll_arcsec_median": _pct([j.roll_arcsec for j in right], 50),
        "ms_median": _pct(ms, 50),
        "ms_p95": _pct(ms, 95),
        "ms_p99": _pct(ms, 99),
        "ms_mean": float(np.mean(ms)) if ms else None,
        "ms_median_failed": _pct([j.ms for j in js if not j.solved], 50),
    }


# ---- skyfix ------------------------------------------------------------------------------
class SkyfixSolver:
    """skyfix's ``solve`` on one opened database with one method (or ``auto``)."""

    kind = "skyfix"

    def __init__(self, db: Any, method: str, *, sigma: Callable[[float], float] | float = matched_sigma,
                 timeout_ms: float = TIMEOUT_MS, label: str = "") -> None:
        self.db, self.method, self.sigma, self.timeout_ms = db, method, sigma, timeout_ms
        self.name = f"skyfix {method}{label}"
        self._opts: dict[float, SolveOptions] = {}

    def options(self, noise_px: float) -> SolveOptions:
        if noise_px not in self._opts:
            s = self.sigma(noise_px) if callable(self.sigma) else float(self.sigma)
            self._opts[noise_px] = SolveOptions(centroid_sigma_px=s, timeout_ms=self.timeout_ms)
        return self._opts[noise_px]

    def solve(self, centroids: Any, camera: Camera, noise_px: float) -> Answer:
        opts = self.options(noise_px)
        t0 = time.perf_counter()
        sol = solve(centroids, camera, self.db, method=self.method, options=opts)
        ms = (time.perf_counter() - t0) * 1e3
        if not sol.solved:
            return Answer(False, ms, status=str(getattr(sol.status, "value", sol.status)))
        return Answer(True, ms, sol.quaternion, [(s.centroid, s.hip) for s in sol.stars], "solved")


@dataclass
class DbReport:
    """Build and open measurements of one database."""

    solver: str
    preset: str
    path: str
    build_s: float | None
    size_bytes: int
    open_ms: float | None
    first_solve_ms: dict[str, float] = field(default_factory=dict)
    per_method_build_s: dict[str, float] = field(default_factory=dict)
    per_method_bytes: dict[str, int] = field(default_factory=dict)
    methods: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    note: str = ""


def dir_bytes(path: Path) -> int:
    p = Path(path).resolve()
    if p.is_file():
        return p.stat().st_size
    return sum(f.stat().st_size for f in p.rglob("*") if f.is_file())


def _array_bytes(manifest: dict[str, Any], prefix: str) -> int:
    total = 0
    for name, spec in manifest.get("arrays", {}).items():
        if name.startswith(prefix):
            total += int(np.prod(spec["shape"], dtype=np.int64)) * np.dtype(spec["dtype"]).itemsize
    return total


def remove_db(path: Path) -> None:
    """Delete a database built by ``build_database`` (a symlink to a versioned sibling)."""
    path = Path(path)
    if path.is_symlink():
        target = path.parent / os.readlink(path)
        path.unlink()
        shutil.rmtree(target, ignore_errors=True)
    elif path.exists():
        shutil.rmtree(path, ignore_errors=True)


def opens(path: Path, log: Callable[[str], None] = print) -> bool:
    """True if the database (or set) at ``path`` opens with this skyfix (an older schema does
    not: it must be rebuilt)."""
    try:
        open_database(path)
    except Exception as exc:
        log(f"  not reusing {path}: {exc}")
        return False
    return True


def build_skyfix_db(preset: Preset, methods: Sequence[str], path: Path, *, reuse: bool = False,
                    log: Callable[[str], None] = print) -> tuple[Path, DbReport]:
    """Build (or, with ``reuse``, keep) one database with every method in ``methods`` that
    builds; a method whose build raises is left out and reported (other methods are being
    written while this harness runs). Times the build per method from the progress stages."""
    side = path.parent / f"{path.name}.bench.json"
    if reuse and (path / "manifest.json").is_file() and side.is_file() and opens(path, log):
        rep = DbReport(**json.loads(side.read_text()))
        log(f"  reusing {path} (built in {rep.build_s:.1f} s)")
        return path, rep
    failed: dict[str, str] = {}
    todo = list(methods)
    while True:
        marks: list[tuple[str, float]] = []

        def progress(stage: str, frac: float) -> None:
            marks.append((stage, time.perf_counter()))

        t0 = time.perf_counter()
        try:
            build_database(path, preset.build_config(tuple(todo)), progress=progress)
            break
        except Exception as exc:  # find the culprit: build each method alone
            log(f"  combined build failed ({type(exc).__name__}: {exc}); trying methods one by one")
            good = []
            for m in todo:
                try:
                    build_database(path.parent / f".probe-{m}", preset.build_config((m,)))
                    good.append(m)
                except Exception as e2:
                    failed[m] = f"{type(e2).__name__}: {e2}"[:300]
                    log(f"  {m}: build fails: {failed[m]}")
                finally:
                    remove_db(path.parent / f".probe-{m}")
            if not good or good == todo:
                raise
            todo = good
    total = time.perf_counter() - t0
    per: dict[str, float] = {}
    starts: dict[str, float] = {}
    for stage, t in marks:
        m = stage.split(":", 1)[0]
        if m in todo and m not in starts:
            starts[m] = t
    order = sorted(starts, key=starts.get)
    ends = [starts[m] for m in order[1:]] + [marks[-1][1] if marks else t0 + total]
    for m, e in zip(order, ends):
        per[m] = round(e - starts[m], 3)
    manifest = json.loads((path / "manifest.json").read_text())
    rep = DbReport(
        solver="skyfix", preset=preset.name, path=str(path), build_s=round(total, 3), size_bytes=dir_bytes(path),
        open_ms=None, per_method_build_s=per,
        per_method_bytes={m: _array_bytes(manifest, f"{m}/") for m in [*todo, "pairs"]}, methods=list(todo),
        failed=failed,
        note=f"{manifest.get('n_stars')} stars to {preset.mag_limit} Mv",
    )
    side.write_text(json.dumps(asdict(rep), indent=1))
    return path, rep


def measure_open(path: Path, methods: Sequence[str], camera: Camera, frame: SimFrame | None,
                 repeats: int = 5) -> tuple[float, dict[str, float]]:
    """Median wall time of ``open_database`` (page cache warm, as after the first start) and,
    per method, the first solve on a freshly opened database (matcher set-up included)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        open_database(path)
        times.append((time.perf_counter() - t0) * 1e3)
    first: dict[str, float] = {}
    if frame is not None:
        for m in methods:
            db = open_database(path)
            t0 = time.perf_counter()
            solve(frame.centroids, camera, db, method=m)
            first[m] = round((time.perf_counter() - t0) * 1e3, 3)
    return round(float(np.median(times)), 3), first


def random_point_frames(camera: Camera, n: int, seed: int) -> list[Any]:
    """No-solution frames: 5..30 uniformly random points each."""
    return [random_points(camera, 5 + i % 26, rng=seed + i) for i in range(n)]


# ---- real images -------------------------------------------------------------------------
@dataclass
class RealFrame:
    name: str
    camera: Camera
    centroids: Any
    quaternion: list[float]
    hip: list[int]


def real_frames(directory: Path = REAL_DIR) -> list[RealFrame]:
    """The real images as centroid lists: matches.json's measured centroids (moved to our
    pixel convention, centre of the top-left pixel at (0, 0)), brightest first by catalogue
    magnitude, on a pinhole camera with the reference solution's field of view."""
    from service.core.types import Centroids

    truth = json.loads((directory / "truth.json").read_text())["images"]
    matches = json.loads((directory / "matches.json").read_text())["images"]
    out = []
    for name in sorted(truth):
        t, stars = truth[name], matches[name]["matches"]
        stars = sorted(stars, key=lambda s: s["mag"])
        xy = np.array([[s["x"] - 0.5, s["y"] - 0.5] for s in stars], float).reshape(-1, 2)
        flux = np.array([10 ** (-0.4 * (s["mag"] - 6.0)) * 1000 for s in stars], float)
        out.append(RealFrame(name, Camera.from_fov(t["fov_deg"], t["width"], t["height"]), Centroids(xy, flux),
                             t["quaternion_icrs_to_camera_wxyz"], [int(s["hip"]) for s in stars]))
    return out


# ---- reporting ---------------------------------------------------------------------------
def machine_info() -> dict[str, Any]:
    """Facts to print beside every table: CPU, cores, load, Python, numpy and its BLAS."""
    info: dict[str, Any] = {"date_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
                            "python": platform.python_version(), "numpy": np.__version__,
                            "platform": platform.platform()}
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=10).stdout
        for line in out.splitlines():
            k, _, v = line.partition(":")
            if k.strip() in ("Model name", "CPU(s)", "Thread(s) per core", "Core(s) per socket"):
                info[k.strip()] = v.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    try:
        info["loadavg"] = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        pass
    info["threads_env"] = {k: os.environ.get(k) for k in THREAD_VARS}
    info["OPENBLAS_CORETYPE"] = os.environ.get("OPENBLAS_CORETYPE")
    try:
        from threadpoolctl import threadpool_info

        info["blas"] = [{k: d.get(k) for k in ("internal_api", "version", "num_threads", "architecture")}
                        for d in threadpool_info()]
    except ImportError:
        info["blas"] = "threadpoolctl not installed"
    try:
        info["git"] = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                                     text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    return info


def machine_line(info: dict[str, Any]) -> str:
    return (f"{info.get('date_utc')}; {info.get('Model name', '?')}, {info.get('CPU(s)', '?')} CPUs; "
            f"load average at start {info.get('loadavg')}; Python {info.get('python')}, numpy {info.get('numpy')}; "
            f"git {info.get('git', '?')}; one single-threaded process (OMP/OPENBLAS/MKL/RAYON threads = 1)")


def fmt(v: Any, nd: int = 2, pct: bool = False) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    if pct:
        return f"{100 * v:.{nd}f}%"
    if isinstance(v, float):
        return f"{v:.{nd}f}"
    return str(v)


def md_table(header: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(" --- " for _ in header) + "|"]
    for r in rows:
        lines.append("| " + " | ".join(str(c) for c in r) + " |")
    return "\n".join(lines)


def write_json(path: Path, data: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1, default=str))


def command_line(argv: Sequence[str]) -> str:
    return " ".join(["python", "-m", *argv])


__all__ = [
    "OUT", "PRESETS", "REAL_DIR", "SWEEPS", "TIMEOUT_MS", "Answer", "BuildConfig", "DbReport", "Judged",
    "Scenario", "SkyfixSolver", "build_skyfix_db", "dir_bytes", "fmt", "judge", "machine_info", "machine_line",
    "matched_sigma", "md_table", "measure_open", "pin_threads", "quat_to_matrix", "random_point_frames",
    "real_frames", "scenarios", "summarize", "write_json",
]
