"""Camera calibration from a planar target: the pinhole as base model, distortion as candidates.

The forward model is :func:`montecarlo.camera_calibration.model.project` (Zhang 1998, eqs. (1),
(2), (11); Brown-Conrady tangential terms). The **base model** is the ideal pinhole with square
pixels and no skew: focal length ``f`` [px], principal point ``(cx, cy)`` [px], and each view's
pose (rotation vector ``rx_V, ry_V, rz_V`` [rad], translation ``tx_V, ty_V, tz_V`` [m]). The
**candidates**, each absent at zero:

- ``radial_k1``, ``radial_k2``, ``radial_k3``: radial distortion ``1 + k1 r^2 + k2 r^4 +
  k3 r^6`` on normalised coordinates, tested in that order (k2 only once k1 is in the model,
  k3 once k2 is);
- ``tangential``: decentering ``p1, p2`` (Brown 1966);
- ``skew``: ``gamma`` [px], ``u = f x + gamma y + cx``;
- ``aspect_ratio``: ``a``, ``f_y = f (1 + a)``;

and every corner of every view (``VIEW/ID``) by data snooping. Residuals are whitened by the
stated pixel noise ``sigma`` per coordinate, independent.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from montecarlo.camera_calibration.calibrate import closed_form, pose_names, poses_of
from montecarlo.camera_calibration.model import project
from montecarlo.discrepancy.engine import Diagnosis
from montecarlo.discrepancy.problem import OUTLIER, Effect, Problem
from montecarlo.discrepancy.view import SystemView
from montecarlo.io.camera_csv import CameraData

FloatArray = NDArray[np.float64]

CANDIDATES = (
    Effect("radial_k1", ("k1",), ((-1.0, 1.0),), (1e-6,),
           "radial distortion x (1 + k1 r^2) on normalised coordinates [1]"),
    Effect("radial_k2", ("k2",), ((-2.0, 2.0),), (1e-6,),
           "radial distortion + k2 r^4 (after k1) [1]"),
    Effect("radial_k3", ("k3",), ((-5.0, 5.0),), (1e-6,),
           "radial distortion + k3 r^6 (after k2) [1]"),
    Effect("tangential", ("p1", "p2"), ((-0.05, 0.05),) * 2, (1e-7,) * 2,
           "Brown-Conrady decentering p1, p2 on normalised coordinates [1]", (1.0, 1.0)),
    Effect("skew", ("gamma",), ((-50.0, 50.0),), (1e-4,),
           "u = f x + gamma y + cx [px]"),
    Effect("aspect_ratio", ("a",), ((-0.1, 0.1),), (1e-7,), "f_y = f (1 + a) [1]"),
)
REQUIRES = {"radial_k2": "radial_k1", "radial_k3": "radial_k2"}
SEPARATING_DATA = {
    frozenset(("radial_k1", "radial_k2")): "points nearer the corners of the image",
    frozenset(("skew", "tangential")): "views with the target in more image positions",
}
"""Pair of camera candidates -> the extra data that would tell them apart."""

DISPLAY_UNITS = {
    **dict.fromkeys(("f", "cx", "cy", "gamma"), ("px", 1.0)),
    **dict.fromkeys(("k1", "k2", "k3", "p1", "p2", "a"), ("1", 1.0)),
}


def display_unit(name: str) -> tuple[str, float]:
    """Unit of a parameter in reports: pixels, dimensionless, rad for rotations, m for
    translations."""
    if name in DISPLAY_UNITS:
        return DISPLAY_UNITS[name]
    return ("rad", 1.0) if name.startswith("r") else ("m", 1.0)


INTRINSIC_REPORTED = ("f", "cx", "cy", "gamma", "a", "k1", "k2", "k3", "p1", "p2")
"""The parameters a calibration reports (poses are nuisance parameters)."""


def base_effect(n_views: int) -> Effect:
    names = ("f", "cx", "cy", *pose_names(n_views))
    steps = tuple(1e-3 if n in ("f", "cx", "cy") else 1e-7 for n in names)
    return Effect("pinhole", names, ((-np.inf, np.inf),) * len(names), steps,
                  "focal length, principal point [px], pose of each view [rad, m]")


def camera_problem(data: CameraData, pixel_sigma: float) -> Problem:
    """The DIA problem of these views with independent pixel noise ``pixel_sigma`` [px] per
    coordinate. The start is Zhang's closed form (focal length: its alpha)."""
    n_views = len(data.views)
    start_cf = closed_form(data.points, data.pixels, data.view, n_views)
    K = start_cf["K"]
    start = {"f": float(K[0, 0]), "cx": float(K[0, 2]), "cy": float(K[1, 2])}
    for v in range(n_views):
        for j, a in enumerate("xyz"):
            start[f"r{a}_{v + 1}"] = float(start_cf["rvec"][v, j])
            start[f"t{a}_{v + 1}"] = float(start_cf["tvec"][v, j])
    base = base_effect(n_views)
    names = (*base.parameters, *(p for c in CANDIDATES for p in c.parameters))
    observed = data.pixels

    def predict(values: Mapping[str, ArrayLike]) -> FloatArray:
        r, t = poses_of(values, n_views)
        return project(values, r, t, data.points, data.view)

    def residuals(values: Mapping[str, FloatArray]) -> FloatArray:
        arrays = [np.asarray(values.get(n, 0.0), float) for n in names]
        batch = max((a.shape[0] for a in arrays if a.ndim), default=0)
        if not batch:
            return ((observed - predict(dict(zip(names, map(float, arrays), strict=True))))
                    / pixel_sigma).ravel()
        # compute each distinct parameter vector once (snooping perturbs only the shifts)
        table = np.column_stack([np.broadcast_to(a.reshape(-1), (batch,)) for a in arrays])
        unique, inverse = np.unique(table, axis=0, return_inverse=True)
        cols = {n: unique[:, j:j + 1] for j, n in enumerate(names)}
        pred = predict(cols).reshape(unique.shape[0], -1)
        return ((observed.ravel()[None, :] - pred) / pixel_sigma)[inverse.reshape(-1)]

    # each corner's data row, 1-based (as every system's; the views file's line is one more)
    observations = tuple((f"{data.views[data.view[i]]}/{data.point_id[i]}", i + 1,
                          (2 * i, 2 * i + 1)) for i in range(data.n))
    # a view's pose moves that view's corners only
    local_rows = {}
    for v in range(n_views):
        corners = np.flatnonzero(data.view == v)
        rows = np.column_stack([2 * corners, 2 * corners + 1]).reshape(-1)
        local_rows.update({f"{q}{a}_{v + 1}": rows for q in "rt" for a in "xyz"})
    return Problem("camera", base, CANDIDATES, residuals, start, {}, observations,
                   SEPARATING_DATA, REQUIRES, local_rows=local_rows)


