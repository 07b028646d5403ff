"""Ground calibration with many surveyed targets: forward model with candidate effects (issue 5).

A sensor at the origin of frame b (x right, y forward, z up) observes targets whose positions
were surveyed in frame b. The base model is seed 000's: the mounting angles (psi, theta, gamma)
give ``C_b^a`` (eq. 5, :func:`montecarlo.rotations.mounting_matrix`) and the ideal pinhole maps
the direction in frame a to pixels through its tangent plane
(:func:`montecarlo.camera.pixels_from_direction`, eqs. 1-4). Each candidate effect extends the
model and is absent when its parameters are zero. The prediction of one observation:

1. target position ``r`` (surveyed, frame b): ``target_height_scale`` ``z <- z (1 + s_h)``;
   ``target_lateral_bias``, ``target_range_bias``, ``target_height_bias``
   ``r <- r + (b_x, b_y, b_z)``; ``earth_curvature`` ``z <- z - c d^2 / (2 R)`` and
   ``refraction`` ``z <- z + k d^2 / (2 R)`` with ``d`` the horizontal distance and
   ``R = 6371 km`` (physical values ``c = 1``, ``k = 0.13``);
2. ``lever_arm``: the projection centre sits at ``l = (l_x, l_y, l_z)`` in frame b, the ray is
   ``r - l``;
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
seed 000: Ding Tao (2014), eqs. (1)-(5) (camera, mounting matrix). Refraction and curvature:
the standard geodetic correction ``(1 - k) d^2 / (2 R)`` with Gauss's coefficient k = 0.13.
Distortion: D. C. Brown (1966), Decentering distortion of lenses.
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from montecarlo.discrepancy import engine as dia
from montecarlo.geometry.camera import Camera, direction_from_pixels, pixels_from_direction
from montecarlo.io.table import read_table
from montecarlo.discrepancy.view import SystemView
from montecarlo.errors import InputError
from montecarlo.systems.params import ParamSystem
from montecarlo.geometry.rotations import euler_zxy_from_matrix, mounting_matrix
from montecarlo.engine.system import Metric

FloatArray = NDArray[np.float64]

EARTH_RADIUS = 6_371_000.0
"""Mean Earth radius [m]."""
STANDARD_REFRACTION = 0.13
"""Gauss's coefficient of terrestrial refraction [1]."""
MRAD = 1e-3
MRAD_PER_H = 1e-3 / 3600.0

BASE = dia.Effect("mounting", ("psi", "theta", "gamma"), ((-np.inf, np.inf),) * 3, (1e-6,) * 3,
                  "mounting angles of seed 000, eq. (5) [rad]")

_CANDIDATES = (
    dia.Effect("radial_distortion", ("k1",), ((-0.5, 0.5),), (1e-6,),
               "tangent-plane radius r -> r (1 + k1 r^2) [1]"),
    dia.Effect("tangential_distortion", ("p1", "p2"), ((-0.05, 0.05),) * 2, (1e-7,) * 2,
               "Brown-Conrady decentering p1, p2 on tangent-plane coordinates [1]",
               (1.0, 1.0)),
    dia.Effect("principal_point", ("c_x", "c_z"), ((-50.0, 50.0),) * 2, (1e-4,) * 2,
               "image coordinates + (c_x, c_z) [px]", (1.0, 1.0)),
    dia.Effect("focal_scale", ("s",), ((-0.1, 0.1),), (1e-7,),
               "image coordinates x (1 + s) [1]"),
    dia.Effect("aspect_ratio", ("a",), ((-0.05, 0.05),), (1e-7,),
               "px x (1 + a/2), pz x (1 - a/2) [1]"),
    dia.Effect("detector_rotation", ("rho",), ((-0.1, 0.1),), (1e-6,),
               "image rotated by rho about its centre [rad]"),
    dia.Effect("target_height_scale", ("s_h",), ((-0.05, 0.05),), (1e-7,),
               "true height = surveyed height x (1 + s_h) [1]"),
    dia.Effect("target_range_bias", ("b_y",), ((-5.0, 5.0),), (1e-5,),
               "true y = surveyed y + b_y [m]"),
    dia.Effect("target_lateral_bias", ("b_x",), ((-2.0, 2.0),), (1e-5,),
               "true x = surveyed x + b_x [m]"),
    dia.Effect("target_height_bias", ("b_z",), ((-2.0, 2.0),), (1e-5,),
               "true z = surveyed z + b_z [m]"),
    dia.Effect("lever_arm", ("l_x", "l_y", "l_z"), ((-1.0, 1.0),) * 3, (1e-5,) * 3,
               "projection centre at (l_x, l_y, l_z) in frame b [m]", (1.0, 1.0, 1.0)),
    dia.Effect("refraction", ("k",), ((-5.0, 5.0),), (1e-2,),
               "apparent z + k d^2 / (2 R), standard k = 0.13 [1]"),
    dia.Effect("earth_curvature", ("c",), ((0.0, 2.0),), (1e-2,),
               "apparent z - c d^2 / (2 R), physical c = 1 [1]"),
    dia.Effect("drift", ("w_psi", "w_theta", "w_gamma"), ((-1e-5, 1e-5),) * 3, (1e-10,) * 3,
               "mounting angles + w (t_s - mean t_s) [rad/s]", (1.0, 1.0, 1.0)),
)
CANDIDATE_NAMES = (*(c.name for c in _CANDIDATES), "session_shift")
"""Ground candidate effects (``session_shift`` exists when the data have several sessions)."""

