"""Where one solved frame's microseconds go, stage by stage, on the default database.

    python -m bench.profile_stages [--camera seed003] [--noise 0.5] [--repeat 5000]

Solves one simulated frame (the fourth of a seeded set, 2 false stars) again and again and times
each stage of :func:`service.core.pipeline.solve_rig`'s compiled first pass alone, with
``perf_counter`` over ``--repeat`` calls: the search plan, the refusal check, converting the
input, the compiled call, building the ``Solution``, reading its stars (they are made Python
tuples only when read), and the whole ``solve``. A frame solved again and again has its data in
the caches: a new frame costs more (``bench.profile_default``).
"""

from __future__ import annotations

from . import common  # noqa: F401  (pins threads before numpy)

import argparse  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Sequence  # noqa: E402


from service.core import pipeline  # noqa: E402
from service.core.first_pass import first_pass  # noqa: E402
from service.core.plan import search_plan  # noqa: E402
from service.core.navdb import ensure_default_database, open_database  # noqa: E402
from service.core.presets import PRESETS  # noqa: E402
from service.core.refusal import refusal  # noqa: E402
from service.core.sim import SimConfig, simulate_frames  # noqa: E402
from service.core.solution import solution_of  # noqa: E402


def _us(fn: Callable[[], object], repeat: int) -> float:
    fn()
    t = time.perf_counter()
    for _ in range(repeat):
        fn()
    return (time.perf_counter() - t) / repeat * 1e6


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--camera", default="seed003")
    ap.add_argument("--noise", type=float, default=0.5)
    ap.add_argument("--repeat", type=int, default=5000)
    args = ap.parse_args(argv)
    db = open_database(ensure_default_database())
    preset = PRESETS[args.camera]
    cam = preset.camera
    frame = simulate_frames(cam, 4, SimConfig(mag_limit=preset.mag_limit, centroid_noise_px=args.noise,
                                              false_stars=2), rng=5)[3]
    opts = pipeline.SolveOptions(centroid_sigma_px=args.noise)
    pipeline.solve(frame.centroids, cam, db, options=opts)  # warm-up, plans and caches
    plan, deepest = search_plan(db, [cam], "auto", args.noise)
    one = [(frame.centroids, cam, None)]
    obs = pipeline._observation(one, pipeline._ONE_CAMERA)
    fp = first_pass(obs, plan[0][0], deepest, args.noise, None, opts.max_false_prob)
    if not fp.solved:
        raise SystemExit("the first pass did not prove this frame; try another --camera or --noise")
    rows = [
        ("search plan", lambda: search_plan(db, [cam], "auto", args.noise)),
        ("refusal check", lambda: refusal(one, db, "auto", 0.0)),
        ("input to body vectors", lambda: pipeline._observation(one, pipeline._ONE_CAMERA).kernel_arrays),
        ("compiled first pass", lambda: first_pass(obs, plan[0][0], deepest, args.noise, None, opts.max_false_prob)),
        ("building the Solution", lambda: solution_of(*fp.columns, fp.rms_arcsec, fp.sigma_arcsec, fp.false_prob,
                                                      "quad")),
        ("reading its stars (when a caller does)", lambda: tuple(solution_of(*fp.columns, fp.rms_arcsec,
                                                                             fp.sigma_arcsec, fp.false_prob,
                                                                             "quad").stars)),
        ("whole solve", lambda: pipeline.solve(frame.centroids, cam, db, options=opts)),
    ]
    print(f"{args.camera}, {args.noise} px, {len(frame.centroids)} centroids, {len(fp.obs_rows)} pairs; "
          f"us per call over {args.repeat} calls")
    print("| stage | us |\n|---|---|")
    for label, fn in rows:
        print(f"| {label} | {_us(fn, args.repeat):.1f} |")


if __name__ == "__main__":
    main()