def view_groups(data: CameraData) -> dict[str, list[int]]:
    """Each view's label -> its corners (0-based indices of the problem's observations)."""
    return {v: np.flatnonzero(data.view == i).tolist() for i, v in enumerate(data.views)}


def raw_residuals(data: CameraData, params: Mapping[str, float]) -> FloatArray:
    """Measured minus predicted pixels (n, 2) [px]."""
    r, t = poses_of(params, len(data.views))
    return data.pixels - project(params, r, t, data.points, data.view)


def report_view(data: CameraData, pixel_sigma: float) -> SystemView:
    """Residuals against the distance from the principal point (closed form) and against the
    image position u, v."""
    K = closed_form(data.points, data.pixels, data.view, len(data.views))["K"]
    offset = data.pixels - K[:2, 2]
    radius = np.hypot(offset[:, 0], offset[:, 1])
    outward = offset / np.where(radius > 0, radius, 1.0)[:, None]

    def radial(res: FloatArray) -> FloatArray:
        """Residuals along and across the image radius [px]."""
        along = np.sum(res * outward, axis=1)
        across = res[:, 1] * outward[:, 0] - res[:, 0] * outward[:, 1]
        return np.stack([along, across], axis=1)

    axes = [("distance from the principal point [px]", radius,
             (("radial", "tangential"), radial)),
            ("image column u [px]", data.pixels[:, 0], None),
            ("image row v [px]", data.pixels[:, 1], None)]
    return SystemView("camera", display_unit, "px", 1.0, ("u", "v"),
                      lambda params: raw_residuals(data, params), axes, "", lambda fit: {},
                      None, {"pixel_sigma_px": pixel_sigma})


