"""The default database against a database built for each camera, by stars in the frame.

    python -m bench.bench_default_db --frames 500 [--camera seed000,...] [--noise 0.5] [--false 0]

For each paper camera: simulated frames (stars to the camera's limit, ``--noise`` px,
``--false`` false stars), solved by ``auto`` on the default database and on a database built
for the camera (``Preset.build_config`` with maxangle, pyramid and triangle). Rates are split
by the number of real stars in the frame (3, 4, 5, 6-9, 10+); wrong answers are counted apart.
"""

from __future__ import annotations

from . import common  # noqa: F401  (pins threads before numpy)

import argparse  # noqa: E402
import tempfile  # noqa: E402
from collections import defaultdict  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from pathlib import Path  # noqa: E402

from service.core.evaluate import score  # noqa: E402
from service.core.navdb import build_database, ensure_default_database, open_database  # noqa: E402
from service.core.pipeline import SolveOptions, solve  # noqa: E402
from service.core.presets import PRESETS  # noqa: E402
from service.core.sim import SimConfig, simulate_frames  # noqa: E402

BINS = ("<=2", "3", "4", "5", "6-9", "10+")


def _bin(n: int) -> str:
    return "<=2" if n <= 2 else str(n) if n <= 5 else "6-9" if n <= 9 else "10+"


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=500)
    ap.add_argument("--camera", default="seed000,seed001,seed002,seed003,seed004")
    ap.add_argument("--noise", type=float, default=0.5)
    ap.add_argument("--false", type=int, default=0)
    ap.add_argument("--seed", type=int, default=11)
    args = ap.parse_args(argv)
    default = open_database(ensure_default_database())
    print(f"{args.frames} frames a camera, {args.noise} px, {args.false} false stars, auto\n")
    print("| camera | database | " + " | ".join(f"{b} stars" for b in BINS) + " | all | wrong |")
    print("|---|---|" + "---|" * (len(BINS) + 2))
    with tempfile.TemporaryDirectory() as tmp:
        for key in args.camera.split(","):
            preset = PRESETS[key]
            own = open_database(build_database(Path(tmp) / key, preset.build_config(("maxangle", "pyramid", "triangle"))))
            config = SimConfig(mag_limit=preset.mag_limit, centroid_noise_px=args.noise, false_stars=args.false)
            frames = simulate_frames(preset.camera, args.frames, config, rng=args.seed)
            opts = SolveOptions(centroid_sigma_px=max(args.noise, 0.1))
            for label, db in (("default", default), ("own", own)):
                tally: dict[str, list[int]] = defaultdict(lambda: [0, 0])
                wrong = 0
                for f in frames:
                    sol = solve(f.centroids, preset.camera, db, options=opts)
                    s = score(sol, f.quaternion, f.hip.tolist(), blends=f.blends)
                    ok = sol.solved and bool(s.correct)
                    wrong += sol.solved and not s.correct
                    t = tally[_bin(int((f.hip >= 0).sum()))]
                    t[0] += 1
                    t[1] += ok
                cells = [f"{t[1]}/{t[0]}" if (t := tally.get(b)) else "-" for b in BINS]
                solved = sum(t[1] for t in tally.values())
                print(f"| {key} | {label} | " + " | ".join(cells) + f" | {100 * solved / len(frames):.1f}% | {wrong} |",
                      flush=True)


if __name__ == "__main__":
    main()
