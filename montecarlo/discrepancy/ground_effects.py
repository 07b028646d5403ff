"""Ground calibration with many surveyed targets: forward model with candidate effects.

A sensor at the origin of frame b (x right, y forward, z up) observes targets whose positions were
surveyed in frame b. The base model is seed 000's: the mounting angles (psi, theta, gamma) give
``C_b^a`` (eq. 5, :func:`montecarlo.geometry.rotations.mounting_matrix`) and the ideal pinhole maps
the direction in frame a to pixels through its tangent plane
(:func:`montecarlo.geometry.camera.pixels_from_direction`, eqs. 1-4). Each candidate effect extends
the model and is absent when its parameters are zero. The prediction of one observation:

1. target position ``r`` (surveyed, frame b): ``target_height_scale`` ``z <- z (1 + s_h)``;
   ``target_lateral_bias``, ``target_range_bias``, ``target_height_bias``
   ``r <- r + (b_x, b_y, b_z)``;
2. ``lever_arm``: the projection centre sits at ``l = (l_x, l_y, l_z)`` in frame b, the ray is
   ``r - l``; earth curvature and refraction, part of the base model
   (:func:`apparent_height_shift`), lower its end by ``(1 - k) d^2 / (2 R)`` with ``d`` its
   horizontal length, ``R = 6371 km`` and ``k = k_std + dk``, ``k_std`` the standard
   coefficient (0.13 unless stated) and ``dk`` the ``refraction`` candidate (refraction
   differs from standard);
3. mounting angles ``(psi, theta, gamma) + w (t - t_mean)`` (``drift``, linear in ``t_s``)
   ``+`` the shift of the observation's session (``session_shift``; the first session is the
   reference); ``u = C_b^a (r - l)``;
4. tangent-plane coordinates ``x = u_x / u_y``, ``z = u_z / u_y``; ``radial_distortion``
   ``(x, z) <- (x, z)(1 + k1 r^2)``, ``r^2 = x^2 + z^2`` (so the radius r becomes
   ``r (1 + k1 r^2)``); ``tangential_distortion`` (Brown-Conrady, with the undistorted r)
   ``x += 2 p1 x z + p2 (r^2 + 2 x^2)``, ``z += p1 (r^2 + 2 z^2) + 2 p2 x z``;
5. pixels ``(k_x x, k_z z)`` (eqs. 1-4); ``focal_scale`` ``x (1 + s)``; ``aspect_ratio``
   ``px (1 + a/2)``, ``pz (1 - a/2)``; ``detector_rotation`` by ``rho`` in the image plane
   (counter-clockwise, px towards pz); ``principal_point`` ``+ (c_x, c_z)`` [px].

References
----------
seed 000: Ding Tao (2014), eqs. (1)-(5) (camera, mounting matrix). Curvature and refraction:
the correction ``(1 - k) d^2 / (2 R)`` of trigonometric heighting (W. Torge, J. Mueller (2012),
Geodesy, 4th ed., de Gruyter, trigonometric heighting), with Gauss's coefficient k = 0.13.
Distortion: D. C. Brown (1966), Decentering distortion of lenses.
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from montecarlo.discrepancy.problem import Effect, Problem, is_outlier
from montecarlo.discrepancy.view import SystemView
from montecarlo.errors import InputError
from montecarlo.geometry.camera import Camera, direction_from_pixels, pixels_from_direction
from montecarlo.geometry.rotations import euler_zxy_from_matrix, mounting_matrix
from montecarlo.io.ground_csv import GroundData
from montecarlo.lsq import LeastSquaresFit
from montecarlo.units import MRAD, MRAD_PER_HOUR

FloatArray = NDArray[np.float64]

EARTH_RADIUS = 6_371_000.0
"""Mean Earth radius [m]."""
STANDARD_REFRACTION = 0.13
"""Gauss's coefficient of terrestrial refraction [1]."""

DEFAULT_MOUNTING = {"psi": math.radians(30.0), "theta": math.radians(20.0),
                    "gamma": math.radians(10.0)}
