"""What cold processor caches cost a frame: ``solve`` warm, frame after frame, and after other writes.

    python -m bench.profile_cold [--camera seed003] [--frames 300] [--noise 0.5 --false 2] [--evict-mb 32]

``bench_peers`` runs tetra3rs in the same process, between skyfix's solves, so each skyfix
frame starts with caches another solver has filled. This solves the same simulated frames on
the default database (``auto``, one camera and options object, as a caller that reuses them)
three ways and reports the median and mean us a frame:

- **warm**: each frame solved twice in a row, the second timed (its code and data cached);
- **in turn**: every frame once, one after the other (code warm, each frame's data new);
- **evicted**: each frame after ``--evict-mb`` MB of other writes (code and data cold).

Each is split into the compiled first pass (the call made from the centroids as given,
``first_pass.frame_first_pass_kernel``, its entry point once the camera's set-up has one, or
``first_pass_kernel`` on the general path; its argument dispatch included; since session 35
``frame_chain.frame_chain_kernel``, which runs the fallback chain too where the first pass
proves nothing) and the rest (Python around it, and any later passes). A last row
times the first pass evicted but with its code warmed by another frame just before: what the
frame's own data costs (docs/performance.md, session 20).
"""

from __future__ import annotations

from . import common  # noqa: F401  (pins threads before numpy)

import argparse  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Sequence  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from service.core import first_pass as first_pass_mod  # noqa: E402
from service.core import pipeline  # noqa: E402
from service.core.camera_setup import kept_setup  # noqa: E402
from service.core.navdb import ensure_default_database, open_database  # noqa: E402
from service.core.pipeline import SolveOptions, solve  # noqa: E402
from service.core.presets import PRESETS  # noqa: E402
from service.core.sim import SimConfig, simulate_frames  # noqa: E402
from service.core.warmup import warm_up  # noqa: E402

KERNELS = ((pipeline, "frame_first_pass_kernel"), (first_pass_mod, "first_pass_kernel"),
           (pipeline, "frame_chain_kernel"), (pipeline, "FRAME_CHAIN"))


class _Timed:
    """Wraps the first pass's compiled calls, summing their wall time (s) since ``reset``: the
    kernels, and the entry point a camera's set-up calls once it has one
    (``first_pass.kernel_entry``; ``setups`` kept before, and any made inside the block)."""

    def __init__(self, setups: Sequence[Any] = ()) -> None:
        self.total = 0.0
        self.calls: list[tuple[Callable[..., Any], tuple[Any, ...]]] = []
        self._saved: list[tuple[Any, str, Callable[..., Any]]] = []
        self._setups = [s for s in setups if s is not None]
        self._entries: list[tuple[Any, Any]] = []

    def __enter__(self) -> _Timed:
        for mod, name in (*KERNELS, (pipeline, "kernel_entry")):
            fn = getattr(mod, name)
            self._saved.append((mod, name, fn))
            setattr(mod, name, self._wrap_entry(fn) if name == "kernel_entry" else self._wrap(fn))
        for setup in self._setups:
            self._entries.append((setup, setup.entry[0]))
            if setup.entry[0] is not None:
                setup.entry[0] = self._wrap(setup.entry[0])
        return self

    def __exit__(self, *exc: object) -> None:
        for mod, name, fn in self._saved:
            setattr(mod, name, fn)
        for setup, entry in self._entries:
            setup.entry[0] = entry

    def _wrap_entry(self, kernel_entry: Callable[[], Any]) -> Callable[[], Any]:
        def timed_entry() -> Any:
            entry = kernel_entry()
            return None if entry is None else self._wrap(entry)
        return timed_entry

    def _wrap(self, fn: Callable[..., Any]) -> Callable[..., Any]:
        def timed(*args: Any) -> Any:
            self.calls.append((fn, args))
            t0 = time.perf_counter()
            try:
                return fn(*args)
            finally:
                self.total += time.perf_counter() - t0
        return timed

    def reset(self) -> None:
        self.total = 0.0
        self.calls.clear()


def _row(label: str, total: list[float], kernel: list[float]) -> str:
    t, k = np.array(total) * 1e6, np.array(kernel) * 1e6
    return (f"| {label} | {np.median(t):.1f} / {t.mean():.1f} | {np.median(k):.1f} / {k.mean():.1f} | "
            f"{np.median(t - k):.1f} / {(t - k).mean():.1f} |")


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--camera", default="seed003")
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--noise", type=float, default=0.5)
    ap.add_argument("--false", type=int, default=2)
    ap.add_argument("--evict-mb", type=float, default=32.0)
    ap.add_argument("--seed", type=int, default=11)
    args = ap.parse_args(argv)
    db = open_database(ensure_default_database())
    warm_up(db)
    p = PRESETS[args.camera]
    config = SimConfig(mag_limit=p.mag_limit, centroid_noise_px=args.noise, false_stars=args.false)
    frames = [f.centroids for f in simulate_frames(p.camera, args.frames, config, rng=args.seed)]
    options = SolveOptions(centroid_sigma_px=max(args.noise, 0.1))
    junk = np.zeros(max(int(args.evict_mb * (1 << 20)) // 8, 1))
    for c in frames:  # every kernel loaded, the camera's set-up kept
        solve(c, p.camera, db, options=options)
    rows = {"warm": ([], []), "in turn": ([], []), "evicted": ([], [])}
    first_calls: list[tuple[Callable[..., Any], tuple[Any, ...]]] = []
    with _Timed([kept_setup(db, p.camera, "auto", options)]) as timed:
        for c in frames:
            solve(c, p.camera, db, options=options)
            timed.reset()
            t0 = time.perf_counter()
            solve(c, p.camera, db, options=options)
            rows["warm"][0].append(time.perf_counter() - t0)
            rows["warm"][1].append(timed.total)
            first_calls.append(timed.calls[0] if timed.calls else None)
        for c in frames:
            timed.reset()
            t0 = time.perf_counter()
            solve(c, p.camera, db, options=options)
            rows["in turn"][0].append(time.perf_counter() - t0)
            rows["in turn"][1].append(timed.total)
        for c in frames:
            junk += 1.0
            timed.reset()
            t0 = time.perf_counter()
            solve(c, p.camera, db, options=options)
            rows["evicted"][0].append(time.perf_counter() - t0)
            rows["evicted"][1].append(timed.total)
    calls = [c for c in first_calls if c is not None]
    code_warm = []
    for i, (fn, call_args) in enumerate(calls):  # the first pass alone: evicted, then another frame's first
        other_fn, other_args = calls[(i + len(calls) // 2) % len(calls)]
        junk += 1.0
        other_fn(*other_args)
        t0 = time.perf_counter()
        fn(*call_args)
        code_warm.append(time.perf_counter() - t0)
    print(f"{args.camera}, {args.frames} frames at {args.noise:g} px with {args.false} false stars, default "
          f"database, auto; us a frame, median / mean; evicted: {args.evict_mb:g} MB written before each\n")
    print("| frames | solve | the first pass's compiled call | the rest |")
    print("|---|---|---|---|")
    for label, (total, kernel) in rows.items():
        print(_row(label, total, kernel))
    if code_warm:
        k = np.array(code_warm) * 1e6
        print(f"| evicted, the first pass's code warmed by another frame | | {np.median(k):.1f} / {k.mean():.1f} | |")


if __name__ == "__main__":
    main()
