"""The batch path: recorded frames parsed and solved in forked workers (or threads), the same
answers as one by one."""

from __future__ import annotations

import os
import threading

import numpy as np
import pytest

from service.core.batch import Frame, FrameError, frame_from_record, solve_frame, solve_many
from service.core.camera import Camera
from service.core.errors import InvalidInputError
from service.core.navdb import NavDatabase
from service.core.pipeline import solve
from service.core.sim import SimConfig, simulate_frames

from ..conftest import SEED000_CAMERA


def _frames(n: int, seed: int) -> list[Frame]:
    sims = simulate_frames(SEED000_CAMERA, n, SimConfig(centroid_noise_px=0.5, false_stars=1), rng=seed)
    return [Frame(((sim.centroids, SEED000_CAMERA, None),), id=i) for i, sim in enumerate(sims)]


@pytest.mark.parametrize("pool", ["process", "thread"])
def test_solve_many_equals_one_by_one(seed000_db: NavDatabase, pool: str) -> None:
    frames = _frames(24, 5)
    one_by_one = [solve_frame(f, seed000_db) for f in frames]
    ran = solve_many(frames, seed000_db, workers=2, pool=pool, then=lambda rec, sol: (sol, os.getpid()))
    batched = [sol for sol, _ in ran]
    if pool == "process" and threading.active_count() == 1:  # else it falls back to threads
        assert os.getpid() not in {pid for _, pid in ran}, "solved in forked workers"
    assert sum(s.solved for s in one_by_one) >= 20
    for a, b in zip(one_by_one, batched, strict=True):
        assert a.status == b.status
        assert [s.hip for s in a.stars] == [s.hip for s in b.stars]
        if a.solved:
            assert np.allclose(a.quaternion, b.quaternion, atol=1e-12)


def test_frame_from_record_single_camera_and_rig() -> None:
    single = frame_from_record({"id": 3, "camera": {"width": 1024, "height": 1024, "fov_deg": 8.0},
                                "centroids": [[1, 2, 3], [4, 5, 6]], "truth": {"hip": [1, 2]}})
    assert single.id == 3 and not single.is_rig and len(single.views[0][0]) == 2
    assert isinstance(single.views[0][1], Camera) and single.truth == {"hip": [1, 2]}
    rig = frame_from_record({"cameras": [
        {"camera": {"width": 100, "height": 100, "fov_deg": 5, "mounting_quaternion": [1, 0, 0, 0]},
         "centroids": [[1, 2]]},
        {"camera": {"width": 100, "height": 100, "fov_deg": 5}, "centroids": []}]})
    assert rig.is_rig and len(rig.views) == 2


@pytest.mark.parametrize(("record", "field"), [
    ({"centroids": [[1, 2]]}, "camera"),
    ({"camera": {"width": 10, "height": 10, "fov_deg": 5}, "centroids": [[1, 2, 3, 4]]}, "centroids"),
    ({"cameras": [{"centroids": []}]}, "cameras[0].camera"),
    ([1, 2], "frame"),
])
def test_frame_from_record_names_the_field(record: object, field: str) -> None:
    with pytest.raises(InvalidInputError) as err:
        frame_from_record(record)  # type: ignore[arg-type]
    assert err.value.field == field


def test_solve_frame_matches_solve(seed000_db: NavDatabase) -> None:
    frame = _frames(1, 9)[0]
    cents, cam, _ = frame.views[0]
    a, b = solve_frame(frame, seed000_db), solve(cents, cam, seed000_db)
    assert a.status == b.status and [s.hip for s in a.stars] == [s.hip for s in b.stars]


def test_solve_many_parses_lines_in_the_workers_and_returns_errors(seed000_db: NavDatabase) -> None:
    """JSON lines are parsed and post-processed (``then``) in the forked workers; a bad line
    gives a FrameError naming the field in its place, the others are answered in order."""
    import json

    cam = {"width": 1024, "height": 1024, "focal_mm": 94.9489, "pixel_um": 14.0}
    sims = simulate_frames(SEED000_CAMERA, 40, SimConfig(centroid_noise_px=0.5), rng=8)
    lines = [json.dumps({"id": i, "camera": cam, "centroids": f.centroids.xy.tolist()})
             for i, f in enumerate(sims)]
    lines[7] = json.dumps({"id": 7, "centroids": [[1, 2]]})  # no camera
    out = solve_many(lines, seed000_db, workers=2, return_errors=True,
                     then=lambda rec, sol: (rec["id"], sol.solved, sol.reason))
    assert isinstance(out[7], FrameError) and out[7].field == "camera"
    assert [o[0] for i, o in enumerate(out) if i != 7] == [i for i in range(40) if i != 7]
    assert sum(o[1] for i, o in enumerate(out) if i != 7) >= 36
    for workers in (1, 2):  # raised in the caller, also from a forked worker (was: a hang)
        with pytest.raises(InvalidInputError, match="camera"):
            solve_many(lines[:20], seed000_db, workers=workers)


