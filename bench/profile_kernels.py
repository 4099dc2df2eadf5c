"""Where the compiled kernels' time goes, function by function: perf samples, named.

    python -m bench.profile_kernels [--camera seed001] [--noise 0.5] [--false 0] [--random 0]
        [--seconds 6] [--top 30] [--callers] [--refused] [--stars N]

Solves simulated frames of one paper camera with ``auto`` on the default database in a loop
while ``perf record`` (Debian's linux-perf; software clock, no hardware counters needed)
samples this process, and prints the share of samples per function. perf cannot name numba's
code on its own: the kernels live in memory numba's JIT mapped, with no symbol table perf can
read. This script keeps a copy of each kernel's object code as numba loads it from its cache
(:func:`install`, before any kernel runs), and writes ``/tmp/perf-PID.map`` from the object
code's symbols (:func:`write_perf_map`), which ``perf report`` reads. numba inlines callees into
the functions' own objects (weak symbols), so each kernel and helper is named where it ran.
``--callers`` names, for the samples in numba's reference counting (``NRT_incref`` /
``NRT_decref``, which take ~15% of a proven frame's first pass), the function that called it
(the return address on top of the stack that ``perf record --call-graph dwarf`` copies:
numba's code keeps no frame pointers, so perf's own call graphs stop there).
``--random N`` solves ``N`` random-point frames instead (the refusal path); ``--refused`` keeps
only the simulated frames that end with no solution (seed 002's sparse frames with false stars);
``--stars N`` only those of ``N`` centroids.
"""

from __future__ import annotations

from . import common  # noqa: F401  (pins threads before numpy)

import argparse  # noqa: E402
import bisect  # noqa: E402
import os  # noqa: E402
import re  # noqa: E402
import shutil  # noqa: E402
import signal  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections import Counter  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from numba.core import codegen as _codegen  # noqa: E402

_OBJECTS: list[tuple[object, bytes]] = []
_NRT_NAMES = ("NRT_MemInfo_data_fast", "NRT_incref", "NRT_decref")


def install() -> None:
    """Keep each kernel's object code as numba loads it from its cache (call before any kernel
    runs in this process; the kernels' answers do not change)."""
    cls = _codegen.CPUCodeLibrary
    if getattr(cls, "_profile_kernels_hook", False):
        return
    original = cls._object_getbuffer_hook.__func__

    def getbuffer(klass, ll_module):  # type: ignore[no-untyped-def]
        buf = original(klass, ll_module)
        if buf:
            _OBJECTS.append((getattr(ll_module, "_CPUCodeLibrary__library", None), bytes(buf)))
        return buf

    cls._object_getbuffer_hook = classmethod(getbuffer)
    cls._profile_kernels_hook = True
    from numba.core.registry import cpu_target

    engine = cpu_target.target_context.codegen()._engine
    engine.set_object_cache(cls._object_compiled_hook, cls._object_getbuffer_hook)


def kernel_symbols() -> list[tuple[int, int, str]]:
    """``(address, size, name)`` of every function in the kernels loaded since :func:`install`,
    and of numba's reference counting (its runtime module, compiled at start-up)."""
    out: dict[int, tuple[int, str]] = {}
    nm = shutil.which("nm")
    for lib, obj in _OBJECTS if nm else ():
        with tempfile.NamedTemporaryFile(suffix=".o") as f:
            f.write(obj)
            f.flush()
            listing = subprocess.run([nm, "-S", "--defined-only", f.name], capture_output=True, text=True).stdout
        syms = []
        for line in listing.splitlines():
            parts = line.split()
            if len(parts) == 4 and parts[2] in "tTwW":
                syms.append((int(parts[0], 16), int(parts[1], 16), parts[3], parts[2]))
        base = None  # the object's load address: from one exported function's address
        for value, _, name, kind in syms:
            if kind == "T" and lib is not None:
                try:
                    addr = lib.get_pointer_to_function(name)
                except Exception:  # noqa: BLE001 (a symbol the engine does not export)
                    continue
                if addr:
                    base = addr - value
                    break
        if base is not None:
            for value, size, name, _ in syms:
                out[base + value] = (size, name)
    from numba.core.runtime import rtsys

    for name in _NRT_NAMES:
        try:
            addr = rtsys.library.get_pointer_to_function(name)
        except Exception:  # noqa: BLE001
            addr = 0
        if addr:
            out[addr] = (16, name)
    return sorted((a, s, n) for a, (s, n) in out.items())


def write_perf_map(path: str | os.PathLike[str] | None = None) -> int:
    """Write perf's map of this process's kernels (``/tmp/perf-PID.map`` by default); returns
    how many functions it names."""
    syms = kernel_symbols()
    target = Path(path or f"/tmp/perf-{os.getpid()}.map")
    tmp = target.with_suffix(".tmp")
    tmp.write_text("".join(f"{a:x} {s:x} {n}\n" for a, s, n in syms))
    tmp.replace(target)
    return len(syms)


def short_name(symbol: str) -> str:
    """A kernel's mangled name as ``module.function``."""
    m = re.match(r"(?:cfunc\.)?_ZN(.*)", symbol)
    if not m:
        return symbol
    parts, rest = [], m.group(1)
    while rest and rest[0].isdigit():
        n = int(re.match(r"\d+", rest).group())
        digits = len(str(n))
        parts.append(rest[digits:digits + n])
        rest = rest[digits + n:]
    names = [p for p in parts if p not in ("service", "core", "_3clocals_3e")]
    return ".".join(names[-2:]) if names else symbol


