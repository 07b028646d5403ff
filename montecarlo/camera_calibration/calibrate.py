"""Calibration of a camera from views of a planar target: Zhang's closed form, then least squares.

1. A homography per view (normalised DLT): ``s (u, v, 1)' = H (X, Y, 1)'``.
2. Zhang's closed form: each homography gives two linear constraints on the image of the
   absolute conic ``B = K^-T K^-1``; three views or more fix ``B`` and so the intrinsics
   (with skew); each view's pose then follows from ``K^-1 H``.
3. Nonlinear least squares (``scipy.optimize.least_squares``) of the chosen model over all
   views: intrinsics, distortion and poses together, the Jacobian by central differences, the
   covariance ``sigma^2 (J'J)^-1`` (``sigma`` stated, or estimated from the residuals).

References
----------
Z. Zhang (1998, updated 1999), A flexible new technique for camera calibration, Microsoft
Research technical report MSR-TR-98-71: section 2.1-2.3 and appendix A (homography, eqs. (3)-(8)),
section 3.1 (closed form, appendix B), section 3.2 (maximum-likelihood estimate), section 3.3
(radial distortion). R. Hartley (1997), In defense of the eight-point algorithm (normalisation).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import optimize

from montecarlo.camera_calibration.model import DISTORTION, project
from montecarlo.lsq import ParameterSummary

FloatArray = NDArray[np.float64]


class CalibrationError(ValueError):
    """These views cannot calibrate the camera (too few, degenerate, singular)."""


def _normaliser(pts: FloatArray) -> FloatArray:
    """Similarity moving ``pts`` (n, 2) to zero mean and mean distance sqrt(2) (Hartley)."""
    c = pts.mean(axis=0)
    d = np.mean(np.linalg.norm(pts - c, axis=1))
    s = math.sqrt(2.0) / d if d > 0 else 1.0
    return np.array([[s, 0.0, -s * c[0]], [0.0, s, -s * c[1]], [0.0, 0.0, 1.0]])


def homography(model: ArrayLike, image: ArrayLike) -> FloatArray:
    """Homography H (3, 3) with ``image ~ H model`` by the normalised DLT, ``H[2, 2] = 1``.

    References
    ----------
    Zhang (1998), eq. (2) and appendix A; Hartley (1997) for the normalisation.
    """
    M, m = np.asarray(model, float), np.asarray(image, float)
    if M.shape[0] < 4:
        raise CalibrationError(f"{M.shape[0]} points in a view, at least 4 needed")
    TM, Tm = _normaliser(M), _normaliser(m)
    Mh = np.column_stack([M, np.ones(len(M))]) @ TM.T
    mh = np.column_stack([m, np.ones(len(m))]) @ Tm.T
    zero = np.zeros_like(Mh)
    rows = np.concatenate([
        np.column_stack([Mh, zero, -mh[:, :1] * Mh]),
        np.column_stack([zero, Mh, -mh[:, 1:2] * Mh])])
    _, s, vt = np.linalg.svd(rows, full_matrices=False)
    if s[-2] < 1e-12 * s[0]:
        raise CalibrationError("the points of a view do not fix a homography (collinear?)")
    H = np.linalg.inv(Tm) @ vt[-1].reshape(3, 3) @ TM
    return H / H[2, 2]


def _v(H: FloatArray, i: int, j: int) -> FloatArray:
    """Zhang (1998), eq. (7): the row ``v_ij`` with ``h_i' B h_j = v_ij' b``."""
    hi, hj = H[:, i], H[:, j]
    return np.array([hi[0] * hj[0], hi[0] * hj[1] + hi[1] * hj[0], hi[1] * hj[1],
                     hi[2] * hj[0] + hi[0] * hj[2], hi[2] * hj[1] + hi[1] * hj[2],
                     hi[2] * hj[2]])


def intrinsics_from_homographies(Hs: Sequence[FloatArray]) -> FloatArray:
    """Camera matrix K (3, 3) ``[[alpha, gamma, u0], [0, beta, v0], [0, 0, 1]]`` [px].

    Solves Zhang's ``V b = 0`` (eq. (9), two rows per view: ``v_12`` and ``v_11 - v_22``) by
    SVD and extracts the intrinsics by his appendix B.

    Raises
    ------
    CalibrationError
        Fewer than three views, or views that do not fix the intrinsics.
    """
    if len(Hs) < 3:
        raise CalibrationError(f"{len(Hs)} views, at least 3 needed for the closed form")
    scaled = [H / np.linalg.norm(H) for H in Hs]
    V = np.concatenate([[_v(H, 0, 1), _v(H, 0, 0) - _v(H, 1, 1)] for H in scaled])
    b = np.linalg.svd(V)[2][-1]
    B11, B12, B22, B13, B23, B33 = b
    den = B11 * B22 - B12**2
    if B11 == 0.0 or den == 0.0:
        raise CalibrationError("the views do not fix the intrinsics (parallel target planes?)")
    v0 = (B12 * B13 - B11 * B23) / den  # Zhang (1998), appendix B
    lam = B33 - (B13**2 + v0 * (B12 * B13 - B11 * B23)) / B11
    if lam / B11 <= 0.0 or lam * B11 / den <= 0.0:
        raise CalibrationError("the views do not fix the intrinsics (no real focal length)")
    alpha = math.sqrt(lam / B11)
    beta = math.sqrt(lam * B11 / den)
    gamma = -B12 * alpha**2 * beta / lam
    u0 = gamma * v0 / beta - B13 * alpha**2 / lam
    return np.array([[alpha, gamma, u0], [0.0, beta, v0], [0.0, 0.0, 1.0]])


def pose_from_homography(K: FloatArray, H: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Rotation vector [rad] and translation (target units) of a view, Zhang (1998), section
    3.1: ``r1 = l K^-1 h1``, ``r2 = l K^-1 h2``, ``r3 = r1 x r2``, ``t = l K^-1 h3``,
    ``l = 1 / |K^-1 h1|``, the sign chosen for a target in front (``t_z > 0``) and R made the
    nearest rotation (SVD, his appendix C)."""
    from scipy.spatial.transform import Rotation

    Ki = np.linalg.inv(K)
    A = Ki @ H
    lam = 1.0 / np.linalg.norm(A[:, 0])
    if A[2, 2] * lam < 0:
        lam = -lam
    r1, r2, t = lam * A[:, 0], lam * A[:, 1], lam * A[:, 2]
    Q = np.column_stack([r1, r2, np.cross(r1, r2)])
    U, _, Vt = np.linalg.svd(Q)
    R = U @ Vt
    if np.linalg.det(R) < 0:
        R = U @ np.diag([1.0, 1.0, -1.0]) @ Vt
    return Rotation.from_matrix(R).as_rotvec(), t


