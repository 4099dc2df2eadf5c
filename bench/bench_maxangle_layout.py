"""maxangle's two table layouts on the same triangles: records read, time per query, same rows.

    python -m bench.bench_maxangle_layout [--db default] [--member mid] [--camera seed000] [--noise 1.0]

Opens a database (default: the default set; ``--member`` picks one of its members), takes its
``maxangle`` table in the layout it was built in and builds the other layout of the same records
in memory (:mod:`service.core.methods.maxangle_index`). The observed triangles of ``--frames``
random-point frames (11-39 points) and as many simulated frames (2 false stars) of ``--camera``
are queried through both, as ``maxangle`` queries them (the 8 brightest stars, candidates capped
at ``MAX_CANDIDATES``). Prints the median of ``--passes`` timed passes per layout, in us a
triangle and ms a frame, and the records both layouts return and those only one does: a record
exactly on a tolerance's edge may fall either side, as the layouts store ``theta`` or ``b`` in
float32 where the other keeps it in the float64 key (a few in 10^5).
"""

from __future__ import annotations

from . import common  # noqa: F401  (pins threads before numpy)

import argparse  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from types import SimpleNamespace  # noqa: E402

import numpy as np  # noqa: E402

from service.core.geometry import pairwise_angles  # noqa: E402
from service.core.methods import get_matcher  # noqa: E402
from service.core.methods.maxangle import MAX_CANDIDATES, MaxAngleMatcher  # noqa: E402
from service.core.methods.maxangle_index import (  # noqa: E402
    N_BLOCKS,
    N_CELLS,
    THETA_LO,
    THETA_SPAN,
    bucket_starts,
    cell_key,
    paper_bucket_starts,
    paper_key,
)
from service.core.navdb import NavDatabaseSet, ensure_default_database, open_database  # noqa: E402
from service.core.pipeline import _IDENTITY, _observation  # noqa: E402
from service.core.presets import PRESETS  # noqa: E402
from service.core.sim import SimConfig, random_points, simulate_frames  # noqa: E402


def other_layout(m: MaxAngleMatcher) -> SimpleNamespace:
    """The matcher's records in the other layout, as a matcher-like namespace."""
    c = np.asarray(m.c, np.float64)
    if m.layout == "cells":
        key = np.asarray(m.key)
        b = np.asarray(m.b, np.float64)
        theta = THETA_LO + (key - np.floor(key)) * THETA_SPAN
        n_blocks = N_BLOCKS
        new_key = paper_key(theta, b, n_blocks, m.b_scale)
        order = np.argsort(new_key, kind="stable")
        return SimpleNamespace(layout="paper", key=new_key[order], ids=np.ascontiguousarray(m.ids[order]),
                               c=np.asarray(m.c)[order], theta=theta[order].astype(np.float32), n_blocks=n_blocks,
                               bucket_start=paper_bucket_starts(new_key[order], n_blocks))
    key = np.asarray(m.key)
    b32 = ((key - np.floor(key)) * m.b_scale).astype(np.float32)
    new_key = cell_key(np.asarray(m.theta, np.float64), b32, c.astype(np.float32), N_CELLS, m.b_scale)
    order = np.argsort(new_key, kind="stable")
    return SimpleNamespace(layout="cells", key=new_key[order], ids=np.ascontiguousarray(m.ids[order]),
                           b=b32[order], c=np.asarray(m.c)[order], n_cells=N_CELLS,
                           bucket_start=bucket_starts(new_key[order], N_CELLS * N_CELLS))


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--db", default="default", help="'default' or a database path")
    ap.add_argument("--member", default="mid", help="member of a database set")
    ap.add_argument("--camera", default="seed000")
    ap.add_argument("--noise", type=float, default=1.0, help="centroid sigma, px (frames and tolerance)")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--passes", type=int, default=5)
    args = ap.parse_args(argv)
    db = open_database(ensure_default_database() if args.db == "default" else args.db)
    if isinstance(db, NavDatabaseSet):
        db = db.members[args.member]
    built = get_matcher(db, "maxangle")
    other = other_layout(built)
    layouts = {built.layout: built, other.layout: SimpleNamespace(**{**vars(built), **vars(other)})}
    p = PRESETS[args.camera]
    rng = np.random.default_rng(5)
    randoms = [random_points(p.camera, int(n), rng) for n in rng.integers(11, 40, args.frames)]
    sims = [f.centroids for f in simulate_frames(
        p.camera, args.frames, SimConfig(mag_limit=p.mag_limit, centroid_noise_px=args.noise, false_stars=2), rng=3)]
    print(f"maxangle query, {args.db} {args.member if args.db == 'default' else ''} ({len(built.key)} triangles), "
          f"{args.camera} at {args.noise} px; median of {args.passes} passes\n")
    print("| frames | triangles a frame | " + " | ".join(f"{name}: us a triangle, ms a frame" for name in layouts)
          + " | records in both / in one only |")
    print("|---|---|" + "---|" * len(layouts) + "---|")
    for label, frames in (("random points", randoms), ("simulated, 2 false", sims)):
        queries = []
        for cents in frames:
            obs = _observation([(cents, p.camera, None)], [_IDENTITY])
            v = obs.vec[:8]
            eps = (3.0 * math.sqrt(2.0) * args.noise + 0.5) * obs.pixel_scale_rad
            labels, sides, theta, tol = built.observed_triangles(pairwise_angles(v), eps)
            queries.append((sides, theta, tol, eps, labels, v))
        n_tri = sum(len(q[1]) for q in queries)
        times, found = {}, {}
        for name, m in layouts.items():
            run = []
            for _ in range(args.passes):
                t0 = time.perf_counter()
                rows = [MaxAngleMatcher.query_many(m, *q, MAX_CANDIDATES) for q in queries]
                run.append(time.perf_counter() - t0)
            times[name] = float(np.median(run))
            found[name] = [sorted(zip(w.tolist(), map(tuple, np.asarray(m.ids)[r].tolist()), strict=True))
                           for r, w in rows]
        a, b = ({rec for i, recs in enumerate(found[n]) for rec in ((i, *r) for r in recs)} for n in layouts)
        cells = " | ".join(f"{times[n] * 1e6 / max(n_tri, 1):.1f}, {times[n] * 1e3 / len(frames):.3f}" for n in layouts)
        print(f"| {label} | {n_tri / len(frames):.1f} | {cells} | {len(a & b)} / {len(a ^ b)} |")


if __name__ == "__main__":
    main()
