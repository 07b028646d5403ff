"""Z-X-Y Euler rotations of seed 000: matrices from angles (eqs. 5, 7), angles back (eqs. 14, 17).

Convention (docs/reference/conventions.md): the attitude of frame a relative to frame b is a yaw
``psi`` about z, then a pitch ``theta`` about the new x, then a roll ``gamma`` about the new y
(intrinsic Z-X-Y).
The matrix of eq. (5) is the *passive* (frame-transformation) matrix ``C_b^a``, which maps
coordinates in b to coordinates in a::

    C_b^a = R_y(gamma) R_x(theta) R_z(psi)
          = Rotation.from_euler("ZXY", [psi, theta, gamma]).as_matrix().T

Matrices have shape ``(..., 3, 3)``; angles broadcast over leading axes.

References
----------
seed 000: Ding Tao (2014), eqs. (5), (7), (14), (17).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def mounting_matrix(psi: ArrayLike, theta: ArrayLike, gamma: ArrayLike) -> FloatArray:
    """Frame-transformation matrix ``C_b^a`` for Z-X-Y angles.

    Parameters
    ----------
    psi, theta, gamma : array_like [rad]
        Yaw about z, then pitch about x, then roll about y.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        Passive matrix taking b coordinates to a coordinates.

    References
    ----------
    seed 000, eq. (5).

    Examples
    --------
    A yaw of 90 deg about z: the b frame's x axis becomes the a frame's -y axis.

    >>> import numpy as np
    >>> C = mounting_matrix(np.pi / 2, 0.0, 0.0)
    >>> (C @ [1.0, 0.0, 0.0]).round(12) + 0.0
    array([ 0., -1.,  0.])

    It is the transpose of scipy's intrinsic Z-X-Y rotation:

    >>> from scipy.spatial.transform import Rotation
    >>> angles = np.radians([30.0, 20.0, 10.0])
    >>> bool(np.allclose(mounting_matrix(*angles),
    ...                  Rotation.from_euler("ZXY", angles).as_matrix().T, atol=1e-15))
    True
    """
    psi, theta, gamma = np.broadcast_arrays(*(np.asarray(v, float) for v in (psi, theta, gamma)))
    cp, sp = np.cos(psi), np.sin(psi)
    ct, st = np.cos(theta), np.sin(theta)
    cg, sg = np.cos(gamma), np.sin(gamma)
    rows = [  # seed 000, eq. (5)
        [cg * cp - sg * st * sp, cg * sp + sg * st * cp, -sg * ct],
        [-ct * sp, ct * cp, st],
        [sg * cp + cg * st * sp, sg * sp - cg * st * cp, cg * ct],
    ]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def target_frame_matrix(psi_m: ArrayLike, theta_m: ArrayLike) -> FloatArray:
    """Matrix ``C_a^{a_m}`` from frame a to the frame whose y axis points at the target.

    Frame a turned by the equivalent yaw ``psi_m`` about z and then the equivalent pitch
    ``theta_m`` about x; eq. (7) is eq. (5) with zero roll.

    Returns
    -------
    ndarray, shape (..., 3, 3)

    References
    ----------
    seed 000, eq. (7).
    """
    return mounting_matrix(psi_m, theta_m, 0.0)  # seed 000, eq. (7) = eq. (5) with gamma = 0


def euler_zxy_from_matrix(C: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Z-X-Y angles of a passive matrix, inverse of :func:`mounting_matrix`.

    Uses the element pattern of eq. (5): ``theta = arcsin(C23)``, ``psi = atan2(-C21, C22)``,
    ``gamma = atan2(-C13, C33)``. With ``atan2`` instead of eq. (17)'s ``arctan`` of the quotient
    the result is exact for any yaw and roll in (-pi, pi] and pitch in (-pi/2, pi/2); the two agree
    wherever eq. (17) applies (C22 > 0 and C33 > 0).

    Parameters
    ----------
    C : array_like, shape (..., 3, 3)

    Returns
    -------
    psi, theta, gamma : ndarray [rad]

    References
    ----------
    seed 000, eq. (17).

    Examples
    --------
    >>> import numpy as np
    >>> angles = np.radians([30.0, 20.0, 10.0])
    >>> np.degrees(euler_zxy_from_matrix(mounting_matrix(*angles))).round(12)
    array([30., 20., 10.])
    """
    C = np.asarray(C, float)
    theta = np.arcsin(np.clip(C[..., 1, 2], -1.0, 1.0))  # seed 000, eq. (17)
    psi = np.arctan2(-C[..., 1, 0], C[..., 1, 1])  # seed 000, eq. (17)
    gamma = np.arctan2(-C[..., 0, 2], C[..., 2, 2])  # seed 000, eq. (17)
    return psi, theta, gamma


def mounting_angles_from_columns(
    c12: ArrayLike, c32: ArrayLike, c13: ArrayLike, c23: ArrayLike, c33: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Z-X-Y angles from elements of the second and third columns of ``C_b^a``.

    For a rotation matrix of eq. (5) with all three angles in (-pi/2, pi/2)::

        theta = arcsin(C23)
        gamma = arctan(-C13 / C33)
        psi   = arcsin((C12 C33 - C13 C32) / sqrt(1 - C23**2))

    (``C12 C33 - C13 C32 = cos(theta) sin(psi)``.) Inputs that violate those ranges
    (``|C23| >= 1``, ``C33 <= 0``, the last quotient outside [-1, 1]) give NaN; callers that
    need to know why check those conditions themselves (see ``ground.solve_mounting``).

    Parameters
    ----------
    c12, c32, c13, c23, c33 : array_like
        Elements of ``C_b^a`` (or their estimates, normalised or not).

    Returns
    -------
    psi, theta, gamma : ndarray [rad]

    References
    ----------
    seed 000, eq. (14).

    Examples
    --------
    >>> import numpy as np
    >>> C = mounting_matrix(*np.radians([30.0, 20.0, 10.0]))
    >>> angles = mounting_angles_from_columns(C[0, 1], C[2, 1], C[0, 2], C[1, 2], C[2, 2])
    >>> np.degrees(angles).round(12)
    array([30., 20., 10.])
    """
    c12, c32, c13, c23, c33 = (np.asarray(v, float) for v in (c12, c32, c13, c23, c33))
    with np.errstate(invalid="ignore", divide="ignore"):
        cos_theta = np.sqrt(1.0 - c23**2)
        sin_psi = (c12 * c33 - c13 * c32) / cos_theta
        theta = np.arcsin(c23)  # seed 000, eq. (14)
        gamma = np.where(c33 > 0.0, np.arctan(-c13 / c33), np.nan)  # seed 000, eq. (14)
        psi = np.where(cos_theta > 0.0, np.arcsin(sin_psi), np.nan)  # seed 000, eq. (14)
    return psi, theta, gamma
