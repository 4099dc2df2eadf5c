"""Wrong answers at scale: the noise x false-star x magnitude-noise grid of every paper camera.

    python -m bench.bench_wrong --frames 100000            # ~830 frames a cell, 120 cells
    python -m bench.bench_wrong --frames 2000 --camera seed003

Solved by ``auto`` on the default database (the product path) with ``centroid_sigma_px``
matched to the simulated noise. Every wrong answer is printed with what replays it: camera,
cell, seed and frame index (``Scenario`` seeds are deterministic). Writes
``bench/out/wrong.json``. A benchmark, not a test: minutes to hours.
"""

from __future__ import annotations

from . import common  # noqa: F401  (pins threads before numpy)

import argparse  # noqa: E402
import hashlib  # noqa: E402
import itertools  # noqa: E402
import time  # noqa: E402
from collections.abc import Sequence  # noqa: E402

from service.core.evaluate import score  # noqa: E402
from service.core.navdb import ensure_default_database, open_database  # noqa: E402
from service.core.pipeline import SolveOptions, solve  # noqa: E402
from service.core.presets import PRESETS  # noqa: E402
from service.core.sim import SimConfig, simulate_frames  # noqa: E402

NOISE = (0.25, 0.5, 1.0, 2.0)
FALSE = (0, 2, 5)
MAG_NOISE = (0.0, 0.3)


def cell_seed(base: int, camera: str, noise: float, false: int, mag_noise: float) -> int:
    h = hashlib.sha256(f"wrong/{base}/{camera}/{noise:g}/{false}/{mag_noise:g}".encode()).digest()
    return int.from_bytes(h[:8], "little")


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=100_000, help="Total frames over the whole grid.")
    ap.add_argument("--camera", default="seed000,seed001,seed002,seed003,seed004")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    cameras = args.camera.split(",")
    cells = list(itertools.product(cameras, NOISE, FALSE, MAG_NOISE))
    per_cell = max(1, args.frames // len(cells))
    db = open_database(ensure_default_database())
    total = solved = named = 0
    wrong: list[dict[str, object]] = []
    t0 = time.perf_counter()
    for cam_key, noise, false, mag_noise in cells:
        preset = PRESETS[cam_key]
        seed = cell_seed(args.seed, cam_key, noise, false, mag_noise)
        config = SimConfig(mag_limit=preset.mag_limit, centroid_noise_px=noise, false_stars=false, mag_noise=mag_noise)
        opts = SolveOptions(centroid_sigma_px=max(noise, 0.1))
        n_solved = 0
        for i, f in enumerate(simulate_frames(preset.camera, per_cell, config, rng=seed)):
            sol = solve(f.centroids, preset.camera, db, options=opts)
            if not sol.solved:
                continue
            n_solved += 1
            s = score(sol, f.quaternion, f.hip.tolist(), blends=f.blends)
            named += len(sol.stars) - s.wrong_stars
            if not s.correct:
                wrong.append({"camera": cam_key, "noise_px": noise, "false_stars": false, "mag_noise": mag_noise,
                              "seed": seed, "frames": per_cell, "index": i, "method": sol.method,
                              "wrong_stars": s.wrong_stars, "cross_arcsec": s.cross_boresight_arcsec,
                              "false_match_probability": sol.false_match_probability})
                print("WRONG", wrong[-1], flush=True)
        total += per_cell
        solved += n_solved
        print(f"{cam_key} {noise:g} px {false} false {mag_noise:g} mag: {n_solved}/{per_cell} solved; "
              f"{len(wrong)} wrong so far; {time.perf_counter() - t0:.0f} s", flush=True)
    print(f"\n{total} frames, {solved} identified ({100 * solved / max(total, 1):.1f}%), {len(wrong)} wrong, "
          f"{named} stars named right ({named / max(solved, 1):.2f} a frame identified)")
    common.write_json(common.OUT / "wrong.json", {"frames": total, "solved": solved, "stars_named_right": named,
                                                  "wrong": wrong,
                                                  "command": common.command_line(["bench.bench_wrong", *(argv or [])])})


if __name__ == "__main__":
    main()