SESSION_SHIFT_BOUND = 0.05
"""Physical bound of a session's shift of each mounting angle [rad]."""

DISPLAY_UNITS = {
    **dict.fromkeys(("k1", "p1", "p2", "s", "a", "s_h", "k", "c"), ("1", 1.0)),
    **dict.fromkeys(("c_x", "c_z"), ("px", 1.0)),
    **dict.fromkeys(("b_x", "b_y", "b_z", "l_x", "l_y", "l_z"), ("m", 1.0)),
    **dict.fromkeys(("psi", "theta", "gamma"), ("deg", math.pi / 180.0)),
    "rho": ("mrad", MRAD),
    **dict.fromkeys(("w_psi", "w_theta", "w_gamma"), ("mrad/h", MRAD_PER_H)),
}
"""Parameter -> (unit shown in reports and JSON, its size in SI/radians)."""


def display_unit(name: str) -> tuple[str, float]:
    """Unit of a parameter at the edge (session shifts are in mrad)."""
    return DISPLAY_UNITS.get(name, ("mrad", MRAD))


def shift_unit(name: str) -> tuple[str, float]:
    """Unit of small changes of a parameter (mounting angles in mrad)."""
    return ("mrad", MRAD) if name in BASE.parameters else display_unit(name)


# --------------------------------------------------------------------------- data


@dataclass(frozen=True)
class GroundData:
    """Observations of surveyed targets.

    Attributes
    ----------
    targets : target names, one per observation.
    positions : (n, 3) surveyed positions in frame b [m].
    pixels : (n, 2) measured ``(px, pz)`` from the image centre [px] (eqs. 1, 4 signs).
    t : (n,) observation times [s], or None.
    session : session label of each observation, or None.
    """

    targets: tuple[str, ...]
    positions: FloatArray
    pixels: FloatArray
    t: FloatArray | None = None
    session: tuple[str, ...] | None = None

    @property
    def n(self) -> int:
        return self.positions.shape[0]

    def sessions(self) -> tuple[str, ...]:
        """Session labels in order of first appearance (``("",)`` without sessions)."""
        return tuple(dict.fromkeys(self.session)) if self.session else ("",)

    def layout(self) -> dict[str, object]:
        """Everything but the measured pixels, as JSON-able lists (for studies)."""
        out: dict[str, object] = {"target": list(self.targets),
                                  "x_m": self.positions[:, 0].tolist(),
                                  "y_m": self.positions[:, 1].tolist(),
                                  "z_m": self.positions[:, 2].tolist()}
        if self.t is not None:
            out["t_s"] = self.t.tolist()
        if self.session is not None:
            out["session"] = list(self.session)
        return out