"""Seed 000's simulation mounting (section 1.4) [rad]."""

BASE = Effect("mounting", ("psi", "theta", "gamma"), ((-np.inf, np.inf),) * 3, (1e-6,) * 3,
                  "mounting angles of seed 000, eq. (5) [rad]")

_CANDIDATES = (
    Effect("radial_distortion", ("k1",), ((-0.5, 0.5),), (1e-6,),
               "tangent-plane radius r -> r (1 + k1 r^2) [1]"),
    Effect("tangential_distortion", ("p1", "p2"), ((-0.05, 0.05),) * 2, (1e-7,) * 2,
               "Brown-Conrady decentering p1, p2 on tangent-plane coordinates [1]",
               (1.0, 1.0)),
    Effect("principal_point", ("c_x", "c_z"), ((-50.0, 50.0),) * 2, (1e-4,) * 2,
               "image coordinates + (c_x, c_z) [px]", (1.0, 1.0)),
    Effect("focal_scale", ("s",), ((-0.1, 0.1),), (1e-7,),
               "image coordinates x (1 + s) [1]"),
    Effect("aspect_ratio", ("a",), ((-0.05, 0.05),), (1e-7,),
               "px x (1 + a/2), pz x (1 - a/2) [1]"),
    Effect("detector_rotation", ("rho",), ((-0.1, 0.1),), (1e-6,),
               "image rotated by rho about its centre [rad]"),
    Effect("target_height_scale", ("s_h",), ((-0.05, 0.05),), (1e-7,),
               "true height = surveyed height x (1 + s_h) [1]"),
    Effect("target_range_bias", ("b_y",), ((-5.0, 5.0),), (1e-5,),
               "true y = surveyed y + b_y [m]"),
    Effect("target_lateral_bias", ("b_x",), ((-2.0, 2.0),), (1e-5,),
               "true x = surveyed x + b_x [m]"),
    Effect("target_height_bias", ("b_z",), ((-2.0, 2.0),), (1e-5,),
               "true z = surveyed z + b_z [m]"),
    Effect("lever_arm", ("l_x", "l_y", "l_z"), ((-1.0, 1.0),) * 3, (1e-5,) * 3,
               "projection centre at (l_x, l_y, l_z) in frame b [m]", (1.0, 1.0, 1.0)),
    Effect("refraction", ("dk",), ((-5.0, 5.0),), (1e-2,),
               "refraction differs from standard: k = k_std + dk, apparent z + dk d^2 / (2 R) "
               "[1]"),
    Effect("drift", ("w_psi", "w_theta", "w_gamma"), ((-1e-5, 1e-5),) * 3, (1e-10,) * 3,
               "mounting angles + w (t_s - mean t_s) [rad/s]", (1.0, 1.0, 1.0)),
)

_SECOND_STATION = ("the projection centre surveyed, or the targets seen from a second sensor "
                   "position: a lever arm is minus a common shift of all targets")
SEPARATING_DATA = {
    **{frozenset(("lever_arm", bias)): _SECOND_STATION
       for bias in ("target_range_bias", "target_lateral_bias", "target_height_bias")},
    **{frozenset((a, b)): "targets at a second range"
       for a, b in (("focal_scale", "target_range_bias"), ("focal_scale", "lever_arm"),
                    ("principal_point", "target_lateral_bias"),
                    ("principal_point", "target_height_bias"), ("principal_point", "lever_arm"),
                    ("refraction", "target_height_scale"), ("refraction", "target_height_bias"))},
    frozenset(("target_height_scale", "target_height_bias")): "targets at more than one height",
    frozenset(("radial_distortion", "focal_scale")): "targets nearer the edge of the field",
    frozenset(("drift", "session_shift")): "observations spread over each session",
}
"""Pair of ground candidates -> the extra data that would tell them apart. A shift ``b`` of a
target at range ``y`` moves its image by ``b / y``, a scale or a principal point does not
depend on range; a height scale moves a target by ``s_h z``, a height bias by ``b_z``;
refraction grows as ``d^2``; distortion as ``r^3``, a focal scale as ``r``."""

