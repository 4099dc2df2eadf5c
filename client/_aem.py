"""CCSDS Attitude Ephemeris Message (AEM), KVN, ADM version 2 (CCSDS 504.0-B-2).

Quaternion convention, and why ``(Q1, Q2, Q3, QC) = (-x, -y, -z, w)``:

* skyfix: ``q = [w, x, y, z]`` (scalar first, Hamilton) is an *operator* on vectors:
  ``v_cam = R(q) v_icrs`` with ``R(q) = (w² - |v|²) I + 2 v vᵀ + 2 w [v×]``.
* ADM v2 fixes the scalar last (``QC``; v1's ``QUATERNION_TYPE`` is gone) and the direction
  from ``REF_FRAME_A`` to ``REF_FRAME_B`` (v1's ``ATTITUDE_DIR`` is gone). Its quaternion is
  the classical attitude quaternion (Shuster): ``e = axis sin(φ/2)``, ``QC = cos(φ/2)``,
  whose attitude matrix ``A(q) = (QC² - |e|²) I + 2 e eᵀ - 2 QC [e×]`` takes the components
  of a vector in frame A to its components in frame B (a frame rotation).
* ``A(q)`` is ``R(q)ᵀ``, so ``A(q_ccsds) = R(q_skyfix)`` needs ``q_ccsds`` = the conjugate:
  ``e = (-x, -y, -z)``, ``QC = w``. Orekit, which reads and writes ADM v2, does the same:
  it writes the Hipparchus rotation quaternion of the A -> B frame transform (Hipparchus
  applies ``q* v q``), which is our conjugate.

Both ``q`` and ``-q`` are the same attitude; the writer keeps ``QC >= 0`` on the first line
and then keeps the sign continuous from line to line (so interpolating readers never go the
long way round).
"""

from __future__ import annotations

import io
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import IO

from ._attitude import quat_normalize

__all__ = ["AemRecord", "format_aem", "quaternion_to_ccsds", "write_aem"]


def quaternion_to_ccsds(q_wxyz: Sequence[float]) -> tuple[float, float, float, float]:
    """skyfix ``[w, x, y, z]`` (ICRS vectors -> camera) as CCSDS ADM v2 ``(Q1, Q2, Q3, QC)``
    for ``REF_FRAME_A = ICRF`` -> ``REF_FRAME_B = the camera/body``."""
    w, x, y, z = quat_normalize(q_wxyz)
    return (-x, -y, -z, w)


@dataclass(frozen=True, slots=True)
class AemRecord:
    """One attitude: a UTC epoch and an ICRS -> camera quaternion ``[w, x, y, z]``."""

    epoch: datetime
    quaternion: tuple[float, float, float, float]


def format_epoch(t: datetime) -> str:
    """CCSDS ASCII time code A, ``YYYY-MM-DDThh:mm:ss.ffffff``, in UTC."""
    if t.tzinfo is not None:
        t = t.astimezone(UTC).replace(tzinfo=None)
    return t.strftime("%Y-%m-%dT%H:%M:%S.%f")


def _kvn(key: str, value: object) -> str:
    text = str(value)
    if not text or any(c in text for c in "\r\n=") or not text.isascii():
        raise ValueError(f"{key} must be non-empty printable ASCII without '=' or newlines: {text!r}")
    return f"{key:<20} = {text}"


def _by_epoch(records: Iterable[AemRecord]) -> dict[datetime, AemRecord]:
    """Records keyed by UTC epoch (naive = UTC); the first of a repeated epoch wins."""
    rows: dict[datetime, AemRecord] = {}
    for rec in records:
        t = rec.epoch if rec.epoch.tzinfo is not None else rec.epoch.replace(tzinfo=UTC)
        rows.setdefault(t, rec)
    return rows


def format_aem(
    records: Iterable[AemRecord],
    *,
    object_name: str = "SKYFIX",
    object_id: str = "UNKNOWN",
    ref_frame_a: str = "ICRF",
    ref_frame_b: str = "SC_BODY_1",
    originator: str = "SKYFIX",
    message_id: str | None = None,
    comments: Sequence[str] = (),
    creation_date: datetime | None = None,
) -> str:
    """The AEM text for ``records`` (sorted by epoch; a repeated epoch keeps its first record).

    Raises ``ValueError`` when there is no record (an AEM needs at least one data line).
    """
    rows = _by_epoch(records)
    if not rows:
        raise ValueError("an AEM needs at least one attitude")
    epochs = sorted(rows)
    created = creation_date or datetime.now(UTC)
    out = io.StringIO()
    lines = [_kvn("CCSDS_AEM_VERS", "2.0")]
    lines += [f"COMMENT {part}" for c in comments for part in str(c).splitlines()]
    lines += [_kvn("CREATION_DATE", format_epoch(created)), _kvn("ORIGINATOR", originator)]
    if message_id:
        lines.append(_kvn("MESSAGE_ID", message_id))
    lines += [
        "",
        "META_START",
        "COMMENT Attitude of REF_FRAME_B relative to REF_FRAME_A (ADM v2: A to B, scalar QC last).",
        _kvn("OBJECT_NAME", object_name),
        _kvn("OBJECT_ID", object_id),
        _kvn("REF_FRAME_A", ref_frame_a),
        _kvn("REF_FRAME_B", ref_frame_b),
        _kvn("TIME_SYSTEM", "UTC"),
        _kvn("START_TIME", format_epoch(epochs[0])),
        _kvn("STOP_TIME", format_epoch(epochs[-1])),
        _kvn("ATTITUDE_TYPE", "QUATERNION"),
        "META_STOP",
        "",
        "DATA_START",
    ]
    out.write("\n".join(lines) + "\n")
    previous: tuple[float, float, float, float] | None = None
    for t in epochs:
        rec = rows[t]
        q = quaternion_to_ccsds(rec.quaternion)
        if previous is None:
            flip = q[3] < 0
        else:
            flip = sum(a * b for a, b in zip(q, previous, strict=True)) < 0
        if flip:
            q = (-q[0], -q[1], -q[2], -q[3])
        previous = q
        out.write(f"{format_epoch(t)} {q[0]: .12f} {q[1]: .12f} {q[2]: .12f} {q[3]: .12f}\n")
    out.write("DATA_STOP\n")
    return out.getvalue()


def write_aem(path: str | os.PathLike[str] | IO[str], records: Iterable[AemRecord], **meta: object) -> int:
    """Write `format_aem` to ``path`` (or an open text file); returns the number of data lines.

    Keyword arguments are those of `format_aem` (``object_name``, ``object_id``,
    ``ref_frame_b``, ...).
    """
    recs = list(records)
    text = format_aem(recs, **meta)  # type: ignore[arg-type]
    if isinstance(path, str | os.PathLike):
        tmp = Path(str(path) + ".tmp")
        tmp.write_text(text, encoding="ascii")
        tmp.replace(path)
    else:
        path.write(text)
    return len(_by_epoch(recs))