def layout_from_json(text: str) -> GroundData:
    """A :class:`GroundData` with zero pixels from :meth:`GroundData.layout` as JSON."""
    raw = json.loads(text)
    positions = np.column_stack([raw["x_m"], raw["y_m"], raw["z_m"]]).astype(float)
    n = positions.shape[0]
    return GroundData(tuple(raw.get("target", [f"T{i + 1}" for i in range(n)])), positions,
                      np.zeros((n, 2)),
                      None if raw.get("t_s") is None else np.asarray(raw["t_s"], float),
                      None if raw.get("session") is None else tuple(map(str, raw["session"])))


CSV_COLUMNS = ("target", "x_m", "y_m", "z_m", "px", "pz")
"""Required columns of a ground data CSV; ``t_s`` and ``session`` are optional."""


def min_targets() -> int:
    """Fewest observations: 3 angles + the largest candidate (3) + 1 degree of freedom, over 2."""
    return math.ceil((len(BASE.parameters) + 3 + 1) / 2)


def read_ground_csv(path: str | Path, camera: Camera) -> GroundData:
    """Read and check a ground data CSV (columns :data:`CSV_COLUMNS`, optional t_s, session).

    Raises
    ------
    InputError
        Missing column, non-numeric or NaN value, too few rows, or an image coordinate outside
        the detector; one line naming file, row and column.
    """
    table = read_table(path, ["x_m", "y_m", "z_m", "px", "pz"], optional_numeric=["t_s"],
                       text=["target"])
    if len(table) < min_targets():
        raise InputError(f"{path}: {len(table)} data rows, at least {min_targets()} needed (3 "
                         "mounting angles + up to 3 parameters of an effect + 1 degree of "
                         "freedom, 2 image coordinates per row)")
    session = None
    if "session" in table.columns:
        values = table["session"].str.strip()
        for i, v in enumerate(values):
            if v == "":
                raise InputError(f"{path}: row {i + 2}, column 'session': empty value")
        session = tuple(values)
    for column, half in (("px", camera.n_x / 2.0), ("pz", camera.n_z / 2.0)):
        values = table[column].to_numpy(float)
        bad = np.flatnonzero(np.abs(values) > half)
        if bad.size:
            i = int(bad[0])
            raise InputError(f"{path}: row {i + 2}, column '{column}': {float(values[i])!r} "
                             f"is outside the detector (|{column}| <= {half:g} px)")
    positions = table[["x_m", "y_m", "z_m"]].to_numpy(float)
    zero = np.flatnonzero(np.linalg.norm(positions, axis=1) == 0.0)
    if zero.size:
        raise InputError(f"{path}: row {int(zero[0]) + 2}, column 'x_m': target at the sensor "
                         "origin (0, 0, 0) has no direction")
    t = table["t_s"].to_numpy(float) if "t_s" in table.columns else None
    data = GroundData(tuple(table["target"]), positions, table[["px", "pz"]].to_numpy(float), t,
                      session)
    start = initial_mounting(data, camera)
    C = mounting_matrix(start["psi"], start["theta"], start["gamma"])
    behind = np.flatnonzero((positions @ C.T)[:, 1] <= 0.0)
    if behind.size:
        raise InputError(f"{path}: row {int(behind[0]) + 2}, columns 'x_m', 'y_m', 'z_m': the "
                         "target is behind the sensor for the mounting that best fits the "
                         "measured directions (check the frame: x right, y forward, z up)")
    return data


def write_ground_csv(path: str | Path, data: GroundData) -> None:
    """Write observations as a ground data CSV (temporary name, then rename)."""
    from montecarlo.io.files import atomic_write_bytes

    cols = ["target", "x_m", "y_m", "z_m", "px", "pz"]
    if data.t is not None:
        cols.append("t_s")
    if data.session is not None:
        cols.append("session")
    lines = [",".join(cols)]
    for i in range(data.n):
        row = [data.targets[i], *(f"{v:.4f}" for v in data.positions[i]),
               *(f"{v:.6f}" for v in data.pixels[i])]
        if data.t is not None:
            row.append(f"{data.t[i]:.1f}")
        if data.session is not None:
            row.append(data.session[i])
        lines.append(",".join(row))
    atomic_write_bytes(Path(path), ("\n".join(lines) + "\n").encode())


# --------------------------------------------------------------------------- forward model