SESSION_SHIFT_BOUND = 0.05
"""Physical bound of a session's shift of each mounting angle [rad]."""

DISPLAY_UNITS = {
    **dict.fromkeys(("k1", "p1", "p2", "s", "a", "s_h", "dk"), ("1", 1.0)),
    **dict.fromkeys(("c_x", "c_z"), ("px", 1.0)),
    **dict.fromkeys(("b_x", "b_y", "b_z", "l_x", "l_y", "l_z"), ("m", 1.0)),
    **dict.fromkeys(("psi", "theta", "gamma"), ("deg", math.pi / 180.0)),
    "rho": ("mrad", MRAD),
    **dict.fromkeys(("w_psi", "w_theta", "w_gamma"), ("mrad/h", MRAD_PER_HOUR)),
}
"""Parameter -> (unit shown in reports and JSON, its size in SI/radians)."""


def display_unit(name: str) -> tuple[str, float]:
    """Unit of a parameter at the edge (session shifts are in mrad)."""
    return DISPLAY_UNITS.get(name, ("mrad", MRAD))


def shift_unit(name: str) -> tuple[str, float]:
    """Unit of small changes of a parameter (mounting angles in mrad)."""
    return ("mrad", MRAD) if name in BASE.parameters else display_unit(name)


def check_in_front(data: GroundData, camera: Camera, source: str) -> None:
    """Refuse data whose targets lie behind the sensor for the best-fitting mounting.

    Raises
    ------
    InputError
        Naming ``source``, the row (as a text editor counts, header = 1) and the columns.
    """
    start = initial_mounting(data, camera)
    C = mounting_matrix(start["psi"], start["theta"], start["gamma"])
    behind = np.flatnonzero((data.positions @ C.T)[:, 1] <= 0.0)
    if behind.size:
        raise InputError(f"{source}: row {int(behind[0]) + 2}, columns 'x_m', 'y_m', 'z_m': the "
                         "target is behind the sensor for the mounting that best fits the "
                         "measured directions (check the frame: x right, y forward, z up)")


def min_targets() -> int:
    """Fewest observations: 3 angles + the largest candidate (3) + 1 degree of freedom, over 2."""
    return math.ceil((len(BASE.parameters) + 3 + 1) / 2)


# --------------------------------------------------------------------------- forward model


def candidates_for(data: GroundData) -> tuple[tuple[Effect, ...], dict[str, str]]:
    """Candidate effects for these data and the ones unavailable (with the reason)."""
    sessions = data.sessions()
    names = tuple(f"{a}_shift_{s}" for s in sessions[1:] for a in ("psi", "theta", "gamma"))
    shift = Effect("session_shift", names,
                       ((-SESSION_SHIFT_BOUND, SESSION_SHIFT_BOUND),) * len(names),
                       (1e-6,) * len(names),
                       "mounting angles shifted in each session after the first [rad]",
                       (1.0,) * len(names))
    unavailable = {}
    if data.t is None:
        unavailable["drift"] = "no t_s column"
    if len(sessions) < 2:
        unavailable["session_shift"] = "fewer than two sessions"
    return (*_CANDIDATES, shift), unavailable


