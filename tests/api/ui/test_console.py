"""The web console in real Chromium (Debian's ``chromium``, driven by Playwright) against a real
``skyfix serve`` on 127.0.0.1 over the default database.

Each test saves a screenshot to its tmp_path, and to ``$SKYFIX_SCREENSHOTS`` when set (the
docs' images: ``SKYFIX_SCREENSHOTS=docs/img pytest tests/api/ui``).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from ..conftest import ROOT, angle_deg, free_port, spawn_serve, stop_serve, wait_healthy

CHROMIUM = os.environ.get("SKYFIX_CHROMIUM", "/usr/bin/chromium")
REAL = Path(os.environ.get("SKYFIX_REAL_DATA", ROOT.parent / "shared" / "data" / "real"))
IMAGE = "cedar-solve/2019-07-29T204726_Alt40_Azi-135_Try1.jpg"
"""A JPEG (so the browser shows it too) of the tetra3 camera, 1024x768, 11.4 deg."""

sync_api = pytest.importorskip("playwright.sync_api", reason="playwright not installed (pip install playwright)")
pytestmark = pytest.mark.skipif(not Path(CHROMIUM).is_file(), reason=f"no chromium at {CHROMIUM}")


@pytest.fixture(scope="module")
def console(default_set_db: Any) -> Iterator[str]:
    """``skyfix serve`` over the default database (built by the session fixture), one named camera."""
    port = free_port()
    cameras = json.dumps({"tetra3": {"width": 1024, "height": 768, "fov_deg": 11.4}})
    proc = spawn_serve("--port", str(port), env={"SKYFIX_CAMERAS": cameras})
    url = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(url, proc)
        yield url
    finally:
        stop_serve(proc)


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox", "--disable-gpu"])
        yield b
        b.close()


@pytest.fixture
def page(browser: Any) -> Iterator[Any]:
    ctx = browser.new_context(viewport={"width": 1360, "height": 1000})
    pg = ctx.new_page()
    pg.errors = []  # uncaught exceptions and CSP refusals: none is expected
    pg.on("pageerror", lambda e: pg.errors.append(str(e)))
    pg.on("console", lambda m: pg.errors.append(m.text) if "Content Security Policy" in m.text else None)
    yield pg
    ctx.close()


def screenshot(page: Any, tmp_path: Path, name: str) -> Path:
    out = tmp_path / name
    page.screenshot(path=str(out), full_page=True)
    if os.environ.get("SKYFIX_SCREENSHOTS"):
        dest = Path(os.environ["SKYFIX_SCREENSHOTS"])
        dest.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(out, dest / name)
    assert out.stat().st_size > 10_000
    return out


def wait_for(check: Callable[[], Any], timeout_s: float = 30, what: str = "condition") -> Any:
    """Poll ``check`` from Python (the page's CSP forbids Playwright's string evaluation)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = check()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what}")


def slew_recording(path: Path, n: int) -> Path:
    """A rig slewing through Orion, 0.4 deg a frame (the tetra3 camera, 0.2 px noise, one false star)."""
    import numpy as np

    from service.core.attitude import matrix_from_radec_roll, matrix_to_quat
    from service.core.camera import Camera
    from service.core.sim import SimConfig, simulate_frame

    cam = Camera.from_fov(11.4, 1024, 768)
    config = SimConfig(mag_limit=6.0, centroid_noise_px=0.2, false_stars=1, max_stars=30)
    rng = np.random.default_rng(7)
    with path.open("w") as fh:
        for i in range(n):
            r = matrix_from_radec_roll(70.0 + 0.4 * i, 2.0 - 0.1 * i, 30.0 + 0.2 * i)
            frame = simulate_frame(cam, matrix_to_quat(r), config, rng)
            fh.write(json.dumps(frame.to_record(i, cam, camera_spec={"width": 1024, "height": 768,
                                                                       "fov_deg": 11.4})) + "\n")
    return path


def number(text: str) -> float:
    return float(re.search(r"-?\d+(\.\d+)?", text).group())  # type: ignore[union-attr]


