"""Error metrics of seed 000, eqs. (17)-(18), and the three rotation angles
(docs/reference/conventions.md).
"""

import numpy as np
from scipy.spatial.transform import Rotation

from montecarlo.geometry import metrics
from montecarlo.geometry.rotations import mounting_matrix

rng = np.random.default_rng(18)


def _rotations(phi):
    axes = rng.normal(size=(len(phi), 3))
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    return Rotation.from_rotvec(axes * phi[:, None]).as_matrix()


def test_rotation_angle_matches_scipy_magnitude_at_all_sizes():
    phi = np.concatenate([[0.0, 1e-12, 1e-9, 1e-6], rng.uniform(0, np.pi, 500), [np.pi - 1e-9]])
    D = _rotations(phi)
    np.testing.assert_allclose(metrics.rotation_angle(D), Rotation.from_matrix(D).magnitude(),
                               rtol=1e-9, atol=1e-15)


def test_eq18_is_half_the_rotation_angle():
    phi = rng.uniform(1e-3, np.pi, 500)
    np.testing.assert_allclose(metrics.eq18_angle(_rotations(phi)), phi / 2, rtol=1e-9)


def test_table1_angle_closed_form_and_small_angle_limit():
    """(1 + tr D)/4 = cos^2(phi/2), so table1_angle = arccos(cos^2(phi/2)) ~ phi/sqrt(2)."""
    phi = rng.uniform(1e-3, np.pi, 500)
    got = metrics.table1_angle(_rotations(phi))
    np.testing.assert_allclose(got, np.arccos(np.cos(phi / 2) ** 2), rtol=1e-9)
    small = np.array([1e-4, 1e-3, 1e-2])
    ratio = metrics.table1_angle(_rotations(small)) / (small / np.sqrt(2))
    # arccos(cos^2(x/2)) = x/sqrt(2) (1 - x^2/48 + O(x^4))
    np.testing.assert_allclose(ratio, 1 - small**2 / 48, rtol=1e-8)


def test_identity_gives_zero_everywhere():
    D = np.eye(3)
    for name, value in metrics.all_metrics(D).items():
        assert value == 0.0, name


def test_error_angles_recover_known_small_rotation():
    d = np.array([1e-3, -2e-3, 5e-4])
    D = mounting_matrix(*d)
    np.testing.assert_allclose(metrics.error_angles(D), d, atol=1e-15)


def test_error_matrix_is_relative_rotation():
    C_ba = mounting_matrix(0.5, 0.2, -0.1)
    D_true = mounting_matrix(1e-3, 2e-3, -3e-3)
    C_bc = D_true @ C_ba
    np.testing.assert_allclose(metrics.error_matrix(C_bc, C_ba), D_true, atol=1e-15)


def test_nan_propagates():
    D = np.full((3, 3), np.nan)
    assert all(np.isnan(v) for v in metrics.all_metrics(D).values())


def test_error_matrix_of_a_batch_against_scipy():
    """A batch (n, 3, 3): D = C_b^c (C_b^a)^T, each against scipy's relative rotation
    (``R_c * R_a.inv()`` for the active rotations whose matrices are the transposes)."""
    R_a, R_c = Rotation.random(7, random_state=3), Rotation.random(7, random_state=4)
    C_ba, C_bc = R_a.as_matrix().transpose(0, 2, 1), R_c.as_matrix().transpose(0, 2, 1)
    expected = (R_c.inv() * R_a).as_matrix()  # C_b^c (C_b^a)^T = R_c^T R_a
    np.testing.assert_allclose(metrics.error_matrix(C_bc, C_ba), expected, atol=1e-14)


def test_a_trace_a_few_ulps_outside_minus_one_to_three_gives_the_end_values():
    """Round-off can put tr D a few ulps above 3 (no rotation) or below -1 (a half turn). The
    metrics then take their end values, never NaN: eq. (18) 0 and pi/2, Table 1's 0 and
    arccos(-ulp/4) = pi/2, the rotation angle 0 and pi."""
    above = np.diag([1.0 + 2.0**-51] * 3)  # each diagonal element 2 ulps above 1
    below = np.diag([1.0, -1.0 - 2.0**-52, -1.0])
    assert np.trace(above) > 3.0 and np.trace(below) < -1.0
    assert metrics.eq18_angle(above) == 0.0 and metrics.table1_angle(above) == 0.0
    assert metrics.rotation_angle(above) == 0.0
    assert metrics.eq18_angle(below) == np.pi / 2
    assert abs(metrics.table1_angle(below) - np.pi / 2) < 1e-15
    assert metrics.rotation_angle(below) == np.pi
