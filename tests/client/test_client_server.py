"""Client, AsyncClient and Stream against a real skyfix server on loopback."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from client import (
    AsyncClient,
    Client,
    RecordedFrame,
    SkyfixFrameError,
    SkyfixHTTPError,
    SolveRequest,
    read_recording,
)

from .conftest import ServerProcess


@pytest.fixture(scope="module")
def sim_frames(sim_recording: Path) -> list[RecordedFrame]:
    return list(read_recording(sim_recording))


def request(frame: RecordedFrame) -> SolveRequest:
    return SolveRequest(id=frame.id, camera=frame.camera, centroids=frame.centroids)


def assert_matches_truth(frame: RecordedFrame, stars: list) -> None:  # type: ignore[type-arg]
    assert frame.truth is not None and frame.truth.hip is not None
    assert stars
    for star in stars:
        assert star.hip == frame.truth.hip[star.centroid]


def test_health_and_info(server: ServerProcess) -> None:
    with Client(server.url) as sky:
        health = sky.health()
        info = sky.info()
    assert health.status == "ok" and health.n_stars > 1000
    assert "auto" in info.methods and info.limits.max_centroids > 0


def test_solve_centroids(server: ServerProcess, sim_frames: list[RecordedFrame]) -> None:
    frame = sim_frames[0]
    with Client(server.url) as sky:
        result = sky.solve(frame.centroids, camera=frame.camera, id=frame.id)
    assert result.status == "solved" and result.id == frame.id
    assert_matches_truth(frame, result.stars)


def test_server_errors_carry_message_and_field(server: ServerProcess) -> None:
    cam = {"width": 1024, "height": 768, "fov_deg": 11.4}
    with Client(server.url) as sky:
        with pytest.raises(SkyfixHTTPError) as info:
            sky.solve([[1, 2], [3, 4]], camera=cam, method="no-such-method")
        assert info.value.status == 422 and info.value.field == "method"
        assert "no-such-method" in info.value.detail
        with pytest.raises(SkyfixHTTPError) as info:
            sky.solve([[1, 2], [3, 4]], camera="no-such-camera")
        assert info.value.status == 422 and info.value.field == "camera"


def test_async_client_many_in_flight(server: ServerProcess, sim_frames: list[RecordedFrame]) -> None:
    async def main() -> list:  # type: ignore[type-arg]
        async with AsyncClient(server.url) as sky:
            return await asyncio.gather(*(sky.solve(request(f)) for f in sim_frames[:8]))

    results = asyncio.run(main())
    assert [r.id for r in results] == [f.id for f in sim_frames[:8]]
    for frame, result in zip(sim_frames[:8], results, strict=True):
        if result.status == "solved":
            assert_matches_truth(frame, result.stars)
    assert sum(r.status == "solved" for r in results) >= 7


def test_stream_pipelines_and_survives_a_bad_frame(server: ServerProcess,
                                                   sim_frames: list[RecordedFrame]) -> None:
    with Client(server.url).stream(track=False) as stream:
        for frame in sim_frames[:5]:
            stream.send(request(frame))
        stream.send({"id": "bad", "camera": "no-such-camera", "centroids": [[1, 2]]})
        stream.send(request(sim_frames[5]))
        got = []
        with pytest.raises(SkyfixFrameError) as info:
            for result in stream.results():
                got.append(result.id)
        assert info.value.frame_id == "bad" and info.value.status == 422 and info.value.field == "camera"
        got += [r.id for r in stream.results()]
        assert stream.unacknowledged == []
    assert got == [f.id for f in sim_frames[:6]]


def test_api_key(db_path: Path, tmp_path: Path, sim_frames: list[RecordedFrame]) -> None:
    srv = ServerProcess(db_path, env={"SKYFIX_API_KEY": "s3cret"}, log=tmp_path / "log").start()
    try:
        with Client(srv.url) as sky, pytest.raises(SkyfixHTTPError) as info:
            sky.solve(request(sim_frames[0]))
        assert info.value.status == 401 and info.value.field == "X-API-Key"
        with Client(srv.url, api_key="s3cret") as sky:
            assert sky.solve(request(sim_frames[0])).status == "solved"
            with sky.stream() as stream:
                assert stream.solve(request(sim_frames[1])).id == sim_frames[1].id
        with pytest.raises(SkyfixHTTPError) as info, Client(srv.url, retries=0).stream() as stream:
            stream.solve(request(sim_frames[1]))
        assert info.value.status == 403
    finally:
        srv.kill()


def test_images_over_rest_and_stream(server: ServerProcess) -> None:
    from .conftest import REAL

    tiff = REAL / "tetra3" / "2019-07-29T204726_Alt40_Azi-135_Try1.tiff"
    if not tiff.is_file():
        pytest.skip("real images not found")
    cam = {"width": 1024, "height": 768, "fov_deg": 11.425}
    with Client(server.url) as sky:
        rest = sky.solve_image(tiff, camera=cam, id="t1")
        with sky.stream(camera=cam) as stream:
            streamed = stream.solve({"id": "c", "camera": cam, "centroids": [[1, 2], [30, 40], [500, 600]]})
            stream.send_image(tiff.read_bytes(), id="t2")
            ws = stream.recv()
    assert rest.status == "solved" and rest.id == "t1" and len(rest.stars) >= 5
    assert streamed.id == "c" and ws.id == "t2" and ws.status == "solved"
    assert ws.quaternion == pytest.approx(rest.quaternion, abs=1e-9)


def test_no_solution_reason_reaches_the_client(server: ServerProcess) -> None:
    cam = {"width": 1024, "height": 768, "fov_deg": 11.4}
    with Client(server.url) as sky:
        result = sky.solve([[1, 2], [3, 4]], camera=cam)
        outside = sky.solve([[1, 2], [300, 400], [500, 60]], camera={**cam, "fov_deg": 1.0})
    assert result.status == "no_solution" and result.reason == "too_few_stars" and result.methods_tried == []
    assert outside.reason == "camera_outside_database" and "skyfix db build" in (outside.message or "")


def test_reason_values_match_the_engine() -> None:
    import typing

    from client.models import NoSolutionReason
    from service.core.types import NoSolutionReason as EngineReason

    assert set(typing.get_args(NoSolutionReason)) == {r.value for r in EngineReason}
