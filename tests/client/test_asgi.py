"""``transport=`` is httpx's seam: the same client runs against the app in-process."""

from __future__ import annotations

import asyncio
from pathlib import Path

import httpx

from client import AsyncClient, read_recording
from client.replay import replay_frames


def test_async_client_and_replay_over_asgi_transport(db_path: Path, sim_recording: Path) -> None:
    from service.api import Settings, create_app

    app = create_app(Settings(db_path=db_path))
    frames = list(read_recording(sim_recording))[:6]

    async def main() -> tuple[str, int]:
        async with app.router.lifespan_context(app):  # ASGITransport does not run the lifespan
            transport = httpx.ASGITransport(app=app)
            async with AsyncClient("http://skyfix.test", transport=transport) as sky:
                health = await sky.health()
            report = await replay_frames(frames, url="http://skyfix.test", transport=transport, concurrency=2)
            return health.status, report.solved

    status, solved = asyncio.run(main())
    assert status == "ok"
    assert solved >= 5
