"""Image bytes -> array: round trips for every format, and refusal of bad or hostile bytes."""

from __future__ import annotations

import io
import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
import tifffile
from astropy.io import fits

from service.core.centroid import decode_image, load_image
from service.core.centroid.decode import sniff_format
from service.core.errors import ImageDecodeError, InvalidInputError


@pytest.fixture
def mono16() -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.integers(0, 65536, size=(37, 53), dtype=np.uint16)


@pytest.fixture
def mono8(mono16: np.ndarray) -> np.ndarray:
    return (mono16 >> 8).astype(np.uint8)


def _png(arr: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", arr)
    assert ok
    return buf.tobytes()


def _fits(*hdus: fits.hdu.base.ExtensionHDU) -> bytes:
    bio = io.BytesIO()
    fits.HDUList(list(hdus)).writeto(bio)
    return bio.getvalue()


def _npy(arr: np.ndarray) -> bytes:
    bio = io.BytesIO()
    np.save(bio, arr)
    return bio.getvalue()


def _tiff(arr: np.ndarray, **kw: object) -> bytes:
    bio = io.BytesIO()
    tifffile.imwrite(bio, arr, **kw)
    return bio.getvalue()


# --------------------------------------------------------------------------- round trips


def test_png_8_and_16_bit_round_trip(mono8: np.ndarray, mono16: np.ndarray) -> None:
    for arr in (mono8, mono16):
        out = decode_image(_png(arr))
        assert out.dtype == arr.dtype and np.array_equal(out, arr)


def test_colour_png_becomes_the_channel_mean(mono8: np.ndarray) -> None:
    a = mono8.astype(np.int32)
    bgr = np.dstack([mono8, np.clip(a + 3, 0, 255), np.clip(a + 6, 0, 255)]).astype(np.uint8)
    out = decode_image(_png(bgr))
    assert out.dtype == np.float32
    np.testing.assert_allclose(out, bgr.astype(np.float64).mean(axis=2), atol=1e-4)
    med = decode_image(_png(bgr), channels="median")
    np.testing.assert_array_equal(med, np.median(bgr, axis=2))


def test_grey_stored_as_rgba_keeps_native_dtype(mono16: np.ndarray) -> None:
    rgba = np.dstack([mono16, mono16, mono16, np.full_like(mono16, 65535)])
    out = decode_image(_png(rgba))
    assert out.dtype == np.uint16 and np.array_equal(out, mono16)  # alpha dropped


def test_tiff_16_bit_and_planar_colour_round_trip(mono8: np.ndarray, mono16: np.ndarray) -> None:
    out = decode_image(_tiff(mono16))
    assert out.dtype == np.uint16 and np.array_equal(out, mono16)
    out = decode_image(_tiff(mono16, compression="zlib"))
    assert np.array_equal(out, mono16)
    planar = np.stack([mono8, mono8, mono8])
    out = decode_image(_tiff(planar, photometric="rgb", planarconfig="separate"))
    assert np.array_equal(out, mono8)


def test_fits_round_trips(mono16: np.ndarray) -> None:
    out = decode_image(_fits(fits.PrimaryHDU(mono16)))  # stored as int16 + BZERO 32768
    assert out.dtype == np.uint16 and np.array_equal(out, mono16)
    flt = mono16.astype(np.float32) / 7
    out = decode_image(_fits(fits.PrimaryHDU(), fits.ImageHDU(flt)))  # first HDU without data
    assert out.dtype == np.float32 and np.array_equal(out, flt)
    cube = mono16[None].astype(np.int32)  # NAXIS3 = 1 counts as 2-D
    np.testing.assert_array_equal(decode_image(_fits(fits.PrimaryHDU(cube))), mono16)


def test_npy_round_trips(mono16: np.ndarray) -> None:
    assert np.array_equal(decode_image(_npy(mono16)), mono16)
    be = mono16.astype(">f8")
    out = decode_image(_npy(be))
    assert out.dtype == np.float32 and np.array_equal(out, mono16)


def test_jpeg_decodes(mono8: np.ndarray) -> None:
    ok, buf = cv2.imencode(".jpg", mono8, [cv2.IMWRITE_JPEG_QUALITY, 100])
    out = decode_image(buf.tobytes())
    assert out.shape == mono8.shape and np.abs(out.astype(int) - mono8).mean() < 3


def test_load_image_reads_a_file(tmp_path: Path, mono16: np.ndarray) -> None:
    path = tmp_path / "frame.png"
    path.write_bytes(_png(mono16))
    assert np.array_equal(load_image(path), mono16)


def test_sniff_format(mono8: np.ndarray) -> None:
    assert sniff_format(_png(mono8)) == "png"
    assert sniff_format(_tiff(mono8)) == "tiff"
    assert sniff_format(_fits(fits.PrimaryHDU(mono8))) == "fits"
    assert sniff_format(_npy(mono8)) == "npy"
    assert sniff_format(b"GIF89a....") is None


# --------------------------------------------------------------------------- refusals


def test_corrupt_truncated_and_unsupported_bytes_raise(mono16: np.ndarray) -> None:
    png = _png(mono16)
    bad = {
        "empty": b"",
        "unsupported": b"GIF89a" + bytes(100),
        "text": b"hello, this is not an image" * 10,
        "truncated png": png[: len(png) // 2],
        "corrupt png": png[:40] + bytes(64) + png[104:],
        "png header only": png[:33],
        "truncated tiff": _tiff(mono16)[:200],
        "truncated fits": _fits(fits.PrimaryHDU(mono16))[:3000],
        "truncated npy": _npy(mono16)[:300],
        "pickled npy": _npy(np.array([{"a": 1}, None], dtype=object).reshape(1, 2)),
        "1-d npy": _npy(np.arange(10)),
        "fits without image": _fits(fits.PrimaryHDU()),
    }
    for name, data in bad.items():
        with pytest.raises(ImageDecodeError) as err:
            decode_image(data)
        assert err.value.field == "image", name


def _forged_png(width: int, height: int) -> bytes:
    """A syntactically valid PNG header that claims a huge image, with one tiny IDAT."""
    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    idat = chunk(b"IDAT", zlib.compress(bytes(64)))
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + idat + chunk(b"IEND", b"")


def test_oversized_headers_are_refused_before_decoding(mono16: np.ndarray) -> None:
    with pytest.raises(ImageDecodeError, match="over the limit"):
        decode_image(_forged_png(100_000, 100_000))
    header = fits.Header()
    header["SIMPLE"], header["BITPIX"], header["NAXIS"] = True, 8, 2
    header["NAXIS1"], header["NAXIS2"] = 50_000, 50_000
    with pytest.raises(ImageDecodeError, match="over the limit"):
        decode_image(header.tostring().encode("ascii"))  # no data block at all
    npy = _npy(np.zeros((2, 2), np.uint8)).replace(b"(2, 2)", b"(90000, 90000)")
    with pytest.raises(ImageDecodeError, match="over the limit"):
        decode_image(npy)
    ok, jpg = cv2.imencode(".jpg", (mono16 >> 8).astype(np.uint8))
    jpg_b = bytearray(jpg.tobytes())
    sof = jpg_b.find(b"\xff\xc0")
    jpg_b[sof + 5 : sof + 9] = struct.pack(">HH", 60_000, 60_000)
    with pytest.raises(ImageDecodeError, match="over the limit"):
        decode_image(bytes(jpg_b))
    for data in (_png(mono16), _tiff(mono16), _fits(fits.PrimaryHDU(mono16)), _npy(mono16)):
        with pytest.raises(ImageDecodeError, match="over the limit"):
            decode_image(data, max_pixels=37 * 53 - 1)
        assert decode_image(data, max_pixels=37 * 53).shape == (37, 53)


def test_bad_options_name_their_field(mono8: np.ndarray) -> None:
    with pytest.raises(InvalidInputError) as err:
        decode_image(_png(mono8), channels="max")
    assert err.value.field == "channels"
    with pytest.raises(ImageDecodeError):
        decode_image("not bytes")  # type: ignore[arg-type]