def apparent_height_shift(horizontal: ArrayLike, k: ArrayLike) -> FloatArray:
    """Shift of a target's apparent height by earth curvature and refraction [m].

    Surveyed heights are above the level surface through the sensor. At horizontal distance
    ``L`` [m] that surface has dropped ``L^2 / (2 R)`` below the sensor's horizontal plane
    (``R`` = 6.371e6 m, ``L << R``). Refraction bends the line of sight into an arc of radius
    ``R / k``, concave to the ground, which raises the target's apparent position by
    ``k L^2 / (2 R)``. The apparent height is therefore shifted by

        ``dz = -(1 - k) L^2 / (2 R)``  [m],

    an apparent-elevation change of ``-(1 - k) L / (2 R)`` [rad] (0.068 mrad at 1 km with
    k = 0.13).

    Parameters
    ----------
    horizontal : horizontal distance L [m].
    k : coefficient of refraction [1] (Gauss's standard value 0.13).

    References
    ----------
    W. Torge, J. Mueller (2012), Geodesy, 4th ed., trigonometric heighting: the height
    difference ``S sin(e) + (1 - k) S^2 / (2 R)`` from slope distance S and elevation e.
    """
    L = np.asarray(horizontal, float)
    return -(1.0 - np.asarray(k, float)) * L**2 / (2.0 * EARTH_RADIUS)


def predict_pixels(params: Mapping[str, ArrayLike], data: GroundData, camera: Camera,
                   refraction: float = STANDARD_REFRACTION) -> FloatArray:
    """Predicted image coordinates of every observation, shape (..., n, 2) [px].

    Parameters
    ----------
    params : parameter name -> value (SI units, radians); floats, or arrays of shape (k, 1)
        for k parameter vectors at once. Missing parameters are zero (effect absent).
    data : positions, times and sessions of the observations (pixels unused).
    camera : field of view and pixel counts.
    refraction : standard coefficient of refraction k_std [1] of the base model; the
        ``refraction`` candidate's ``dk`` adds to it.

    References
    ----------
    seed 000, eq. (5) (mounting matrix) and eqs. (1)-(4) (tangent-plane projection);
    :func:`apparent_height_shift` (curvature and refraction); the candidate effects as in the
    module docstring.
    """
    def p(name: str) -> FloatArray:
        return np.asarray(params.get(name, 0.0), float)

    x, y, z = (data.positions[:, j] for j in range(3))
    z = z * (1.0 + p("s_h"))
    x, y, z = x + p("b_x"), y + p("b_y"), z + p("b_z")
    x, y, z = x - p("l_x"), y - p("l_y"), z - p("l_z")
    z = z + apparent_height_shift(np.hypot(x, y), refraction + p("dk"))
    ray = np.stack(np.broadcast_arrays(x, y, z), axis=-1)

    angles = [p(a) for a in ("psi", "theta", "gamma")]
    if data.t is not None:
        dt = data.t - data.t.mean()
        angles = [v + p(w) * dt for v, w in zip(angles, ("w_psi", "w_theta", "w_gamma"),
                                                strict=True)]
    sessions = data.sessions()
    if len(sessions) > 1:
        label = np.asarray(data.session)
        for s in sessions[1:]:
            mask = (label == s).astype(float)
            angles = [v + p(f"{a}_shift_{s}") * mask
                      for v, a in zip(angles, ("psi", "theta", "gamma"), strict=True)]
    C = mounting_matrix(*angles)  # seed 000, eq. (5)
    u = np.matmul(C, ray[..., None])[..., 0]  # seed 000, eq. (6)

    tx, tz = u[..., 0] / u[..., 1], u[..., 2] / u[..., 1]
    r2 = tx**2 + tz**2
    radial = 1.0 + p("k1") * r2
    p1, p2 = p("p1"), p("p2")
    dx = 2.0 * p1 * tx * tz + p2 * (r2 + 2.0 * tx**2)
    dz = p1 * (r2 + 2.0 * tz**2) + 2.0 * p2 * tx * tz
    tangent = np.stack([tx * radial + dx, np.ones_like(tx), tz * radial + dz], axis=-1)
    px, pz = pixels_from_direction(tangent, camera)  # seed 000, eqs. (1)-(4)
    scale, a = 1.0 + p("s"), p("a")
    px, pz = px * scale * (1.0 + a / 2.0), pz * scale * (1.0 - a / 2.0)
    cr, sr = np.cos(p("rho")), np.sin(p("rho"))
    px, pz = px * cr - pz * sr, px * sr + pz * cr
    return np.stack([px + p("c_x"), pz + p("c_z")], axis=-1)


