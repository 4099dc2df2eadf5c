"""The console's files: every page reference exists, vendored libraries carry their licences, no
inline code or third-party host, and /ui answers with its Content-Security-Policy."""

from __future__ import annotations

import re

import httpx
import pytest

from service.api.ui import CSP, PAGES, STATIC


@pytest.mark.parametrize("page", sorted(PAGES.values()))
def test_a_page_loads_only_files_it_ships_and_no_inline_code(page: str) -> None:
    html = (STATIC / page).read_text()
    refs = re.findall(r'(?:src|href)="([^"]+)"', html)
    assert refs
    for ref in refs:
        if ref.startswith("/ui/static/"):
            assert (STATIC / ref.removeprefix("/ui/static/")).is_file(), ref
        else:
            assert ref in ("/ui/live", "/ui/solve"), ref
    assert not re.search(r"<script(?![^>]*\bsrc=)[^>]*>", html), "inline script"
    assert not re.search(r"\sstyle=|<style|\son[a-z]+=", html), "inline style or handler"


def test_our_scripts_name_no_other_host() -> None:
    for path in STATIC.glob("*.js"):
        assert not re.search(r"https?://", path.read_text()), path.name


def test_every_vendored_library_ships_its_licence() -> None:
    vendor = STATIC / "vendor"
    libs = [d for d in vendor.iterdir() if d.is_dir()]
    assert {d.name for d in libs} == {"uplot", "d3-celestial"}
    for lib in libs:
        assert "Permission" in (lib / "LICENSE").read_text() or "Redistribution" in (lib / "LICENSE").read_text()
    assert "Redistribution" in (vendor / "d3-celestial" / "lib" / "LICENSE.d3").read_text()
    assert "uplot 1.6.32 MIT" in (vendor / "VERSIONS").read_text()


def test_ui_answers_with_its_security_headers(client: httpx.Client) -> None:
    assert client.get("/ui").headers["location"] == "/ui/live"
    for path in ("/ui/live", "/ui/solve", "/ui/static/live.js", "/ui/static/vendor/uplot/uPlot.min.css"):
        r = client.get(path)
        assert r.status_code == 200, path
        assert r.headers["content-security-policy"] == CSP
        assert r.headers["x-content-type-options"] == "nosniff"
    assert "'unsafe" not in CSP and "default-src 'none'" in CSP
    assert client.get("/ui/static/../__init__.py").status_code == 404
    assert client.get("/ui/static/nothing.js").status_code == 404