DISTORTION_CANDIDATES = ("radial_k1", "radial_k2", "radial_k3", "tangential")


def pixel_error(d: Diagnosis, data: CameraData, pixel_sigma: float) -> dict[str, object]:
    """The pixel error a ground study should assume after this calibration.

    - ``sigma_u``, ``sigma_v``: residual RMS of each image axis under the final model [px],
      flagged corners left out, scaled by ``sqrt(N / dof)`` (N coordinates) so that it
      estimates the noise rather than what the fit left of it;
    - ``distortion_bound``: the largest image displacement [px], over the data's points, of a
      distortion candidate not in the final model at its minimal detectable bias (what could
      remain undetected, once the final model is refitted to it: the candidate's columns
      projected orthogonal to the model's), and which candidate gives it
      (``distortion_source``).
    """
    after = d.after
    raw = raw_residuals(data, after.params)
    flagged = {t.name[len(OUTLIER):] for t in d.outliers}
    keep = np.array([oid not in flagged for oid, _, _ in d.problem.observations])
    used = raw[keep]
    scale = math.sqrt(2 * used.shape[0] / max(1, 2 * used.shape[0] - len(after.names)
                                              + 2 * len(flagged)))
    sigma_u, sigma_v = (float(np.sqrt(np.mean(used[:, k] ** 2)) * scale) for k in (0, 1))
    bound, source = 0.0, None
    final = {t.name: t for t in d.steps[-1].tests}
    for name in DISTORTION_CANDIDATES:
        t = final.get(name)
        if t is None or t.status not in ("testable", "undetectable") or not t.mdb \
                or t.projected is None:
            continue
        for j, mdb in enumerate(t.mdb.values()):
            # projected: what the final model, refitted, cannot absorb of the effect
            shift = t.projected[:, j].reshape(-1, 2) * pixel_sigma * mdb
            size = float(np.max(np.hypot(shift[:, 0], shift[:, 1])))
            if size > bound:
                bound, source = size, name
    return {"sigma_u": sigma_u, "sigma_v": sigma_v, "distortion_bound": bound,
            "distortion_source": source}


def errors_toml(error: Mapping[str, object], source: str, pixel_sigma: float,
                model: Sequence[str]) -> str:
    """The ``[errors]`` table of a ground study carrying ``error`` (:func:`pixel_error`).

    A ground study draws one pixel error per image axis from one source (``pixel_px``); the
    bounded part, uniform within +-B (variance B^2/3), is folded into the normal sigma by
    variance: ``sigma = sqrt(max(sigma_u, sigma_v)^2 + B^2/3)``. The comments keep both parts.
    """
    su, sv = float(error["sigma_u"]), float(error["sigma_v"])  # type: ignore[arg-type]
    bound = float(error["distortion_bound"])  # type: ignore[arg-type]
    sigma = math.sqrt(max(su, sv) ** 2 + bound**2 / 3.0)
    return "\n".join([
        f"# Pixel error left by the camera calibration of {source}",
        f"# (montecarlo diagnose camera, stated pixel sigma {pixel_sigma:g} px; final model: "
        f"{', '.join(model)})",
        f"# residual sigma per axis: u {su:.4f} px, v {sv:.4f} px",
        f"# remaining distortion, largest image displacement undetected at its MDB: "
        f"+-{bound:.4f} px ({error['distortion_source'] or 'none tested'}), a bounded source",
        "# one pixel source per axis in a ground study: the bound folded in by variance, "
        "sigma = sqrt(max(su, sv)^2 + B^2/3)",
        "[errors]",
        f'pixel_px = {{ dist = "normal", sigma = {sigma:.6g} }}',
        f"# pixel_distortion_bound_px = {bound:.6g}",
        ""])