def _frames(camera: str, noise: float, false: int, random: int, seed: int) -> tuple[list, object, object]:
    from service.core.pipeline import SolveOptions
    from service.core.presets import PRESETS
    from service.core.sim import SimConfig, random_points, simulate_frames

    p = PRESETS[camera]
    if random:
        rng = np.random.default_rng(seed)
        frames = [random_points(p.camera, int(n), rng) for n in rng.integers(5, 40, random)]
    else:
        config = SimConfig(mag_limit=p.mag_limit, centroid_noise_px=noise, false_stars=false)
        frames = [f.centroids for f in simulate_frames(p.camera, 300, config, rng=seed)]
    return frames, p.camera, SolveOptions(centroid_sigma_px=max(noise, 0.1))


def _callers(data: Path, syms: list[tuple[int, int, str]]) -> Counter:
    """For the samples in numba's reference counting, the function whose return address is on
    top of the copied user stack."""
    starts = [a for a, _, _ in syms]

    def name_of(addr: int) -> str | None:
        i = bisect.bisect_right(starts, addr) - 1
        return short_name(syms[i][2]) if i >= 0 and addr < syms[i][0] + syms[i][1] else None

    nrt = [(a, s) for a, s, n in syms if n in _NRT_NAMES]
    lo, hi = min(a for a, _ in nrt), max(a + s for a, s in nrt)
    dump = subprocess.run(["perf", "script", "-i", str(data), "-D"], capture_output=True, text=True).stdout
    raw: dict[int, int] = {}
    ip = 0
    found: Counter = Counter()
    for line in dump.splitlines():
        m = re.match(r"\.\s+([0-9a-f]{4}):\s+((?:[0-9a-f]{2} )+)", line)
        if m:
            off = int(m.group(1), 16)
            for k, b in enumerate(m.group(2).split()):
                raw[off + k] = int(b, 16)
            continue
        m = re.search(r"PERF_RECORD_SAMPLE.*: (0x[0-9a-f]+) period", line)
        if m:
            ip = int(m.group(1), 16)
            continue
        m = re.search(r"ustack: size \d+, offset (0x[0-9a-f]+)", line)
        if m:
            if lo <= ip < hi:
                off = int(m.group(1), 16)
                for slot in range(0, 32, 8):
                    word = sum(raw.get(off + slot + k, 0) << (8 * k) for k in range(8))
                    caller = name_of(word)
                    if caller:
                        found[caller] += 1
                        break
            raw = {}
    return found


def refused_only(frames: list, solved: list[bool]) -> list:
    """The frames whose solve ended with no solution (``solved``: each frame's outcome, in order;
    ``--refused``)."""
    kept = [c for c, ok in zip(frames, solved, strict=True) if not ok]
    if not kept:
        raise SystemExit("no frame ends with no solution")
    return kept


def of_stars(frames: list, n: int) -> list:
    """The frames of exactly ``n`` centroids, in order (``--stars``)."""
    kept = [c for c in frames if len(c) == n]
    if not kept:
        raise SystemExit(f"no frame of {n} centroids")
    return kept


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--camera", default="seed001")
    ap.add_argument("--noise", type=float, default=0.5)
    ap.add_argument("--false", type=int, default=0)
    ap.add_argument("--random", type=int, default=0, help="random-point frames instead of simulated stars")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--top", type=int, default=30)
    ap.add_argument("--callers", action="store_true", help="name the callers of the reference counting")
    ap.add_argument("--refused", action="store_true", help="only the frames that end with no solution")
    ap.add_argument("--stars", type=int, default=0, help="only the frames of this many centroids (0: all)")
    args = ap.parse_args(argv)
    if shutil.which("perf") is None:
        raise SystemExit("perf not found (Debian: apt install linux-perf)")
    install()
    from service.core.navdb import ensure_default_database, open_database
    from service.core.pipeline import solve

    db = open_database(ensure_default_database())
    frames, camera, options = _frames(args.camera, args.noise, args.false, args.random, args.seed)
    ends = [solve(c, camera, db, options=options).solved for c in frames]  # every kernel the loop
    # reaches is loaded (and its object code kept)
    if args.refused:
        frames = refused_only(frames, ends)
    if args.stars:
        frames = of_stars(frames, args.stars)
    print(f"{len(frames)} frames; {write_perf_map()} functions named", flush=True)
    out = Path(tempfile.mkdtemp()) / "perf.data"
    graph = ["--call-graph", "dwarf,64"] if args.callers else []
    rec = subprocess.Popen(["perf", "record", "-F", "2000", "-e", "cpu-clock", *graph, "-p", str(os.getpid()),
                            "-o", str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(0.5)  # perf attached
    end, solved = time.perf_counter() + args.seconds, 0
    while time.perf_counter() < end:
        for c in frames:
            solved += solve(c, camera, db, options=options).solved
    rec.send_signal(signal.SIGINT)
    rec.wait()
    report = subprocess.run(["perf", "report", "-i", str(out), "--no-children", "--sort", "sym", "--stdio"],
                            capture_output=True, text=True).stdout
    print("\n| share of samples | function |\n|---|---|")
    shown = 0
    for line in report.splitlines():
        m = re.match(r"\s+([\d.]+)%\s+\[\.\]\s+(\S+)", line)
        if m and shown < args.top:
            print(f"| {m.group(1)}% | {short_name(m.group(2))} |")
            shown += 1
    if args.callers:
        found = _callers(out, kernel_symbols())
        total = sum(found.values()) or 1
        print("\n| share of the reference counting's samples | called from |\n|---|---|")
        for name, n in found.most_common(args.top):
            print(f"| {100 * n / total:.1f}% | {name} |")
    shutil.rmtree(out.parent, ignore_errors=True)


if __name__ == "__main__":
    main()