@pytest.mark.parametrize("pool", ["process", "thread"])
def test_solve_pool_serves_block_after_block_and_reads_a_generator_lazily(seed000_db: NavDatabase,
                                                                           pool: str) -> None:
    """One SolvePool answers several blocks in order on the same workers (forked once), and
    takes frames from a generator only as fast as it solves them."""
    from service.core.batch import CHUNK, CHUNKS_IN_FLIGHT, SolvePool

    frames = _frames(12, 21)
    want = [solve_frame(f, seed000_db).status for f in frames]
    with SolvePool(seed000_db, workers=2, pool=pool, then=lambda rec, sol: (rec.id, sol.status, os.getpid())) as sp:
        first = list(sp.imap(frames))
        second = list(sp.imap(frames[::-1]))
        assert [r[:2] for r in first] == [(i, s) for i, s in enumerate(want)]
        assert [r[:2] for r in second] == [(i, s) for i, s in enumerate(want)][::-1]
        if pool == "process" and sp._procs is not None:
            pids = {r[2] for r in first + second}
            assert os.getpid() not in pids and len(pids) <= 2, "the same two forked workers"

        taken = 0

        def endless():  # a live feed: never ends
            nonlocal taken
            while True:
                taken += 1
                yield frames[taken % len(frames)]

        answers = sp.imap(endless())
        got = [next(answers) for _ in range(5)]
        answers.close()  # cancels what is queued
        assert len(got) == 5
        assert taken <= (CHUNKS_IN_FLIGHT * 2 + 1) * CHUNK, "read ahead by at most the chunks in flight"


def test_solve_pool_names_a_bad_pool_and_solves_in_process_on_one_worker(seed000_db: NavDatabase) -> None:
    from service.core.batch import SolvePool

    with pytest.raises(ValueError, match="pool"):
        SolvePool(seed000_db, pool="gpu")
    with SolvePool(seed000_db, workers=1, then=lambda rec, sol: os.getpid()) as sp:
        assert set(sp.imap(_frames(3, 2))) == {os.getpid()}


def test_file_ranges_cover_the_file_and_shrink_to_its_end() -> None:
    from service.core.batch import RANGE_MAX_BYTES, RANGE_MIN_BYTES, file_ranges

    size = 10 * RANGE_MAX_BYTES + 12_345
    ranges = file_ranges(size, 2)
    assert ranges[0] == (0, RANGE_MAX_BYTES) and ranges[-1][1] == size
    assert all(a[1] == b[0] for a, b in zip(ranges, ranges[1:]))  # contiguous, no gap, no overlap
    steps = [e - s for s, e in ranges]
    assert steps == sorted(steps, reverse=True) and min(steps[:-1]) == RANGE_MIN_BYTES
    assert file_ranges(0, 2) == [] and file_ranges(10, 4) == [(0, 10)]


def _record_line(rec: dict) -> bytes:  # type: ignore[type-arg]
    import orjson

    return orjson.dumps(rec) + b"\n"


def _ids(pairs):  # type: ignore[no-untyped-def]
    """A fold for map_file (module level: it is pickled by name): each line's offset and answer."""
    return [(offset, answer) for offset, answer in pairs]


@pytest.mark.parametrize("workers", [1, 2])
def test_map_file_reads_every_line_once_across_range_bounds(seed000_db: NavDatabase, tmp_path,  # type: ignore[no-untyped-def]
                                                            monkeypatch: pytest.MonkeyPatch, workers: int) -> None:
    """Ranges far smaller than a line (forced here) still hand each non-blank line to exactly one
    worker, in file order, the same answers as one by one; blank lines and a last line without
    its newline included; a bad line comes back as a FrameError at its own offset."""
    from service.core import batch
    from service.core.batch import SolvePool

    monkeypatch.setattr(batch, "RANGE_MIN_BYTES", 97)  # lines are ~600 bytes: most ranges start mid-line
    monkeypatch.setattr(batch, "RANGE_MAX_BYTES", 1500)
    sims = simulate_frames(SEED000_CAMERA, 14, SimConfig(centroid_noise_px=0.5, false_stars=1), rng=8)
    cam = {"width": SEED000_CAMERA.width, "height": SEED000_CAMERA.height, "fov_deg": SEED000_CAMERA.fov_deg}
    lines = [_record_line({"id": i, "camera": cam, "centroids": np.column_stack(
        [s.centroids.xy, s.centroids.flux]).round(4).tolist()}) for i, s in enumerate(sims)]
    lines.insert(5, b"\n")
    lines.insert(9, b'{"id": "bad", "camera": {"width": 10}}\n')
    data = b"".join(lines)[:-1]  # the last line without its newline
    path = tmp_path / "rec.jsonl"
    path.write_bytes(data)
    with SolvePool(seed000_db, workers=workers, return_errors=True,
                   then=lambda rec, sol: (rec["id"], sol.status, [s.hip for s in sol.stars])) as sp:
        got = [pair for part in sp.map_file(path, _ids) for pair in part]
    offsets = [off for off, _ in got]
    starts = [data.index(line.rstrip(b"\n")) for line in lines if line.strip()]
    assert offsets == starts  # every non-blank line once, in order
    bad = [answer for _, answer in got if isinstance(answer, FrameError)]
    assert len(bad) == 1 and "camera" in (bad[0].field or bad[0].message)
    import orjson

    records = [orjson.loads(line) for line in lines if line.strip() and b'"bad"' not in line]
    want = [(rec["id"], sol.status, [m.hip for m in sol.stars])
            for rec, sol in ((rec, solve_frame(frame_from_record(rec), seed000_db)) for rec in records)]
    assert sum(status == "solved" for _, status, _ in want) >= 10
    assert [answer for _, answer in got if not isinstance(answer, FrameError)] == want