def candidates_for(data: GroundData) -> tuple[tuple[dia.Effect, ...], dict[str, str]]:
    """Candidate effects for these data and the ones unavailable (with the reason)."""
    sessions = data.sessions()
    names = tuple(f"{a}_shift_{s}" for s in sessions[1:] for a in ("psi", "theta", "gamma"))
    shift = dia.Effect("session_shift", names,
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


def predict_pixels(params: Mapping[str, ArrayLike], data: GroundData, camera: Camera
                   ) -> FloatArray:
    """Predicted image coordinates of every observation, shape (..., n, 2) [px].

    Parameters
    ----------
    params : parameter name -> value (SI units, radians); floats, or arrays of shape (k, 1)
        for k parameter vectors at once. Missing parameters are zero (effect absent).
    data : positions, times and sessions of the observations (pixels unused).
    camera : field of view and pixel counts.

    References
    ----------
    seed 000, eq. (5) (mounting matrix) and eqs. (1)-(4) (tangent-plane projection); the
    candidate effects as in the module docstring.
    """
    def p(name: str) -> FloatArray:
        return np.asarray(params.get(name, 0.0), float)

    x, y, z = (data.positions[:, j] for j in range(3))
    z = z * (1.0 + p("s_h"))
    x, y, z = x + p("b_x"), y + p("b_y"), z + p("b_z")
    d2 = x**2 + y**2
    z = z + (p("k") - p("c")) * d2 / (2.0 * EARTH_RADIUS)
    ray = np.stack(np.broadcast_arrays(x - p("l_x"), y - p("l_y"), z - p("l_z")), axis=-1)

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


def initial_mounting(data: GroundData, camera: Camera) -> dict[str, float]:
    """Mounting angles that best rotate the surveyed directions onto the measured ones.

    Wahba's problem (``scipy.spatial.transform.Rotation.align_vectors``): the rotation taking
    unit target directions in b to the unit directions of the measured pixels in a is
    ``C_b^a``; its Z-X-Y angles start the least-squares fit.
    """
    b = data.positions / np.linalg.norm(data.positions, axis=1, keepdims=True)
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
                   survey_sigma: float = 0.0) -> dia.Problem:
    """The DIA problem of ground observations with stated pixel and survey noise.

    Residuals are whitened per target with the covariance of :func:`pixel_covariance` at the
    starting mounting angles (:func:`initial_mounting`).
    """
    start = initial_mounting(data, camera)
    cov = pixel_covariance(data, camera, start, pixel_sigma, survey_sigma)
    whiten = np.linalg.inv(np.linalg.cholesky(cov))
    observed = data.pixels

    def residuals(values: Mapping[str, FloatArray]) -> FloatArray:
        diff = observed - predict_pixels(values, data, camera)
        white = np.einsum("nij,...nj->...ni", whiten, diff)
        return white.reshape(*white.shape[:-2], -1)

    candidates, unavailable = candidates_for(data)
    return dia.Problem("ground", BASE, candidates, residuals, start, unavailable)


def raw_residuals(data: GroundData, camera: Camera, params: Mapping[str, float]) -> FloatArray:
    """Measured minus predicted image coordinates, shape (n, 2) [px]."""
    return data.pixels - predict_pixels(params, data, camera)


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
             survey_sigma: float, rng: int | np.random.Generator | None = None) -> GroundData:
    """Measured-like data: pixels of the true positions under ``truth`` plus noise.

    The file gets surveyed positions = true positions + ``N(0, survey_sigma^2)`` per axis;
    the pixels are ``predict_pixels(truth)`` of the true positions + ``N(0, pixel_sigma^2)``.
    """
    rng = np.random.default_rng(rng)
    pixels = predict_pixels(truth, layout, camera)
    pixels = pixels + pixel_sigma * rng.standard_normal(pixels.shape)
    surveyed = layout.positions + survey_sigma * rng.standard_normal(layout.positions.shape)
    return GroundData(layout.targets, surveyed, pixels, layout.t, layout.session)


def exact_problem(layout: GroundData, camera: Camera, truth: Mapping[str, float],
                  pixel_sigma: float, survey_sigma: float) -> dia.Problem:
    """The problem of noise-free data generated by ``truth`` (for design MDBs)."""
    exact = GroundData(layout.targets, layout.positions, predict_pixels(truth, layout, camera),
                       layout.t, layout.session)
    return ground_problem(exact, camera, pixel_sigma, survey_sigma)