@pytest.mark.skipif(not (REAL / IMAGE).is_file(), reason=f"real images absent ({REAL})")
def test_an_uploaded_real_image_has_its_stars_named_and_its_attitude_within_0_1_deg(
        console: str, page: Any, tmp_path: Path) -> None:
    truth = json.loads((REAL / "truth.json").read_text())["images"][IMAGE]
    resp = page.goto(console + "/ui/solve")
    csp = resp.headers["content-security-policy"]
    assert "script-src 'self'" in csp and "unsafe" not in csp and "default-src 'none'" in csp
    page.fill("#fov", "11.4")
    page.set_input_files("#file", str(REAL / IMAGE))
    wait_for(lambda: page.text_content("#result-json"), what="the result")
    assert page.is_visible("#progress") and page.get_attribute("#progress", "value") == "1"
    result = json.loads(page.text_content("#result-json"))
    assert result["status"] == "solved"
    assert angle_deg(result["quaternion"], truth["quaternion_icrs_to_camera_wxyz"]) < 0.1
    shown = {row.locator("td").nth(0).text_content(): row.locator("td").nth(1).text_content()
             for row in page.locator("#attitude tr").all()}
    assert abs(number(shown["RA"]) - truth["ra_deg"]) < 0.1
    assert abs(number(shown["Dec"]) - truth["dec_deg"]) < 0.1
    assert abs((number(shown["roll"]) - truth["up_pa_deg"] + 180) % 360 - 180) < 0.1
    assert "e-" in shown["false-match probability"]
    named = page.locator("#stars tr").count() - 1
    assert named == len(result["stars"]) >= 10
    assert page.get_attribute("#image", "data-identified") == str(named)
    assert int(page.get_attribute("#image", "data-detected")) == result["n_detected"] == len(result["centroids"])
    first = page.locator("#stars tr").nth(1).locator("td").nth(0).text_content()
    assert int(first) == result["stars"][0]["hip"]
    assert page.is_visible("#dl-json") and page.is_visible("#dl-wcs")
    with page.expect_download() as dl:
        page.click("#dl-wcs")
    header = Path(dl.value.path()).read_bytes()
    assert len(header) % 2880 == 0 and header.startswith(b"SIMPLE  =")
    cards = {header[i:i + 8].decode().strip(): header[i + 10:i + 80].decode() for i in range(0, len(header), 80)}
    assert abs(float(cards["CRVAL1"].split("/")[0]) - result["wcs"]["CRVAL1"]) < 1e-9
    assert page.errors == []
    screenshot(page, tmp_path, "console-solve.png")


def test_a_bad_file_and_a_bad_field_show_the_service_message(console: str, page: Any, tmp_path: Path) -> None:
    bad = tmp_path / "notes.png"
    bad.write_bytes(b"these are notes, not a picture of the sky\n" * 10)
    expected = httpx.post(console + "/v1/solve/image", files={"image": ("notes.png", bad.read_bytes())},
                          data={"fov_deg": "11.4"}).json()
    page.goto(console + "/ui/solve")
    page.fill("#fov", "11.4")
    page.set_input_files("#file", str(bad))
    error = wait_for(lambda: page.is_visible("#error") and page.text_content("#error"), what="the error")
    assert error == f"422 {expected['field']}: {expected['detail']}"
    page.fill("#fov", "-3")
    page.set_input_files("#file", str(bad))
    wait_for(lambda: "fov_deg" in page.text_content("#error"), what="the field error")
    assert page.text_content("#error").startswith("422 fov_deg: ")
    page.fill("#fov", "11.4")
    page.set_input_files("#file", str(bad))
    wait_for(lambda: page.text_content("#error") == error, what="the first error again")
    assert page.errors == []
    screenshot(page, tmp_path, "console-error.png")