def initial_mounting(data: GroundData, camera: Camera,
                     refraction: float = STANDARD_REFRACTION) -> dict[str, float]:
    """Mounting angles that best rotate the surveyed directions onto the measured ones.

    Wahba's problem (``scipy.spatial.transform.Rotation.align_vectors``): the rotation taking
    unit apparent target directions in b (surveyed positions lowered by
    :func:`apparent_height_shift`) to the unit directions of the measured pixels in a is
    ``C_b^a``; its Z-X-Y angles start the least-squares fit.
    """
    seen = data.positions.copy()
    seen[:, 2] += apparent_height_shift(np.hypot(seen[:, 0], seen[:, 1]), refraction)
    b = seen / np.linalg.norm(seen, axis=1, keepdims=True)
    a = direction_from_pixels(data.pixels[:, 0], data.pixels[:, 1], camera)
    with warnings.catch_warnings():  # degenerate directions: the fit reports them (FitError)
        warnings.simplefilter("ignore", UserWarning)
        rotation, _ = Rotation.align_vectors(a, b)
    psi, theta, gamma = euler_zxy_from_matrix(rotation.as_matrix())
    return {"psi": float(psi), "theta": float(theta), "gamma": float(gamma)}


def pixel_covariance(data: GroundData, camera: Camera, mounting: Mapping[str, float],
                     pixel_sigma: float, survey_sigma: float) -> FloatArray:
    """Covariance of each observation's (px, pz), shape (n, 2, 2) [px^2].

    ``pixel_sigma^2 I + survey_sigma^2 J J'`` with ``J = d(px, pz)/d r`` the pinhole's
    derivative with respect to the target position (isotropic survey error of each target).
    """
    C = mounting_matrix(mounting["psi"], mounting["theta"], mounting["gamma"])
    u = data.positions @ C.T
    k = np.array([camera.k_x, camera.k_z])
    J = np.empty((data.n, 2, 3))
    for i, row in enumerate((0, 2)):
        J[:, i, :] = k[i] * (C[row][None, :] * u[:, 1:2] - u[:, row:row + 1] * C[1][None, :]) \
            / u[:, 1:2] ** 2
    return pixel_sigma**2 * np.eye(2) + survey_sigma**2 * J @ np.swapaxes(J, 1, 2)


def ground_problem(data: GroundData, camera: Camera, pixel_sigma: float,
                   survey_sigma: float = 0.0, refraction: float = STANDARD_REFRACTION
                   ) -> Problem:
    """The DIA problem of ground observations with stated pixel and survey noise.

    The base model includes earth curvature and refraction with the standard coefficient
    ``refraction`` [1] (:func:`apparent_height_shift`). Residuals are whitened per target
    with the covariance of :func:`pixel_covariance` at the starting mounting angles
    (:func:`initial_mounting`).
    """
    start = initial_mounting(data, camera, refraction)
    cov = pixel_covariance(data, camera, start, pixel_sigma, survey_sigma)
    whiten = np.linalg.inv(np.linalg.cholesky(cov))
    observed = data.pixels

    def residuals(values: Mapping[str, FloatArray]) -> FloatArray:
        diff = observed - predict_pixels(values, data, camera, refraction)
        white = np.einsum("nij,...nj->...ni", whiten, diff)
        return white.reshape(*white.shape[:-2], -1)

    candidates, unavailable = candidates_for(data)
    return Problem("ground", BASE, candidates, residuals, start, unavailable,
                   observations(data), SEPARATING_DATA)