# --------------------------------------------------------------------------- study hook

DEFAULT_MOUNTING = {"psi": math.radians(30.0), "theta": math.radians(20.0),
                    "gamma": math.radians(10.0)}
"""Seed 000's simulation mounting (section 1.4)."""

_TRUTH_KEYS = tuple(p for c in _CANDIDATES for p in c.parameters)

DEFAULT_PARAMS: dict[str, float | int | str] = {
    "fov_yaw": math.radians(90.0), "fov_pitch": math.radians(90.0), "n_x": 512, "n_z": 512,
    "pixel_sigma": 0.3, "survey_sigma": 0.01, "layout": "",
    **DEFAULT_MOUNTING,
    **dict.fromkeys(_TRUTH_KEYS, 0.0),
    "c": 1.0, "k": STANDARD_REFRACTION,
    "extra_truth": "",
    "fit_effects": "", "diagnose": 0, "expected": "", "inject_mdb": 0.0, "alpha": dia.ALPHA,
}
"""Defaults of :func:`run_trials` (SI units, radians); see its docstring."""

METRICS = dia.TRIAL_METRICS
"""Per-trial metrics of :func:`run_trials` (``named_watched``: refraction or earth_curvature
named)."""


def default_layout(camera: Camera, mounting: Mapping[str, float]) -> GroundData:
    """The acceptance layout: 6 x 6 targets over 80 % of the field at 50 and 100 m, one hour."""
    return field_layout(camera, mounting, (50.0, 100.0), (6, 6), 0.8, 3600.0, 1, rng=2024)


def run_trials(params: Mapping[str, float | int | str], rng: np.random.Generator, n: int
               ) -> dict[str, FloatArray]:
    """Monte Carlo of the ground diagnosis: simulate data sets, fit or diagnose each.

    Parameters
    ----------
    params : mapping; missing keys take :data:`DEFAULT_PARAMS`.
        ``fov_yaw``, ``fov_pitch`` [rad], ``n_x``, ``n_z`` [px]: camera (seed 000's 90 deg,
        512 px). ``pixel_sigma`` [px] (0.3), ``survey_sigma`` [m] (0.01): noise.
        ``layout`` [JSON text]: targets as :meth:`GroundData.layout`; "" for
        :func:`default_layout` at the true mounting. ``psi``, ``theta``, ``gamma`` [rad]: true
        mounting (30, 20, 10 deg). Every candidate parameter (``k1``, ``p1``, ``p2``, ``c_x``
        [px], ``c_z`` [px], ``s``, ``a``, ``rho`` [rad], ``s_h``, ``b_x``, ``b_y``, ``b_z``,
        ``l_x``, ``l_y``, ``l_z`` [m], ``k``, ``c``, ``w_psi``, ``w_theta``, ``w_gamma``
        [rad/s]): its true value (0, except the physical ``c`` = 1 and ``k`` = 0.13).
        ``extra_truth`` [JSON text]: further true parameters, e.g. session shifts [rad].
        ``fit_effects`` [text]: comma-separated effects fitted for ``chi2`` .. ``rms`` ("":
        the base model). ``diagnose`` [0/1]: also run the whole DIA diagnosis. ``expected``
        [text]: the effect injected, for scoring. ``inject_mdb`` [1]: if > 0, ``expected`` is
        injected at this multiple of its design MDB along its default direction (replacing its
        values above). ``alpha`` [1]: significance (0.01).
    rng : numpy Generator, the only source of randomness.
    n : number of simulated data sets.

    Returns
    -------
    dict of metric -> ndarray (n,), float64 (NaN where not applicable):
        ``chi2``, ``chi2_red``, ``p_value`` [1], ``rms`` [px]: residual statistic of the
        ``fit_effects`` model (rms over both coordinates of all observations).
        With ``diagnose``: ``detected``, ``named_any`` [0/1]; ``n_named`` [count];
        ``named_expected`` [0/1] (the expected effect named), ``named_expected_or_group``
        [0/1] (named or in a named effect's confounded group); ``named_watched`` [0/1]
        (refraction or earth_curvature named); ``expected_within_2sigma`` [1] (fraction of
        its parameters within 2 sigma of the truth, when it is named);
        ``expected_all_within_2sigma`` [0/1]; ``chi2_red_after`` [1] and
        ``chi2_red_after_in_band`` [0/1] (inside the central 99 % band of chi2(dof)/dof).
    """
    unknown = set(params) - set(DEFAULT_PARAMS)
    if unknown:
        raise ValueError(f"unknown parameter(s) {sorted(unknown)}")
    p = {**DEFAULT_PARAMS, **params}
    camera = Camera(float(p["fov_yaw"]), float(p["fov_pitch"]), float(p["n_x"]),
                    float(p["n_z"]))
    truth = {k: float(p[k]) for k in ("psi", "theta", "gamma", *_TRUTH_KEYS)}
    if p["extra_truth"]:
        truth.update({k: float(v) for k, v in json.loads(str(p["extra_truth"])).items()})
    layout = (default_layout(camera, truth) if not p["layout"]
              else layout_from_json(str(p["layout"])))
    sigma, survey = float(p["pixel_sigma"]), float(p["survey_sigma"])
    alpha = float(p["alpha"])
    expected = str(p["expected"])
    effects = tuple(e for e in str(p["fit_effects"]).split(",") if e.strip())
    effects = tuple(e.strip() for e in effects)
    if float(p["inject_mdb"]) > 0:
        if not expected:
            raise ValueError("inject_mdb needs an expected effect")
        truth = dia.inject_at_mdb(
            lambda tr: exact_problem(layout, camera, tr, sigma, survey), truth, expected,
            float(p["inject_mdb"]), alpha)
    return dia.score_trials(
        lambda g: simulate(layout, camera, truth, sigma, survey, g),
        lambda data: ground_problem(data, camera, sigma, survey),
        lambda data, fit: float(np.sqrt(np.mean(raw_residuals(data, camera, fit.params) ** 2))),
        truth, effects, int(p["diagnose"]), expected, alpha, rng, n,
        watched=("refraction", "earth_curvature"))


