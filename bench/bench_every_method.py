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

Per cell: right answers (%), wrong answers, refused frames, median ms a frame (refusals
included); each camera's header counts the frames holding 4 or more real stars (a frame of 3
only ``triangle``'s unique-triangle proof can name). Output: ``bench/out/every-method.{md,json}``; the table is printed too.
"""

from __future__ import annotations

from bench import common  # noqa: I001  (first: pins BLAS threads before numpy loads)

import argparse  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

from bench.common import (  # noqa: E402
    OUT, PRESETS, SkyfixSolver, build_skyfix_db, judge, machine_info, machine_line, md_table, scenarios, summarize,
    write_json,
)
from service.core.methods import method_names  # noqa: E402
from service.core.navdb import open_database  # noqa: E402
from service.core.refusal import method_refusal  # noqa: E402

PUBLISHED = ("maxangle", "multifov", "radial", "dmv", "pso", "triangle", "pyramid")
"""The seven methods of the source papers (seeds 000-004) and their baselines; ``quad`` is ours."""
NOISE_PX = 0.5


def cell(row: dict[str, Any]) -> str:
    """One table cell: the rate, or the refusal and its reason."""
    if row.get("refused_why"):
        return f"refused ({row['refused_why']})"
    return (f"{100 * row['rate']:.1f}% ({row['wrong']} wrong, {row['refused']} refused, "
            f"{row['ms_median']:.1f} ms)")


def run_camera(cam: str, frames_n: int, seed: int, db_dir: Path) -> list[dict[str, Any]]:
    """Every method of ``PUBLISHED`` and ``auto`` on ``frames_n`` frames of camera ``cam``."""
    preset = PRESETS[cam]
    path, _ = build_skyfix_db(preset, method_names(), db_dir / cam, reuse=True)
    db = open_database(path)
    frames = scenarios(cam, "noise", [NOISE_PX])[0].frames(frames_n, seed)
    rows = []
    for m in (*PUBLISHED, "auto"):
        why = method_refusal([preset.camera], db, m, NOISE_PX) if m != "auto" else None
        solver = SkyfixSolver(db, m, sigma=NOISE_PX)
        judged, refused = [], 0
        for f in frames:
            a = solver.solve(f.centroids, preset.camera, NOISE_PX)
            judged.append(judge(a, f.quaternion, f.hip.tolist(), f.blends))
            refused += a.status == "no_solution" and why is not None
        st = summarize(judged)
        short = why.split(": ", 1)[1].rsplit("; use", 1)[0] if why else None
        rows.append({"camera": cam, "method": m, **st, "refused": refused, "refused_why": short, "message": why,
                     "frames_4_stars": sum(int((f.hip >= 0).sum()) >= 4 for f in frames)})
        print(f"[{cam}] {m}: {cell(rows[-1])}", flush=True)
    return rows


def render(rows: list[dict[str, Any]], cams: list[str], args: argparse.Namespace, info: dict[str, Any]) -> str:
    by = {(r["camera"], r["method"]): r for r in rows}
    header = ["method", *(f"{c} ({PRESETS[c].camera.fov_deg:.3g} deg, {PRESETS[c].mag_limit:g} Mv; "
                          f"{by[(c, 'auto')]['frames_4_stars']} frames of 4+ stars)" for c in cams)]
    table = md_table(header, [[m, *(cell(by[(c, m)]) for c in cams)] for m in (*PUBLISHED, "auto")])
    cmd = "python -m bench.bench_every_method " + " ".join(sys.argv[1:])
    return (f"{args.frames} frames per cell at {NOISE_PX} px, 2 false stars, no magnitude noise; cell = right "
            f"(wrong answers, refused frames, median ms a frame).\n\n{table}\n\n`{cmd}`; {machine_line(info)}\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--camera", default=",".join(PRESETS), help="comma-separated preset names")
    ap.add_argument("--seed", type=int, default=16)
    ap.add_argument("--db-dir", default=str(OUT / "db"))
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args(argv)
    info = machine_info()
    cams = args.camera.split(",")
    rows = [r for c in cams for r in run_camera(c, args.frames, args.seed, Path(args.db_dir))]
    md = render(rows, cams, args, info)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "every-method.md").write_text(md)
    write_json(out / "every-method.json", {"rows": rows, "machine": info, "args": vars(args)})
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
