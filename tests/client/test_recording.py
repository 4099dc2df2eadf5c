"""Recorded frames: JSON Lines reader and writer; image paths stay inside the recording's dir."""

import json
import os
from pathlib import Path

import pytest

from client import RecordedFrame, RecordingError, RecordingWriter, read_recording, resolve_image

CAM = {"width": 1024, "height": 768, "fov_deg": 11.4}


def test_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "rec.jsonl"
    img = tmp_path / "src.png"
    img.write_bytes(b"\x89PNG fake")
    with RecordingWriter(path) as rec:
        rec.write({"id": 1, "time": 1.5, "camera": CAM, "centroids": [[1, 2], [3, 4, 5]],
                   "truth": {"quaternion": [1, 0, 0, 0], "hip": [11, None]}})
        rel = rec.add_image(img)
        rec.write(RecordedFrame(id="b", time="2026-01-01T00:00:00Z", image=rel, camera=None))
        rec.write({"id": 3, "cameras": [{"camera": CAM, "centroids": [[1, 1]]}], "note": "extra kept"})
    assert rec.count == 3
    frames = list(read_recording(path))
    assert [f.id for f in frames] == [1, "b", 3]
    assert frames[0].truth is not None and frames[0].truth.hip == [11, None]
    assert frames[1].image == "images/src.png"
    assert resolve_image(path, "images/src.png").read_bytes() == b"\x89PNG fake"
    assert frames[2].model_extra == {"note": "extra kept"}
    with RecordingWriter(path, append=True) as rec:
        rec.write({"id": 4, "camera": CAM, "centroids": []})
    assert len(list(read_recording(path))) == 4


def test_blank_and_comment_lines_are_skipped(tmp_path: Path) -> None:
    path = tmp_path / "rec.jsonl"
    frame = json.dumps({"id": 1, "camera": CAM, "centroids": [[1, 2]]})
    path.write_text(f"# a recording\n\n{frame}\n")
    assert [f.id for f in read_recording(path)] == [1]


@pytest.mark.parametrize("image", ["../secret.png", "/etc/passwd", "a/../../b.png", "..\\x.png", ""])
def test_paths_escaping_the_directory_are_refused(tmp_path: Path, image: str) -> None:
    path = tmp_path / "d" / "rec.jsonl"
    path.parent.mkdir()
    with path.open("w") as f:
        f.write(json.dumps({"id": 1, "image": "ok.png"}) + "\n")
        f.write(json.dumps({"id": 2, "image": image}) + "\n")
    with pytest.raises(RecordingError, match="outside|relative|invalid") as info:
        list(read_recording(path))
    assert info.value.line == 2


def test_symlink_out_of_the_directory_is_refused(tmp_path: Path) -> None:
    outside = tmp_path / "outside.png"
    outside.write_bytes(b"x")
    rec_dir = tmp_path / "rec"
    rec_dir.mkdir()
    os.symlink(outside, rec_dir / "link.png")
    (rec_dir / "inside.png").write_bytes(b"y")
    path = rec_dir / "rec.jsonl"
    path.write_text('{"id": 1, "image": "inside.png"}\n{"id": 2, "image": "link.png"}\n')
    with pytest.raises(RecordingError, match="outside") as info:
        list(read_recording(path))
    assert info.value.line == 2
    with pytest.raises(RecordingError):
        resolve_image(path, "link.png")


def test_writer_refuses_escaping_image(tmp_path: Path) -> None:
    with RecordingWriter(tmp_path / "r.jsonl") as rec, pytest.raises(RecordingError):
        rec.write({"id": 1, "image": "../x.png"})


@pytest.mark.parametrize(("line", "message"), [
    ("not json", "JSON"),
    ('{"id": 1}', "exactly one of"),
    ('{"id": 1, "centroids": [[1, 2]]}', "needs a camera"),
    ('{"id": 1, "camera": {"width": 10, "height": 10}, "centroids": [[1, 2]]}', "exactly one of fov_deg"),
    (json.dumps({"id": 1, "camera": CAM, "centroids": [[1, 2, 3, 4]]}), "rows"),
    (json.dumps({"id": 1, "camera": CAM, "centroids": [[1, 2]], "truth": {"quaternion": [2, 0, 0, 0]}}),
     "unit"),
])
def test_bad_lines_name_their_line(tmp_path: Path, line: str, message: str) -> None:
    path = tmp_path / "rec.jsonl"
    path.write_text(json.dumps({"id": 0, "camera": CAM, "centroids": [[1, 2]]}) + f"\n{line}\n")
    with pytest.raises(RecordingError, match=message) as info:
        list(read_recording(path))
    assert info.value.line == 2
    assert f"{path}:2:" in str(info.value)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="cannot open"):
        list(read_recording(tmp_path / "nope.jsonl"))