def report_view(data: GroundData, camera: Camera, pixel_sigma: float, survey_sigma: float
                ) -> SystemView:
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

    def study_params(fit: dia.ModelFit) -> dict[str, object]:
        values = fit.params
        return {"fov_yaw": float(camera.fov_yaw), "fov_pitch": float(camera.fov_pitch),
                "n_x": int(camera.n_x), "n_z": int(camera.n_z), "pixel_sigma": pixel_sigma,
                "survey_sigma": survey_sigma, "layout": layout,
                **{k: float(values.get(k, 0.0)) for k in ("psi", "theta", "gamma",
                                                          *_TRUTH_KEYS)},
                "extra_truth": json.dumps({q: values[q] for q in shifts if q in values}),
                "fit_effects": ",".join(fit.effects[1:]), "diagnose": 0}

    return SystemView("ground", display_unit, "px", 1.0, ("px", "pz"),
                      lambda params: raw_residuals(data, camera, params), axes, STUDY_SYSTEM,
                      study_params, shift_unit)


STUDY_SYSTEM = ParamSystem(
    name="discrepancy_ground",
    module="montecarlo.discrepancy.ground_effects",
    units={"fov_yaw": "deg", "fov_pitch": "deg", "pixel_sigma": "px", "survey_sigma": "m",
           "psi": "deg", "theta": "deg", "gamma": "deg", "c_x": "px", "c_z": "px",
           "rho": "mrad", "b_x": "m", "b_y": "m", "b_z": "m", "l_x": "m", "l_y": "m",
           "l_z": "m"},
    metrics_=(
        Metric("chi2", "χ² of the fitted model", "1", 1.0),
        Metric("chi2_red", "reduced χ² of the fitted model", "1", 1.0),
        Metric("p_value", "global test p-value", "1", 1.0),
        Metric("rms", "residual RMS", "px", 1.0),
        *(Metric(m, m.replace("_", " "), "1", 1.0) for m in METRICS[4:]),
    ),
    default_block_size=32,
)
"""Study system ``discrepancy_ground``: residual statistics and DIA rates (issue 5)."""
