"""Z-X-Y rotations of seed 000, eqs. (5), (7), (14), (17), against scipy's Rotation."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from montecarlo.geometry.rotations import (
    euler_zxy_from_matrix,
    mounting_angles_from_columns,
    mounting_matrix,
    target_frame_matrix,
)

rng = np.random.default_rng(20140118)
N = 2000


def _angles(limit_yaw_roll=np.pi, limit_pitch=np.pi / 2 * 0.999):
    return (rng.uniform(-limit_yaw_roll, limit_yaw_roll, N),
            rng.uniform(-limit_pitch, limit_pitch, N),
            rng.uniform(-limit_yaw_roll, limit_yaw_roll, N))


def test_eq5_is_scipy_intrinsic_zxy_transposed():
    """C_b^a = Rotation.from_euler('ZXY', [psi, theta, gamma]).as_matrix().T (conventions.md)."""
    psi, theta, gamma = _angles()
    ours = mounting_matrix(psi, theta, gamma)
    ref = Rotation.from_euler("ZXY", np.stack([psi, theta, gamma], -1)).as_matrix()
    np.testing.assert_allclose(ours, np.swapaxes(ref, -1, -2), atol=1e-15)


def test_eq5_is_product_of_elementary_passive_rotations():
    """C_b^a = R_y(gamma) R_x(theta) R_z(psi) for passive elementary rotations."""
    psi, theta, gamma = 0.3, -0.7, 1.1

    def passive(axis, a):
        return Rotation.from_euler(axis, a).as_matrix().T

    expected = passive("y", gamma) @ passive("x", theta) @ passive("z", psi)
    np.testing.assert_allclose(mounting_matrix(psi, theta, gamma), expected, atol=1e-15)


def test_eq7_is_yaw_then_pitch():
    psi, theta, _ = _angles()
    ref = Rotation.from_euler("ZX", np.stack([psi, theta], -1)).as_matrix()
    np.testing.assert_allclose(target_frame_matrix(psi, theta), np.swapaxes(ref, -1, -2),
                               atol=1e-15)


def test_matrices_are_proper_rotations():
    C = mounting_matrix(*_angles())
    np.testing.assert_allclose(C @ np.swapaxes(C, -1, -2), np.broadcast_to(np.eye(3), C.shape),
                               atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(C), 1.0, atol=1e-14)


def test_euler_round_trip_full_range():
    angles = _angles()
    back = euler_zxy_from_matrix(mounting_matrix(*angles))
    np.testing.assert_allclose(np.stack(back), np.stack(angles), rtol=0, atol=1e-12)


def test_euler_agrees_with_scipy_as_euler():
    C = mounting_matrix(*_angles())
    ref = Rotation.from_matrix(np.swapaxes(C, -1, -2)).as_euler("ZXY")
    np.testing.assert_allclose(np.stack(euler_zxy_from_matrix(C), -1), ref, atol=1e-12)


def test_eq14_round_trip_within_plus_minus_90_deg():
    psi, theta, gamma = _angles(np.pi / 2 * 0.999, np.pi / 2 * 0.999)
    C = mounting_matrix(psi, theta, gamma)
    back = mounting_angles_from_columns(C[..., 0, 1], C[..., 2, 1], C[..., 0, 2], C[..., 1, 2],
                                        C[..., 2, 2])
    # arcsin near +-90 deg amplifies round-off by 1/cos: allow 1e-15 / cos(0.999 * 90 deg)
    np.testing.assert_allclose(np.stack(back), np.stack([psi, theta, gamma]), atol=1e-12)


def test_eq14_returns_nan_outside_its_domain():
    psi, theta, gamma = mounting_angles_from_columns(2.0, 0.0, 0.0, 1.5, -1.0)
    assert np.isnan(psi) and np.isnan(theta) and np.isnan(gamma)


@pytest.mark.parametrize("shape", [(), (5,), (2, 3)])
def test_shapes(shape):
    a = np.zeros(shape)
    assert mounting_matrix(a, a, a).shape == (*shape, 3, 3)
    assert mounting_matrix(np.zeros((4, 1)), np.zeros(3), 0.0).shape == (4, 3, 3, 3)


def test_euler_at_a_pitch_of_plus_minus_90_deg_with_c23_an_ulp_beyond_one():
    """Round-off can put C23 = sin(theta) an ulp beyond +-1: theta is then +-pi/2, not NaN."""
    for sign in (1.0, -1.0):
        C = mounting_matrix(0.3, sign * np.pi / 2, -0.2)
        C[1, 2] = sign * (1.0 + 2.0**-52)
        assert euler_zxy_from_matrix(C)[1] == sign * np.pi / 2


def test_eq14_outside_its_domain_gives_nan_without_a_warning():
    """C33 = 0 (roll of 90 deg) and C23 = 1 (pitch of 90 deg) divide by zero inside eq. (14):
    the angles that need the quotient are NaN, silently (the test run turns warnings into
    errors). By hand: C23 = 0.3 gives theta = arcsin(0.3) = 0.30469265 rad."""
    psi, theta, gamma = mounting_angles_from_columns(0.5, 0.0, -1.0, 0.3, 0.0)
    assert np.isnan(gamma) and theta == pytest.approx(0.30469265, abs=1e-8)
    assert np.isfinite(psi)
    psi, theta, gamma = mounting_angles_from_columns(0.0, 0.0, 0.0, 1.0, 1.0)
    assert np.isnan(psi) and theta == np.pi / 2 and gamma == 0.0
