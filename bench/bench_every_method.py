"""Every published method, and ``auto``, on every paper camera's database, or its refusal (issue 16).

    python -m bench.bench_every_method --frames 100

For each paper camera (``PRESETS`` seed000..seed004): a database built for it with every
registered method (``Preset.build_config``; reused from ``--db-dir`` when one that opens is
there, as ``bench_methods --reuse-db`` leaves them), the noise sweep's 0.5 px point of
``bench_methods`` (0.5 px Gaussian centroid noise, 2 false stars at random pixels, no magnitude
noise; the same frames for every method) and ``SolveOptions(centroid_sigma_px=0.5)``, 500 ms a
frame. Each of the seven published methods (``maxangle``, ``multifov``, ``radial``, ``dmv``,
``pso``, ``triangle``, ``pyramid``) and ``auto`` is asked by name; a method that cannot serve the
camera on that database (``service.core.methods.capability``) is answered at once with reason
``camera_outside_database``, and its cell says so with the reason.

``--db PATH --fov 12 --px 1024 --mag 6.0,6.5`` runs a given database instead: a square camera
of that field and pixel count, frames to each magnitude limit (one column each), at the same
0.5 px and 2 false stars; the issue's case:

    python -m bench.bench_every_method --db DB --fov 12 --px 1024 --mag 6.5,6.0 --frames 100

Per cell: right answers (%), wrong answers, refused frames, median ms a frame (refusals
included); each camera's header counts the frames holding 4 or more real stars (a frame of 3
only ``triangle``'s unique-triangle proof can name). Output: ``bench/out/every-method.{md,json}``; the table is printed too.
"""

from __future__ import annotations

from bench import common  # noqa: I001  (first: pins BLAS threads before numpy loads)

import argparse  # noqa: E402
import sys  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

from bench.common import (  # noqa: E402
    OUT, PRESETS, SkyfixSolver, build_skyfix_db, judge, machine_info, machine_line, md_table, scenarios, summarize,
    write_json,
)
from service.core.camera import Camera  # noqa: E402
from service.core.methods import method_names  # noqa: E402
from service.core.navdb import open_database  # noqa: E402
from service.core.refusal import method_refusal  # noqa: E402
from service.core.sim import SimConfig, SimFrame, simulate_frames  # noqa: E402

PUBLISHED = ("maxangle", "multifov", "radial", "dmv", "pso", "triangle", "pyramid")
"""The seven methods of the source papers (seeds 000-004) and their baselines; ``quad`` is ours."""
NOISE_PX = 0.5
FALSE_STARS = 2
"""As ``bench_methods``' noise sweep (``common.SWEEPS["noise"]``)."""


def cell(row: dict[str, Any]) -> str:
    """One table cell: the rate, or the refusal and its reason."""
    if row.get("absent"):
        return "not in the database"
    if row.get("refused_why"):
        return f"refused ({row['refused_why']})"
    return (f"{100 * row['rate']:.1f}% ({row['wrong']} wrong, {row['refused']} refused, "
            f"{row['ms_median']:.1f} ms)")


@dataclass
class Column:
    """One column of the table: a camera, its database and its frames."""

    label: str
    camera: Camera
    db: Any
    frames: list[SimFrame]


def paper_column(cam: str, frames_n: int, seed: int, db_dir: Path) -> Column:
    """A paper camera on its own database (built with every method, or reused), with
    ``bench_methods``' frames of the 0.5 px noise point."""
    preset = PRESETS[cam]
    path, _ = build_skyfix_db(preset, method_names(), db_dir / cam, reuse=True)
    frames = scenarios(cam, "noise", [NOISE_PX])[0].frames(frames_n, seed)
    return Column(f"{cam} ({preset.camera.fov_deg:.3g} deg, {preset.mag_limit:g} Mv", preset.camera,
                  open_database(path), frames)