def whitened_noise_components(data: GroundData, camera: Camera, pixel_sigma: float,
                               survey_sigma: float,
                               refraction: float = STANDARD_REFRACTION) -> list[FloatArray]:
    """The pixel and survey noise's covariances (per unit variance) in the coordinates of
    :func:`ground_problem`'s whitened residuals at ``pixel_sigma``, ``survey_sigma``:
    ``W I W'`` and ``W J J' W'``, each (2n, 2n) block-diagonal (variance components)."""
    start = initial_mounting(data, camera, refraction)
    whiten = np.linalg.inv(np.linalg.cholesky(
        pixel_covariance(data, camera, start, pixel_sigma, survey_sigma)))
    out = []
    for unit in (pixel_covariance(data, camera, start, 1.0, 0.0),
                 pixel_covariance(data, camera, start, 0.0, 1.0)):
        blocks = whiten @ unit @ np.swapaxes(whiten, 1, 2)
        Q = np.zeros((2 * data.n, 2 * data.n))
        for i in range(data.n):
            Q[2 * i:2 * i + 2, 2 * i:2 * i + 2] = blocks[i]
        out.append(Q)
    return out


def observations(data: GroundData) -> tuple[tuple[str, int, tuple[int, ...]], ...]:
    """Each target's image point as one observation: its name (with the session, if any, or
    the row where a name repeats), its data row (1-based) and its two whitened residuals."""
    names = [t if not data.session else f"{t}@{s}"
             for t, s in zip(data.targets, data.session or [""] * data.n, strict=True)]
    repeated = {n for n in names if names.count(n) > 1}
    return tuple((f"{n} (row {i + 1})" if n in repeated else n, i + 1, (2 * i, 2 * i + 1))
                 for i, n in enumerate(names))


def raw_residuals(data: GroundData, camera: Camera, params: Mapping[str, float],
                  refraction: float = STANDARD_REFRACTION) -> FloatArray:
    """Measured minus predicted image coordinates, shape (n, 2) [px]."""
    return data.pixels - predict_pixels(params, data, camera, refraction)


# --------------------------------------------------------------------------- layouts, simulation


def field_layout(camera: Camera, mounting: Mapping[str, float], ranges: Sequence[float] = (
                 50.0, 100.0), grid: tuple[int, int] = (6, 6), spread: float = 0.8,
                 duration: float = 3600.0, sessions: int = 1,
                 rng: int | np.random.Generator | None = 0) -> GroundData:
    """Targets spread over the field of view at several ranges (pixels zero).

    A ``grid`` of directions covering ``spread`` of the field in tangent-plane coordinates; the
    ranges (distance along the line of sight) alternate over the grid like a checkerboard, so
    each range covers the whole field. Positions in frame b through the true mounting. Times: a
    random visiting order over ``duration`` seconds; ``sessions`` > 1 repeats the whole layout
    in each session (times continue).
    """
    rng = np.random.default_rng(rng)
    C = mounting_matrix(mounting["psi"], mounting["theta"], mounting["gamma"])
    gx = spread * np.tan(camera.fov_yaw / 2.0) * np.linspace(-1.0, 1.0, grid[0])
    gz = spread * np.tan(camera.fov_pitch / 2.0) * np.linspace(-1.0, 1.0, grid[1])
    tx, tz = (v.ravel() for v in np.meshgrid(gx, gz, indexing="ij"))
    ij = np.add.outer(np.arange(grid[0]), np.arange(grid[1])).ravel()
    rng_of = np.asarray(ranges, float)[ij % len(ranges)]
    u = np.stack([tx, np.ones_like(tx), tz], axis=-1)
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    positions = (u * rng_of[:, None]) @ C  # r_b = C^T r_a
    n = positions.shape[0]
    names = [f"T{i + 1:02d}" for i in range(n)]
    all_t, all_pos, all_names, all_sessions = [], [], [], []
    for s in range(sessions):
        order = rng.permutation(n)
        t = np.empty(n)
        t[order] = (np.arange(n) + 0.5) * duration / n + s * duration
        all_t.append(t)
        all_pos.append(positions)
        all_names += names
        all_sessions += [f"S{s + 1}"] * n
    return GroundData(tuple(all_names), np.concatenate(all_pos), np.zeros((n * sessions, 2)),
                      np.concatenate(all_t), tuple(all_sessions) if sessions > 1 else None)


