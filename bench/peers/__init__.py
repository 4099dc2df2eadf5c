"""Adapters for the peer solvers the benchmarks compare skyfix with.

Each adapter builds its peer's database from the *same* star list skyfix's database holds
(through the peer's public catalogue-reading API), loads it, and solves frames in skyfix's
conventions, timing each solve inside the process that runs it:

- ``tetra3rs`` (PyPI ``tetra3rs``, compiled Rust): in this process.
- ``cedar`` (PyPI ``cedar-solve`` 0.5.1, pure Python; it pins numpy < 2): in its own venv
  ``bench/out/venv-cedar``, driven over a pipe (``cedar_worker.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StarRows:
    """A star list handed to a peer's database generator: HIP, ICRS RA/Dec (deg) at the
    benchmark epoch (proper motion already applied), approximate Johnson V."""

    hip: np.ndarray
    ra_deg: np.ndarray
    dec_deg: np.ndarray
    mag: np.ndarray

    @classmethod
    def from_table(cls, stars: object) -> StarRows:
        vec = np.asarray(stars.vec, float)  # type: ignore[attr-defined]
        ra = np.degrees(np.mod(np.arctan2(vec[:, 1], vec[:, 0]), 2 * np.pi))
        dec = np.degrees(np.arcsin(np.clip(vec[:, 2], -1, 1)))
        return cls(np.asarray(stars.hip, np.int64), ra, dec, np.asarray(stars.mag, float))  # type: ignore[attr-defined]

    def __len__(self) -> int:
        return len(self.hip)

    def digest(self) -> str:
        import hashlib

        h = hashlib.sha256()
        for a in (self.hip, np.round(self.ra_deg, 7), np.round(self.dec_deg, 7), np.round(self.mag, 3)):
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()[:16]