def given_column(db: Any, fov: float, px: int, mag: float, frames_n: int, seed: int) -> Column:
    """A square ``fov``-deg camera of ``px`` pixels seeing stars to ``mag`` on a given database,
    at 0.5 px with 2 false stars."""
    camera = Camera.from_fov(fov, px, px)
    config = SimConfig(mag_limit=mag, centroid_noise_px=NOISE_PX, false_stars=FALSE_STARS)
    return Column(f"{fov:g} deg, {px} px (frames to {mag:g} Mv", camera, db,
                  simulate_frames(camera, frames_n, config, rng=seed))


def run_column(col: Column) -> list[dict[str, Any]]:
    """Every method of ``PUBLISHED`` and ``auto`` on the column's frames."""
    rows = []
    n4 = sum(int((f.hip >= 0).sum()) >= 4 for f in col.frames)
    held = getattr(col.db, "any_methods", None) or col.db.methods
    for m in (*PUBLISHED, "auto"):
        if m != "auto" and m not in held:
            rows.append({"camera": col.label, "method": m, "absent": True, "frames_4_stars": n4})
            continue
        why = method_refusal([col.camera], col.db, m, NOISE_PX)
        solver = SkyfixSolver(col.db, m, sigma=NOISE_PX)
        judged, refused = [], 0
        for f in col.frames:
            a = solver.solve(f.centroids, col.camera, NOISE_PX)
            judged.append(judge(a, f.quaternion, f.hip.tolist(), f.blends))
            refused += a.status == "no_solution" and why is not None
        st = summarize(judged)
        short = why.split(": ", 1)[1].rsplit("; use", 1)[0] if why else None
        rows.append({"camera": col.label, "method": m, **st, "refused": refused, "refused_why": short,
                     "message": why, "frames_4_stars": n4})
        print(f"[{col.label}] {m}: {cell(rows[-1])}", flush=True)
    return rows


def render(rows: list[dict[str, Any]], labels: list[str], args: argparse.Namespace, info: dict[str, Any]) -> str:
    by = {(r["camera"], r["method"]): r for r in rows}
    header = ["method", *(f"{c}; {by[(c, 'auto')]['frames_4_stars']} frames of 4+ stars)" for c in labels)]
    table = md_table(header, [[m, *(cell(by[(c, m)]) for c in labels)] for m in (*PUBLISHED, "auto")])
    cmd = "python -m bench.bench_every_method " + " ".join(sys.argv[1:])
    return (f"{args.frames} frames per cell at {NOISE_PX} px, {FALSE_STARS} false stars, no magnitude noise; "
            f"cell = right (wrong answers, refused frames, median ms a frame).\n\n{table}\n\n`{cmd}`; "
            f"{machine_line(info)}\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--camera", default=",".join(PRESETS), help="comma-separated preset names")
    ap.add_argument("--seed", type=int, default=16)
    ap.add_argument("--db-dir", default=str(OUT / "db"))
    ap.add_argument("--out", default=str(OUT))
    ap.add_argument("--db", help="a given database instead of the paper cameras' (with --fov, --px, --mag)")
    ap.add_argument("--fov", type=float, default=12.0, help="--db: the square camera's field, deg")
    ap.add_argument("--px", type=int, default=1024, help="--db: its pixels a side")
    ap.add_argument("--mag", default="6.5", help="--db: comma-separated magnitude limits of the frames, one column each")
    args = ap.parse_args(argv)
    info = machine_info()
    if args.db:
        db = open_database(args.db)
        cols = [given_column(db, args.fov, args.px, float(m), args.frames, args.seed) for m in args.mag.split(",")]
    else:
        cols = [paper_column(c, args.frames, args.seed, Path(args.db_dir)) for c in args.camera.split(",")]
    rows = [r for col in cols for r in run_column(col)]
    md = render(rows, [c.label for c in cols], args, info)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "every-method.md").write_text(md)
    write_json(out / "every-method.json", {"rows": rows, "machine": info, "args": vars(args)})
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
