"""Forward model of a camera observing a planar target: poses, Brown-Conrady distortion, pixels.

A target point ``P = (X, Y, 0)`` [m] (target frame) seen in view ``v`` is moved into the camera
frame by that view's pose, ``p = R(w_v) P + t_v`` (``w_v`` a rotation vector [rad], ``R`` by
Rodrigues' formula, ``t_v`` [m]); the camera's z axis is the optical axis, x points along image
rows (u grows), y down the columns (v grows). The normalised coordinates ``x = p_x / p_z``,
``y = p_y / p_z`` are distorted (Brown-Conrady, in the form of OpenCV and of Zhang's report):

    ``r^2 = x^2 + y^2``,
    ``x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)``,
    ``y_d = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y``,

and mapped to pixels by the intrinsics

    ``u = f x_d + gamma y_d + c_x``,   ``v = f (1 + a) y_d + c_y``,

``f`` the focal length along rows [px], ``a`` the aspect-ratio departure (``f_y = f (1 + a)``),
``gamma`` the skew [px] (Zhang's gamma), ``(c_x, c_y)`` the principal point [px]. Every
parameter absent from a call is zero: the ideal pinhole with square pixels.

References
----------
Z. Zhang (1998, updated 1999), A flexible new technique for camera calibration, Microsoft
Research technical report MSR-TR-98-71, eqs. (1), (2) (pinhole, skew) and (11)-(12) (radial
distortion on the ideal normalised coordinates); D. C. Brown (1966), Decentering distortion of
lenses, Photogrammetric Engineering 32(3) (tangential terms p1, p2).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

INTRINSICS = ("f", "a", "gamma", "cx", "cy")
"""Intrinsic parameters: focal length [px], aspect departure [1], skew [px], principal point
[px]."""
DISTORTION = ("k1", "k2", "k3", "p1", "p2")
"""Brown-Conrady distortion coefficients [1] on normalised coordinates."""


def rotate(w: ArrayLike, points: ArrayLike) -> FloatArray:
    """Rotate ``points`` by the rotation vectors ``w`` (Rodrigues' formula), shape (..., 3).

    ``R(w) P = P cos(t) + (k x P) sin(t) + k (k . P)(1 - cos(t))``, ``t = |w|``, ``k = w / t``;
    written with ``sin(t)/t`` and ``(1 - cos(t))/t^2`` (their series below ``t = 1e-4``) so
    that ``w = 0`` is exact. Same convention as ``scipy.spatial.transform.Rotation.from_rotvec``
    (active rotation).

    Parameters
    ----------
    w : (..., 3) rotation vectors [rad].
    points : (..., 3) points; broadcast against ``w``.
    """
    w = np.asarray(w, float)
    p = np.asarray(points, float)
    t2 = np.sum(w * w, axis=-1, keepdims=True)
    t = np.sqrt(t2)
    small = t < 1e-4
    safe = np.where(small, 1.0, t)
    a = np.where(small, 1.0 - t2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - t2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    cross = np.cross(w, p)
    return p + a * cross + b * np.cross(w, cross)


def rotation_matrix(w: ArrayLike) -> FloatArray:
    """Rotation matrices of rotation vectors ``w`` [rad], shape (..., 3) -> (..., 3, 3).

    Rodrigues' formula in matrix form, ``R = I + a [w]x + b [w]x^2`` with the ``a``, ``b`` of
    :func:`rotate` (``R P`` equals ``rotate(w, P)``). :func:`project` uses it: one matrix per
    view, instead of two cross products per point.
    """
    w = np.asarray(w, float)
    t2 = np.sum(w * w, axis=-1)
    t = np.sqrt(t2)
    small = t < 1e-4
    safe = np.where(small, 1.0, t)
    a = np.where(small, 1.0 - t2 / 6.0, np.sin(safe) / safe)[..., None, None]
    b = np.where(small, 0.5 - t2 / 24.0, (1.0 - np.cos(safe)) / safe**2)[..., None, None]
    zero = np.zeros_like(w[..., 0])
    K = np.stack([np.stack([zero, -w[..., 2], w[..., 1]], axis=-1),
                  np.stack([w[..., 2], zero, -w[..., 0]], axis=-1),
                  np.stack([-w[..., 1], w[..., 0], zero], axis=-1)], axis=-2)
    return np.eye(3) + a * K + b * (K @ K)


def distort(x: ArrayLike, y: ArrayLike, params: Mapping[str, ArrayLike]
            ) -> tuple[FloatArray, FloatArray]:
    """Brown-Conrady distortion of normalised coordinates (module docstring) [1]."""
    def p(name: str) -> FloatArray:
        return np.asarray(params.get(name, 0.0), float)

    x, y = np.asarray(x, float), np.asarray(y, float)
    r2 = x * x + y * y
    radial = 1.0 + r2 * (p("k1") + r2 * (p("k2") + r2 * p("k3")))  # Zhang (1998), eq. (11)
    p1, p2 = p("p1"), p("p2")
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)  # Brown (1966)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return xd, yd


def project(params: Mapping[str, ArrayLike], rvec: ArrayLike, tvec: ArrayLike,
            points: ArrayLike, view: ArrayLike) -> FloatArray:
    """Pixels of target points, shape (..., n, 2) [px].

    Parameters
    ----------
    params : intrinsics and distortion (:data:`INTRINSICS`, :data:`DISTORTION`); floats or
        arrays of shape (k, 1) for k parameter vectors at once; missing ones are zero.
    rvec, tvec : (..., V, 3) rotation vector [rad] and translation [m] of each view.
    points : (n, 2) target coordinates X, Y [m] (Z = 0).
    view : (n,) index of each point's view in ``rvec``/``tvec``.

    References
    ----------
    Zhang (1998), eqs. (1)-(2) and (11); see the module docstring.
    """
    def p(name: str) -> FloatArray:
        return np.asarray(params.get(name, 0.0), float)

    pts = np.asarray(points, float)
    idx = np.asarray(view, int)
    R = rotation_matrix(rvec)  # (..., V, 3, 3): the target's Z = 0 leaves its first two columns
    cam = (R[..., 0][..., idx, :] * pts[:, :1] + R[..., 1][..., idx, :] * pts[:, 1:2]
           + np.asarray(tvec, float)[..., idx, :])
    x, y = cam[..., 0] / cam[..., 2], cam[..., 1] / cam[..., 2]
    xd, yd = distort(x, y, params)
    f = p("f")
    u = f * xd + p("gamma") * yd + p("cx")  # Zhang (1998), eq. (1): alpha, gamma, u0
    v = f * (1.0 + p("a")) * yd + p("cy")  # beta = f (1 + a), v0
    return np.stack(np.broadcast_arrays(u, v), axis=-1)


def depth(rvec: ArrayLike, tvec: ArrayLike, points: ArrayLike, view: ArrayLike) -> FloatArray:
    """Camera-frame depth ``p_z`` [m] of every point (positive: in front of the camera)."""
    pts = np.asarray(points, float)
    P = np.concatenate([pts, np.zeros((pts.shape[0], 1))], axis=1)
    idx = np.asarray(view, int)
    return (rotate(np.asarray(rvec, float)[idx], P) + np.asarray(tvec, float)[idx])[:, 2]