def simulate(layout: GroundData, camera: Camera, truth: Mapping[str, float], pixel_sigma: float,
             survey_sigma: float, rng: int | np.random.Generator | None = None,
             refraction: float = STANDARD_REFRACTION) -> GroundData:
    """Measured-like data: pixels of the true positions under ``truth`` plus noise.

    The file gets surveyed positions = true positions + ``N(0, survey_sigma^2)`` per axis;
    the pixels are ``predict_pixels(truth)`` of the true positions + ``N(0, pixel_sigma^2)``,
    with earth curvature and refraction ``refraction`` + the truth's ``dk``.
    """
    rng = np.random.default_rng(rng)
    pixels = predict_pixels(truth, layout, camera, refraction)
    pixels = pixels + pixel_sigma * rng.standard_normal(pixels.shape)
    surveyed = layout.positions + survey_sigma * rng.standard_normal(layout.positions.shape)
    return GroundData(layout.targets, surveyed, pixels, layout.t, layout.session)


def exact_problem(layout: GroundData, camera: Camera, truth: Mapping[str, float],
                  pixel_sigma: float, survey_sigma: float,
                  refraction: float = STANDARD_REFRACTION) -> Problem:
    """The problem of noise-free data generated by ``truth`` (for design MDBs)."""
    exact = GroundData(layout.targets, layout.positions,
                       predict_pixels(truth, layout, camera, refraction), layout.t,
                       layout.session)
    return ground_problem(exact, camera, pixel_sigma, survey_sigma, refraction)


TRUTH_KEYS = tuple(p for c in _CANDIDATES for p in c.parameters)
"""Parameters of every candidate effect (session shifts aside)."""


def report_view(data: GroundData, camera: Camera, pixel_sigma: float, survey_sigma: float,
                refraction: float = STANDARD_REFRACTION) -> SystemView:
    """How reports show a ground diagnosis: units, residual axes, Monte Carlo study params."""
    tangent = data.pixels / np.array([camera.k_x, camera.k_z])
    radius = np.hypot(tangent[:, 0], tangent[:, 1])
    outward = tangent / np.where(radius > 0, radius, 1.0)[:, None]

    def radial(res: FloatArray) -> FloatArray:
        """Residuals along and across the image radius [px]."""
        along = np.sum(res * outward, axis=1)
        across = res[:, 1] * outward[:, 0] - res[:, 0] * outward[:, 1]
        return np.stack([along, across], axis=1)

    axes = [("image radius (tangent plane) [1]", radius, (("radial", "tangential"), radial)),
            ("range [m]", np.linalg.norm(data.positions, axis=1), None),
            ("target height z [m]", data.positions[:, 2], None)]
    if data.t is not None:
        axes.append(("time t_s [s]", data.t, None))
    layout = json.dumps(data.layout())
    shifts = [q for c in candidates_for(data)[0] if c.name == "session_shift"
              for q in c.parameters]

    def study_params(fit: LeastSquaresFit) -> dict[str, object]:
        values = fit.params
        return {"fov_yaw": float(camera.fov_yaw), "fov_pitch": float(camera.fov_pitch),
                "n_x": int(camera.n_x), "n_z": int(camera.n_z), "pixel_sigma": pixel_sigma,
                "survey_sigma": survey_sigma, "layout": layout, "refraction_k": refraction,
                **{k: float(values.get(k, 0.0)) for k in ("psi", "theta", "gamma",
                                                          *TRUTH_KEYS)},
                "extra_truth": json.dumps({q: values[q] for q in shifts if q in values}),
                "fit_effects": ",".join(e for e in fit.effects[1:] if not is_outlier(e)),
                "diagnose": 0}

    return SystemView("ground", display_unit, "px", 1.0, ("px", "pz"),
                      lambda params: raw_residuals(data, camera, params, refraction), axes,
                      "discrepancy_ground", study_params, shift_unit,
                      {"earth_curvature": True, "refraction_k": refraction})