def test_the_live_view_follows_a_replayed_session(console: str, page: Any, tmp_path: Path) -> None:
    recording = slew_recording(tmp_path / "rig.jsonl", 60)
    cli = [sys.executable, "-c", "from service.cli import main; main()"]
    page.goto(console + "/ui/live?session=test-rig&watch=1")
    wait_for(lambda: page.text_content("#status") == "watching test-rig", what="the viewer to connect")
    replay = subprocess.Popen([*cli, "replay", str(recording), "--ws", "--session", "test-rig", "--rate", "12",
                               "--url", console, "-q"], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        seen = []
        for _ in range(3):  # three looks at the page while the frames stream in
            n = int(wait_for(lambda: int(page.text_content("#frames")) > (seen[-1][0] if seen else 0)
                             and page.text_content("#frames"), what="the frame counter"))
            time.sleep(0.6)  # the plots redraw four times a second
            seen.append((n, int(page.get_attribute("#chart-ra", "data-points") or 0),
                         page.get_attribute("#skymap", "data-center")))
        _, err = replay.communicate(timeout=60)
        assert replay.returncode == 0, err.decode()[-2000:]
    finally:
        if replay.poll() is None:
            replay.kill()
            replay.communicate()
    wait_for(lambda: page.text_content("#frames") == "60", what="all 60 frames")
    frames = [s[0] for s in seen]
    points = [s[1] for s in seen]
    centres = [s[2] for s in seen]
    assert frames == sorted(frames) and frames[0] < frames[-1]
    assert points == sorted(points) and points[0] < points[-1]
    assert len(set(centres)) == len(centres) and None not in centres
    time.sleep(0.6)
    assert int(page.get_attribute("#chart-dec", "data-points")) == 60
    assert float(page.text_content("#fps")) > 0
    assert page.text_content("#p50").endswith(" ms") and page.text_content("#p99").endswith(" ms")
    assert page.text_content("#dropped") == "0"
    assert page.locator("#attitude tr").count() >= 4
    assert page.errors == []
    screenshot(page, tmp_path, "console-live.png")


@pytest.mark.skipif(not (REAL / "matches.json").is_file(), reason=f"real data absent ({REAL})")
def test_a_pasted_centroid_list_is_solved_with_a_configured_camera(console: str, page: Any, tmp_path: Path) -> None:
    """The reference centroids of the real image above, as a user would paste them."""
    matches = json.loads((REAL / "matches.json").read_text())["images"][IMAGE]["matches"]
    page.goto(console + "/ui/solve")
    wait_for(lambda: page.locator("#camera option[value=tetra3]").count(), what="the configured cameras")
    page.click("summary")
    page.fill("#centroids", json.dumps({"camera": "tetra3", "centroids": [[m["x"], m["y"]] for m in matches]}))
    page.click("#solve-json")
    wait_for(lambda: page.text_content("#result-json"), what="the result")
    result = json.loads(page.text_content("#result-json"))
    assert result["status"] == "solved" and len(result["stars"]) >= 10
    for star in result["stars"]:
        assert star["hip"] == matches[star["centroid"]]["hip"]
    assert page.get_attribute("#image", "data-identified") == str(len(result["stars"]))
    assert page.get_attribute("#image", "data-detected") == str(len(matches))
    assert page.errors == []


@pytest.fixture(scope="module")
def keyed(api_db_path: Path) -> Iterator[str]:
    """A server that needs an API key (the small API database, in a thread)."""
    from service.api import Settings

    from ..conftest import CAMERA_SPEC, start_server

    live = start_server(Settings(db_path=api_db_path, api_key="console-test-key", cameras={"tetra3": CAMERA_SPEC}))
    yield live.url
    live.stop()


def test_the_key_is_typed_kept_in_memory_and_sent(keyed: str, page: Any, browser: Any, tmp_path: Path) -> None:
    rows = [[512.0 + 40 * i, 384.0 - 25 * i] for i in range(4)]
    html = page.goto(keyed + "/ui/solve").text()
    assert "console-test-key" not in html
    page.click("summary")
    page.fill("#centroids", json.dumps({"camera": {"width": 1024, "height": 768, "fov_deg": 11.4}, "centroids": rows}))
    page.click("#solve-json")
    error = wait_for(lambda: page.is_visible("#error") and page.text_content("#error"), what="the 401")
    assert error == "401 X-API-Key: missing or wrong API key"
    page.fill("#apikey", "console-test-key")
    page.dispatch_event("#apikey", "change")
    wait_for(lambda: page.locator("#camera option[value=tetra3]").count(), what="the cameras, with the key")
    page.click("#solve-json")
    wait_for(lambda: page.text_content("#result-json"), what="an answer with the key")
    assert json.loads(page.text_content("#result-json"))["status"] in ("solved", "no_solution")
    assert page.is_hidden("#error")
    state = page.context.storage_state()
    assert "console-test-key" not in json.dumps(state)  # no cookie, no localStorage
    live = page.context.new_page()
    live.goto(keyed + "/ui/live?session=keyed")
    live.click("#connect")
    wait_for(lambda: "refused" in live.text_content("#status"), what="the refusal without a key")
    live.fill("#apikey", "console-test-key")
    live.click("#connect")
    wait_for(lambda: live.text_content("#status") == "watching keyed", what="the viewer, with the key")
    live.reload()
    assert live.input_value("#apikey") == ""  # gone with the page
    assert page.errors == []
    screenshot(page, tmp_path, "console-key.png")
