"""Ground static-base two-target calibration of seed 000, sections 1.2-1.4 (eqs. 6-16).

Literal, vectorised reference implementation: every step follows the paper's trigonometric
form (equivalent angles, eq. (7) matrices). Functions take whole batches of trials (leading axes
broadcast) and flag invalid geometry per trial with :class:`montecarlo.geometry.invalid.Invalid`.

Frames (docs/reference/conventions.md): base b has x right, y forward, z up, origin at the sensor;
target A is on the forward axis at range L and the sensor's height, target B is A raised by H.

References
----------
seed 000: Ding Tao (2014), eqs. (6)-(16).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from montecarlo.geometry import camera as cam
from montecarlo.geometry.invalid import FLAG_DTYPE, Invalid, mark
from montecarlo.geometry.metrics import all_metrics, error_matrix
from montecarlo.geometry.rotations import (
    mounting_angles_from_columns,
    mounting_matrix,
    target_frame_matrix,
)

FloatArray = NDArray[np.float64]
FlagArray = NDArray[np.uint16]

SOLVERS = ("raw", "normalised")
"""Solver variants: eqs. (11), (14) alone, or with the normalisation of eqs. (12)-(13)."""


def target_positions(
    L: ArrayLike,
    H: ArrayLike,
    dx: ArrayLike = 0.0,
    dy: ArrayLike = 0.0,
    dh1: ArrayLike = 0.0,
    dh: ArrayLike = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """Actual positions of targets A' and B' in frame b, with placement errors.

    ``r_A' = [dx, L + dy, dh1]`` and ``r_B' = [dx, L + dy, H + dh1 + dh]``: B' is A' raised, so
    they share the horizontal error; ``dh1`` is the height-reference error and ``dh`` the error of
    the height scale (``delta_h2 = delta_h1 + delta_h``).

    Parameters
    ----------
    L, H : array_like [m]
        Nominal range and height difference.
    dx, dy, dh1, dh : array_like [m]
        Lateral, range, height-reference and height-scale errors.

    Returns
    -------
    r_a, r_b : ndarray, shape (..., 3) [m]

    References
    ----------
    seed 000, section 1.3 (the positions used in eqs. (15)-(16)).
    """
    L, H, dx, dy, dh1, dh = np.broadcast_arrays(
        *(np.asarray(v, float) for v in (L, H, dx, dy, dh1, dh))
    )
    r_a = np.stack([dx, L + dy, dh1], axis=-1)
    r_b = np.stack([dx, L + dy, H + dh1 + dh], axis=-1)
    return r_a, r_b


def target_in_product_frame(C_ba: ArrayLike, r_b: ArrayLike) -> FloatArray:
    """Target coordinates in frame a, ``r^a = C_b^a r^b``, shape (..., 3).

    References
    ----------
    seed 000, eq. (6).
    """
    return np.matmul(C_ba, np.asarray(r_b, float)[..., None])[..., 0]  # seed 000, eq. (6)


def equivalent_angles_of_target(
    C_ba: ArrayLike, r_b: ArrayLike
) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """Equivalent angles under which the sensor sees a target at ``r_b``.

    Parameters
    ----------
    C_ba : array_like, shape (..., 3, 3)
        True mounting matrix (eq. (5)).
    r_b : array_like, shape (..., 3) [m]
        Target position in frame b.

    Returns
    -------
    psi_m, theta_m : ndarray [rad]
        ``theta = arcsin(r^a_z / |r|)``, ``psi = arctan(-r^a_x / r^a_y)``; NaN behind the sensor.
    in_front : ndarray of bool
        False where the target is behind the focal plane (``r^a_y <= 0``).

    References
    ----------
    seed 000, eqs. (9)-(10), and their instances (15) for A' and (16) for B'.
    """
    r_a = target_in_product_frame(C_ba, r_b)
    front = cam.in_front(r_a)
    with np.errstate(divide="ignore", invalid="ignore"):
        theta_m = np.arcsin(r_a[..., 2] / np.linalg.norm(r_b, axis=-1))  # eqs. (10), (15), (16)
        psi_m = np.arctan(-r_a[..., 0] / r_a[..., 1])  # seed 000, eqs. (10), (15), (16)
    return np.where(front, psi_m, np.nan), np.where(front, theta_m, np.nan), front


def observe_target(
    C_ba: ArrayLike, r_b: ArrayLike, camera: cam.Camera
) -> tuple[FloatArray, FlagArray]:
    """Ideal pixel coordinates of a target, the paper's forward model.

    Returns
    -------
    pixels : ndarray, shape (..., 2) [px]
        ``[f_mx, f_mz]`` from eq. (4) applied to the angles of eqs. (15)-(16); NaN behind the
        sensor, the true (off-detector) projection outside the field of view.
    invalid : ndarray of uint16
        ``BEHIND_SENSOR`` or ``OUTSIDE_FOV`` where the target cannot be seen.

    References
    ----------
    seed 000, eqs. (15)-(16) and the pixel equations that follow them (eq. (4)).
    """
    psi_m, theta_m, front = equivalent_angles_of_target(C_ba, r_b)
    f_mx, f_mz = cam.pixels_from_equivalent_angles(psi_m, theta_m, camera)  # seed 000, eq. (4)
    flags = np.where(front, 0, Invalid.BEHIND_SENSOR).astype(FLAG_DTYPE)
    mark(flags, front & ~cam.in_field_of_view(f_mx, f_mz, camera), Invalid.OUTSIDE_FOV)
    return np.stack([f_mx, f_mz], axis=-1), flags


@dataclass(frozen=True)
class MountingSolution:
    """Mounting angles computed by the solver for a batch of trials.

    Attributes
    ----------
    psi, theta, gamma : ndarray [rad]
        Computed yaw, pitch and roll (``psi_c, theta_c, gamma_c``); NaN where invalid.
    invalid : ndarray of uint16
        :class:`Invalid` bits; zero where the solution is valid.
    """

    psi: FloatArray
    theta: FloatArray
    gamma: FloatArray
    invalid: FlagArray

    @property
    def valid(self) -> NDArray[np.bool_]:
        return self.invalid == 0

    def matrix(self) -> FloatArray:
        """Computed mounting matrix ``C_b^c`` (eq. (5) of the computed angles), (..., 3, 3)."""
        return mounting_matrix(self.psi, self.theta, self.gamma)


def _input_flags(pix_a: FloatArray, pix_b: FloatArray, L: FloatArray, H: FloatArray,
                 camera: cam.Camera) -> FlagArray:
    finite = (np.isfinite(pix_a).all(axis=-1) & np.isfinite(pix_b).all(axis=-1)
              & np.isfinite(L) & np.isfinite(H))
    flags = np.where(finite, 0, Invalid.NAN_INPUT).astype(FLAG_DTYPE)
    mark(flags, finite & (L <= 0.0), Invalid.RANGE_NOT_POSITIVE)
    mark(flags, finite & (H == 0.0), Invalid.ZERO_HEIGHT)
    seen = (cam.in_field_of_view(pix_a[..., 0], pix_a[..., 1], camera)
            & cam.in_field_of_view(pix_b[..., 0], pix_b[..., 1], camera))
    mark(flags, finite & ~seen, Invalid.OUTSIDE_FOV)
    return flags


def solve_mounting(
    pix_a: ArrayLike,
    pix_b: ArrayLike,
    L: ArrayLike,
    H: ArrayLike,
    camera: cam.Camera,
    normalise: bool = True,
) -> MountingSolution:
    """Mounting angles from the pixel coordinates of targets A and B.

    The solver knows only the nominal geometry: A at ``[0, L, 0]`` and B at ``[0, L, H]``.

    Parameters
    ----------
    pix_a, pix_b : array_like, shape (..., 2) [px]
        Measured ``[f_mx, f_mz]`` of targets A and B.
    L, H : array_like [m]
        Nominal range (> 0) and height difference (!= 0).
    camera : Camera
    normalise : bool
        Apply the partial normalisation of eqs. (12)-(13) before eq. (14).

    Returns
    -------
    MountingSolution

    References
    ----------
    seed 000, eqs. (3), (7)-(9), (11)-(14).
    """
    pix_a = np.asarray(pix_a, float)
    pix_b = np.asarray(pix_b, float)
    shape = np.broadcast_shapes(pix_a.shape[:-1], pix_b.shape[:-1], np.shape(L), np.shape(H))
    pix_a = np.broadcast_to(pix_a, (*shape, 2))
    pix_b = np.broadcast_to(pix_b, (*shape, 2))
    L = np.broadcast_to(np.asarray(L, float), shape)
    H = np.broadcast_to(np.asarray(H, float), shape)
    flags = _input_flags(pix_a, pix_b, L, H, camera)

    psi_a, theta_a = cam.equivalent_angles_from_pixels(pix_a[..., 0], pix_a[..., 1], camera)
    psi_b, theta_b = cam.equivalent_angles_from_pixels(pix_b[..., 0], pix_b[..., 1], camera)
    a2 = target_frame_matrix(psi_a, theta_a)[..., 1, :]  # [A21, A22, A23], eqs. (7)-(8)
    b2 = target_frame_matrix(psi_b, theta_b)[..., 1, :]  # [B21, B22, B23]
    with np.errstate(divide="ignore", invalid="ignore"):
        c12, c22, c32 = np.moveaxis(a2, -1, 0)  # seed 000, eq. (11)
        col3 = (b2 * np.hypot(L, H)[..., None] - a2 * L[..., None]) / H[..., None]  # eq. (11)
        c13, c23, c33 = np.moveaxis(col3, -1, 0)
        if normalise:
            alpha = np.sqrt(c13**2 + c23**2 + c33**2)  # seed 000, eq. (12)
            beta = np.sqrt((c12 * c33 - c13 * c32) ** 2 + c22**2 + c23**2)  # seed 000, eq. (12)
            c13, c23, c33 = c13 / alpha, c23 / alpha, c33 / alpha  # seed 000, eq. (13)
            c12, c32 = alpha * c12 / beta, alpha * c32 / beta  # seed 000, eq. (13)
    psi, theta, gamma = mounting_angles_from_columns(c12, c32, c13, c23, c33)  # eq. (14)

    eq14 = np.where(np.abs(c23) < 1.0, 0, Invalid.PITCH_OUT_OF_RANGE).astype(FLAG_DTYPE)
    mark(eq14, ~(c33 > 0.0), Invalid.ROLL_OUT_OF_RANGE)
    mark(eq14, (eq14 == 0) & ~np.isfinite(psi), Invalid.YAW_OUT_OF_RANGE)
    flags = np.where(flags == 0, eq14, flags).astype(FLAG_DTYPE)
    ok = flags == 0
    return MountingSolution(
        np.where(ok, psi, np.nan), np.where(ok, theta, np.nan), np.where(ok, gamma, np.nan), flags
    )


def simulate(
    camera: cam.Camera,
    true_angles: tuple[ArrayLike, ArrayLike, ArrayLike],
    L: ArrayLike,
    H: ArrayLike,
    *,
    dx: ArrayLike = 0.0,
    dy: ArrayLike = 0.0,
    dh1: ArrayLike = 0.0,
    dh: ArrayLike = 0.0,
    pixel_error_a: ArrayLike = 0.0,
    pixel_error_b: ArrayLike = 0.0,
    solvers: Sequence[str] = SOLVERS,
) -> dict[str, MountingSolution]:
    """Simulate a batch of ground calibrations: placement -> pixels (+ error) -> solve.

    Parameters
    ----------
    camera : Camera
    true_angles : (psi, theta, gamma), array_like [rad]
        True mounting angles.
    L, H : array_like [m]
        Nominal range and height difference (what the solver is told).
    dx, dy, dh1, dh : array_like [m]
        Placement errors, see :func:`target_positions`.
    pixel_error_a, pixel_error_b : array_like, shape (..., 2) or scalar [px]
        Errors added to the ideal ``[f_mx, f_mz]`` of A' and B'.
    solvers : sequence of {"raw", "normalised"}

    Returns
    -------
    dict of solver name -> MountingSolution
        A trial rejected by the forward model (target behind the sensor or out of view) carries
        the forward model's reasons; otherwise the solver's.

    References
    ----------
    seed 000, section 1.3 (error analysis flow): eqs. (15)-(16), (4), then (3), (11)-(14).
    """
    unknown = set(solvers) - set(SOLVERS)
    if unknown:
        raise ValueError(f"unknown solver(s) {sorted(unknown)}; choose from {SOLVERS}")
    C_ba = mounting_matrix(*true_angles)
    r_a, r_b = target_positions(L, H, dx, dy, dh1, dh)
    pix_a, flags_a = observe_target(C_ba, r_a, camera)
    pix_b, flags_b = observe_target(C_ba, r_b, camera)
    forward_flags = flags_a | flags_b
    pix_a = pix_a + np.asarray(pixel_error_a, float)
    pix_b = pix_b + np.asarray(pixel_error_b, float)
    out = {}
    for name in solvers:
        sol = solve_mounting(pix_a, pix_b, L, H, camera, normalise=(name == "normalised"))
        flags = np.where(forward_flags != 0, forward_flags, sol.invalid).astype(FLAG_DTYPE)
        ok = flags == 0
        psi, theta, gamma = (np.where(ok, v, np.nan) for v in (sol.psi, sol.theta, sol.gamma))
        out[name] = MountingSolution(psi, theta, gamma, flags)
    return out


def solution_metrics(solution: MountingSolution, true_angles: tuple[ArrayLike, ...]
                     ) -> dict[str, FloatArray]:
    """Error metrics of a solution against the true angles [rad] (:mod:`.geometry.metrics`).

    References
    ----------
    seed 000, eqs. (17)-(18).
    """
    D = error_matrix(solution.matrix(), mounting_matrix(*true_angles))
    return all_metrics(D)