def closed_form(points: ArrayLike, image: ArrayLike, view: ArrayLike, n_views: int
                ) -> dict[str, FloatArray]:
    """Zhang's closed-form intrinsics and poses: ``{"K", "rvec" (V, 3), "tvec" (V, 3)}``."""
    points, image, view = np.asarray(points, float), np.asarray(image, float), np.asarray(view)
    Hs = [homography(points[view == v], image[view == v]) for v in range(n_views)]
    K = intrinsics_from_homographies(Hs)
    poses = [pose_from_homography(K, H) for H in Hs]
    return {"K": K, "rvec": np.array([p[0] for p in poses]),
            "tvec": np.array([p[1] for p in poses])}


@dataclass(frozen=True)
class Calibration(ParameterSummary):
    """A fitted camera.

    Attributes
    ----------
    names, values : parameters (intrinsics, distortion, then ``rx_V, ry_V, rz_V`` [rad] and
        ``tx_V, ty_V, tz_V`` [m] of each view).
    covariance : (p, p) covariance of the values.
    residual : (n, 2) measured minus predicted pixels [px].
    sigma : the pixel noise behind the covariance [px] (stated, or estimated).
    """

    names: tuple[str, ...]
    values: FloatArray
    covariance: FloatArray
    residual: FloatArray
    sigma: float

    @property
    def chi2(self) -> float:
        """Sum of squared residuals over the noise behind the covariance [1]."""
        return float(np.sum(self.residual**2)) / self.sigma**2

    @property
    def rms(self) -> float:
        """RMS residual per image coordinate [px] (the per-point RMS is sqrt(2) larger)."""
        return float(np.sqrt(np.mean(self.residual**2)))

    @property
    def dof(self) -> int:
        return self.residual.size - len(self.names)


