"""The geometry kernels against independent formulas."""

from __future__ import annotations

import numpy as np

from service.core.geometry import angle_between, pairwise_angles, radec_to_vector


def test_pairwise_angles_agree_with_the_angle_between_each_pair(rng) -> None:
    v = radec_to_vector(rng.uniform(0, 2 * np.pi, 40), np.arcsin(rng.uniform(-1, 1, 40)))
    d = pairwise_angles(v)
    assert d.shape == (40, 40) and np.all(np.diag(d) == 0) and np.array_equal(d, d.T)
    i, j = np.triu_indices(40, 1)
    np.testing.assert_allclose(d[i, j], angle_between(v[i], v[j]), rtol=1e-14, atol=0)
    # far from 0 and pi the arccos of the dot product is accurate too (independent of the chord form)
    well = (d[i, j] > 0.1) & (d[i, j] < 3.0)
    np.testing.assert_allclose(d[i, j][well], np.arccos(np.einsum("ij,ij->i", v[i], v[j]))[well], rtol=1e-12)


def test_pairwise_angles_are_accurate_at_an_arcsecond_and_take_any_array_layout() -> None:
    arcsec = np.radians(1 / 3600)
    v = radec_to_vector(np.array([0.3, 0.3 + arcsec, 0.3]), np.array([0.1, 0.1, 0.1 + 2 * arcsec]))
    d = pairwise_angles(v)
    assert abs(d[0, 1] - arcsec * np.cos(0.1)) < 1e-6 * arcsec
    assert abs(d[0, 2] - 2 * arcsec) < 1e-6 * arcsec
    np.testing.assert_array_equal(pairwise_angles(np.asfortranarray(v)), d)
    np.testing.assert_array_equal(pairwise_angles(v.astype(np.float32)), pairwise_angles(v.astype(np.float32).astype(float)))
    assert pairwise_angles(np.zeros((0, 3))).shape == (0, 0)
