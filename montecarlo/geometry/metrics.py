"""Calibration error metrics of seed 000, eqs. (17)-(18), and the rotation angles kept apart.

``D = C_a^c = C_b^c (C_b^a)^T`` is the rotation from the true product frame a to the computed
frame c. Three scalar "angles" of D appear around seed 000 and must never be confused
(docs/reference/conventions.md):

=================  ================================  ==========================================
name               formula                           relation to the true rotation angle phi
=================  ================================  ==========================================
``rotation_angle`` ``arccos((tr D - 1) / 2)``        phi itself
``eq18_angle``     ``arccos(sqrt(1 + tr D) / 2)``    phi / 2 (eq. (18) as printed)
``table1_angle``   ``arccos((1 + tr D) / 4)``        about phi / sqrt(2) (the value of Table 1)
=================  ================================  ==========================================

The two arccos forms taken literally from the paper lose precision below about 1e-8 rad
(arccos near 1), which is far below any error they are used for; ``rotation_angle`` is computed
from the axial vector and the trace so that it is accurate at any size.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from montecarlo.geometry.rotations import euler_zxy_from_matrix

FloatArray = NDArray[np.float64]


def error_matrix(C_bc: ArrayLike, C_ba: ArrayLike) -> FloatArray:
    """``D = C_a^c = C_b^c (C_b^a)^T``, shape (..., 3, 3).

    References
    ----------
    seed 000, the relation before eq. (17).
    """
    return np.matmul(C_bc, np.swapaxes(np.asarray(C_ba, float), -1, -2))


def error_angles(D: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per-axis error angles (delta_psi, delta_theta, delta_gamma) [rad] of D, Z-X-Y.

    References
    ----------
    seed 000, eq. (17).
    """
    return euler_zxy_from_matrix(D)


def _trace(D: ArrayLike) -> FloatArray:
    return np.trace(np.asarray(D, float), axis1=-2, axis2=-1)


def rotation_angle(D: ArrayLike) -> FloatArray:
    """True rotation angle phi [rad] of D, in [0, pi]; equals ``arccos((tr D - 1) / 2)``.

    Computed as ``atan2(|axial vector|, (tr D - 1) / 2)``, accurate for small and large angles.

    Examples
    --------
    The three metrics of one error rotation of 1 mrad (docs/reference/conventions.md):

    >>> from scipy.spatial.transform import Rotation
    >>> D = Rotation.from_rotvec([0.0, 0.0, 1e-3]).as_matrix()
    >>> round(float(rotation_angle(D)), 12), round(float(eq18_angle(D)), 12)
    (0.001, 0.0005)
    >>> round(float(table1_angle(D)) * 2**0.5, 6)
    0.001
    """
    D = np.asarray(D, float)
    axial = np.stack(
        [D[..., 2, 1] - D[..., 1, 2], D[..., 0, 2] - D[..., 2, 0], D[..., 1, 0] - D[..., 0, 1]],
        axis=-1,
    )
    return np.arctan2(0.5 * np.linalg.norm(axial, axis=-1), 0.5 * (_trace(D) - 1.0))


def eq18_angle(D: ArrayLike) -> FloatArray:
    """Eq. (18) as printed, ``arccos(sqrt(1 + tr D) / 2)`` [rad]; equals phi / 2.

    The argument is clipped to [0, 1] so that round-off in tr D (it may exceed 3 by an ulp) does
    not produce NaN.

    References
    ----------
    seed 000, eq. (18).
    """
    return np.arccos(np.clip(np.sqrt(np.clip(1.0 + _trace(D), 0.0, None)) / 2.0, 0.0, 1.0))


def table1_angle(D: ArrayLike) -> FloatArray:
    """The metric behind Table 1, ``arccos((1 + tr D) / 4)`` [rad]; about phi / sqrt(2).

    Not a formula printed in seed 000: docs/reference/conventions.md shows that all twelve values of
    Table 1 are reproduced by this expression (the paper's Delta and normalised Delta).

    References
    ----------
    seed 000, Table 1; docs/reference/conventions.md, "How seed 000's Table 1 was computed".
    """
    return np.arccos(np.clip((1.0 + _trace(D)) / 4.0, -1.0, 1.0))


ROTATION_METRICS = {
    "rotation_angle": (rotation_angle, "true rotation angle φ of D"),
    "eq18_angle": (eq18_angle, "eq. (18) as printed, arccos(√(1+tr D)/2) = φ/2"),
    "table1_angle": (table1_angle, "Table 1 metric arccos((1+tr D)/4) ≈ φ/√2"),
}
"""Name -> (function, label) of every scalar rotation metric; outputs use these names."""

AXIS_METRICS = {
    "delta_psi": "yaw error δψ (eq. 17)",
    "delta_theta": "pitch error δθ (eq. 17)",
    "delta_gamma": "roll error δγ (eq. 17)",
}
"""Name -> label of the per-axis error angles of eq. (17)."""


def all_metrics(D: ArrayLike) -> dict[str, FloatArray]:
    """Every rotation metric and per-axis error angle of D [rad], keyed by the names above."""
    out = {name: fn(D) for name, (fn, _) in ROTATION_METRICS.items()}
    out.update(zip(AXIS_METRICS, error_angles(D), strict=True))
    return out