def pose_names(n_views: int) -> tuple[str, ...]:
    return tuple(f"{a}_{v + 1}" for v in range(n_views)
                 for a in ("rx", "ry", "rz", "tx", "ty", "tz"))


def poses_of(values: Mapping[str, ArrayLike], n_views: int) -> tuple[FloatArray, FloatArray]:
    """(rvec, tvec), each (..., V, 3), from named pose parameters (scalars or (k, 1))."""
    def stack(prefix: str) -> FloatArray:
        cols = [np.stack(np.broadcast_arrays(*(np.asarray(values[f"{prefix}{a}_{v + 1}"], float)
                                                 for a in "xyz")), axis=-1)
                for v in range(n_views)]
        return np.stack(np.broadcast_arrays(*cols), axis=-2)
    r, t = stack("r"), stack("t")
    if r.ndim == 4:  # (k, 1) parameters: drop the trailing 1
        r, t = r[:, 0], t[:, 0]
    r, t = np.broadcast_arrays(r, t)
    return r, t


def calibrate(points: ArrayLike, image: ArrayLike, view: ArrayLike, n_views: int,
              distortion: Sequence[str] = ("k1", "k2"), skew: bool = True,
              aspect: bool = True, sigma: float | None = None) -> Calibration:
    """Fit intrinsics, ``distortion`` (names of :data:`DISTORTION`) and poses.

    Parameters
    ----------
    points : (n, 2) target coordinates [m]; image : (n, 2) measured pixels [px];
    view : (n,) view index 0..V-1.
    skew, aspect : fit gamma and the aspect departure a (else zero).
    sigma : pixel noise per coordinate [px] for the covariance; None: estimated,
        ``sqrt(r'r / dof)``.

    References
    ----------
    Zhang (1998), section 3.2 (maximum-likelihood estimate, eq. (10)) and 3.3 (eq. (14)).
    """
    points, image, view = np.asarray(points, float), np.asarray(image, float), np.asarray(view)
    unknown = [d for d in distortion if d not in DISTORTION]
    if unknown:
        raise ValueError(f"unknown distortion terms {unknown}; known: {DISTORTION}")
    start = closed_form(points, image, view, n_views)
    K = start["K"]
    intr = {"f": K[0, 0], "cx": K[0, 2], "cy": K[1, 2]}
    if aspect:
        intr["a"] = K[1, 1] / K[0, 0] - 1.0
    if skew:
        intr["gamma"] = K[0, 1]
    names = (*intr, *distortion, *pose_names(n_views))
    x0 = np.concatenate([list(intr.values()), np.zeros(len(distortion)),
                         np.column_stack([start["rvec"], start["tvec"]]).ravel()])

    def residual(x: FloatArray) -> FloatArray:
        values = dict(zip(names, x, strict=True))
        r, t = poses_of(values, n_views)
        return (image - project(values, r, t, points, view)).ravel()

    sol = optimize.least_squares(residual, x0, method="lm", x_scale="jac", xtol=1e-15,
                                 ftol=1e-15, gtol=1e-15, max_nfev=2000)
    J = sol.jac
    dof = sol.fun.size - len(names)
    if dof < 1:
        raise CalibrationError(f"{sol.fun.size} image coordinates cannot fit {len(names)} "
                               "parameters")
    s = np.linalg.svd(J / np.linalg.norm(J, axis=0), compute_uv=False)
    if s[-1] < 1e-10 * s[0]:
        raise CalibrationError("the parameters are not separable with these views")
    sig = float(np.sqrt(sol.fun @ sol.fun / dof)) if sigma is None else float(sigma)
    cov = sig**2 * np.linalg.inv(J.T @ J)
    return Calibration(names, sol.x, cov, sol.fun.reshape(-1, 2), sig)
