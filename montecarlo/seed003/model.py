"""Autocollimator–INS axis calibration of seed 003: 3-D model, fit, Figs. 3-6, study hook.

An autocollimator is fixed to a strapdown INS; its optical axis should be parallel to the INS
roll axis ("the INS axis") but is off by an azimuth angle gamma and a pitch angle lambda. Mirrors
whose normals a theodolite has measured are autocollimated in turn; the INS attitude reported at
each mirror, compared with the theodolite angles, gives gamma and lambda (seed 003, section 2).

Frames and signs
----------------
``n``  INS navigation frame: x east (right), y north (forward), z up.
``t``  theodolite/mirror frame: levelled, so z up; azimuth zero arbitrary.
``b``  INS body frame: y along the INS roll axis, x right, z up (seed 000's axes).

Angles at the edges are those the instruments read: azimuth and heading clockwise seen from
above, elevation and pitch positive up, roll positive right side down. A direction of azimuth
``az`` and elevation ``el`` is ``direction(az, el) = [sin az cos el, cos az cos el, sin el]``.

* INS attitude: active matrix ``C_b^n`` (b coordinates to n coordinates)
  ``= R_z(-psi) R_x(theta) R_y(phi) = Rotation.from_euler("ZXY", [-psi, theta, phi]).as_matrix()``
  for heading psi, pitch theta, roll phi: seed 000's Z-X-Y sequence with yaw = -heading.
* Optical axis in b: ``u = direction(gamma, lambda)``; gamma > 0 turns it to the right of the INS
  axis, lambda > 0 up.
* Mirror: the theodolite autocollimates on it; its line of sight ``d = direction(az_t, el_t)``
  (in t) is the mirror normal, pointing into the mirror. The autocollimator, autocollimated on the
  same mirror, looks along the same line, so ``C_b^n u = C_t^n d``.
* ``C_t^n = attitude_matrix(frame_heading, frame_tilt_x, frame_tilt_y)``: the theodolite
  azimuth zero is at INS heading ``frame_heading``; the tilts (theodolite levelling error against
  the INS level) are zero unless fitted.

Roll assumption: autocollimation fixes the optical axis, not the rotation about it. The INS roll
at each mirror is taken from the reported roll when there is one; otherwise the mount is assumed
to keep the INS roll at zero (a two-axis azimuth/elevation mount with a horizontal trunnion). A
roll phi turns the offsets about the INS axis, so an unreported roll of 0.5 deg with offsets of
0.1 deg biases the fit by about 3 arc-seconds.

References
----------
seed 003: "Characterization calibration method of strapdown inertial navigation axis in
photoelectric target calibration", section 2 (Figs. 2-6) and section 3.1 (mirror fixture).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from montecarlo.io.table import read_table
from montecarlo.errors import InputError
from montecarlo.io.files import atomic_write_bytes
from montecarlo.geometry.rotations import euler_zxy_from_matrix, mounting_matrix

FloatArray = NDArray[np.float64]

ARCSEC = math.pi / (180.0 * 3600.0)
"""One arc-second [rad]."""

SETS = ("azimuth", "pitch")
"""The two mirror families of seed 003, section 3.1 (7 + 7 mirrors in the paper)."""

EFFECTS: dict[str, tuple[str, ...]] = {
    "frame_heading": ("frame_heading",),
    "axis_misalignment": ("axis_az", "axis_el"),
    "frame_misalignment": ("frame_tilt_x", "frame_tilt_y"),
}
"""Named effects of the forward model and their parameters [rad].

``frame_heading``: INS heading of the theodolite's azimuth zero (always needed: the theodolite
zero is arbitrary). ``axis_misalignment``: the offsets gamma (``axis_az``) and lambda
(``axis_el``) of the optical axis from the INS axis, the quantity seed 003 calibrates.
``frame_misalignment``: tilts of the theodolite frame against the INS level, about its x and
y axes (zero in the paper, which levels both).
"""

BASE_EFFECTS = ("frame_heading", "axis_misalignment")
"""Effects fitted by default: the paper's method with level references."""

CSV_COLUMNS = ("mirror", "set", "theodolite_az_deg", "theodolite_el_deg", "ins_az_deg",
               "ins_el_deg")
"""Columns of the measured-data CSV (issue 5); ``ins_roll_deg`` is optional."""


# --------------------------------------------------------------------------- geometry


def direction(az: ArrayLike, el: ArrayLike) -> FloatArray:
    """Unit vector of azimuth ``az`` (clockwise from y) and elevation ``el``, shape (..., 3).

    Parameters
    ----------
    az, el : array_like [rad]
    """
    az, el = np.broadcast_arrays(np.asarray(az, float), np.asarray(el, float))
    return np.stack([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)], axis=-1)


def azimuth_elevation(v: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Azimuth (clockwise from y, in (-pi, pi]) and elevation [rad] of vectors (..., 3)."""
    v = np.asarray(v, float)
    return np.arctan2(v[..., 0], v[..., 1]), np.arctan2(v[..., 2], np.hypot(v[..., 0], v[..., 1]))


def attitude_matrix(heading: ArrayLike, pitch: ArrayLike, roll: ArrayLike) -> FloatArray:
    """Active attitude matrix ``C_b^n = R_z(-heading) R_x(pitch) R_y(roll)``, shape (..., 3, 3).

    Equals ``Rotation.from_euler("ZXY", [-heading, pitch, roll]).as_matrix()`` and the transpose
    of seed 000's eq. (5) with yaw = -heading. Its second column is
    ``direction(heading, pitch)``, the INS axis in frame n.

    Parameters
    ----------
    heading, pitch, roll : array_like [rad]
        Heading clockwise from north, pitch up, roll right side down.
    """
    C = mounting_matrix(-np.asarray(heading, float), pitch, roll)  # seed 000, eq. (5), passive
    return np.swapaxes(C, -1, -2)


def attitude_angles(C: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Heading, pitch, roll [rad] of an active attitude matrix; inverse of :func:`attitude_matrix`.
    """
    yaw, pitch, roll = euler_zxy_from_matrix(np.swapaxes(np.asarray(C, float), -1, -2))
    return -yaw, pitch, roll


def wrap(angle: ArrayLike) -> FloatArray:
    """Angle wrapped to [-pi, pi) [rad]."""
    return (np.asarray(angle, float) + np.pi) % (2.0 * np.pi) - np.pi


# --------------------------------------------------------------------------- parameters


def parameter_names(effects: Iterable[str]) -> tuple[str, ...]:
    """Flat parameter names of a list of effects, in :data:`EFFECTS` order per effect."""
    names: list[str] = []
    for effect in effects:
        if effect not in EFFECTS:
            raise ValueError(f"unknown effect {effect!r}; known: {', '.join(EFFECTS)}")
        names.extend(EFFECTS[effect])
    return tuple(names)


_ALL_PARAMETERS = frozenset(parameter_names(EFFECTS))


def _getter(params: Mapping[str, ArrayLike]):
    unknown = set(params) - _ALL_PARAMETERS
    if unknown:
        raise ValueError(f"unknown parameter(s) {sorted(unknown)}; "
                         f"known: {sorted(_ALL_PARAMETERS)}")
    return lambda name: np.asarray(params.get(name, 0.0), float)


# --------------------------------------------------------------------------- forward model


def mirror_normal_in_nav(params: Mapping[str, ArrayLike], theodolite_az: ArrayLike,
                         theodolite_el: ArrayLike) -> FloatArray:
    """Mirror normal (theodolite line of sight) in the INS navigation frame, shape (..., 3).

    ``w = C_t^n direction(az_t, el_t)`` with ``C_t^n`` from ``frame_heading``, ``frame_tilt_x``
    and ``frame_tilt_y`` (see the module docstring); parameters broadcast against the angles.

    References
    ----------
    seed 003, section 2 (Fig. 2: mirror normals measured by the autocollimating theodolite).
    """
    p = _getter(params)
    C_tn = attitude_matrix(p("frame_heading"), p("frame_tilt_x"), p("frame_tilt_y"))
    d = direction(theodolite_az, theodolite_el)
    return np.matmul(C_tn, d[..., None])[..., 0]


def predict_readings(params: Mapping[str, ArrayLike], theodolite_az: ArrayLike,
                     theodolite_el: ArrayLike, roll: ArrayLike = 0.0
                     ) -> tuple[FloatArray, FloatArray]:
    """INS heading and pitch reported when the autocollimator is autocollimated on a mirror.

    Solves ``R_z(-psi) R_x(theta) R_y(phi) u = w`` for heading psi and pitch theta, where
    ``u = direction(axis_az, axis_el)`` is the optical axis in frame b, ``w`` the mirror normal
    in frame n (:func:`mirror_normal_in_nav`) and phi the INS roll at that mirror. With
    ``u' = R_y(phi) u = r [., cos delta, sin delta]``: ``theta = arcsin(w_z / r) - delta``, and
    psi is the azimuth of w minus that of ``R_x(theta) u'``. Pure and vectorised: parameters
    (scalars, or arrays shaped to broadcast against the angles) missing from ``params`` are zero.

    Parameters
    ----------
    params : mapping of parameter name (see :data:`EFFECTS`) to value [rad]
    theodolite_az, theodolite_el : array_like [rad]
        Mirror normals as read by the theodolite.
    roll : array_like [rad]
        INS roll at each mirror (reported, or 0 for a level mount).

    Returns
    -------
    heading, pitch : ndarray [rad]
        Heading in [-pi, pi); NaN where no pitch autocollimates (``|w_z| > r``).

    References
    ----------
    seed 003, section 2 (the INS attitude recorded at each autocollimation).
    """
    p = _getter(params)
    w = mirror_normal_in_nav(params, theodolite_az, theodolite_el)
    u = direction(p("axis_az"), p("axis_el"))
    roll = np.asarray(roll, float)
    ux = u[..., 0] * np.cos(roll) + u[..., 2] * np.sin(roll)  # u' = R_y(roll) u
    uy = u[..., 1]
    uz = -u[..., 0] * np.sin(roll) + u[..., 2] * np.cos(roll)
    r = np.hypot(uy, uz)
    with np.errstate(invalid="ignore"):
        pitch = np.arcsin(w[..., 2] / r) - np.arctan2(uz, uy)
    vx = ux
    vy = uy * np.cos(pitch) - uz * np.sin(pitch)  # horizontal part of R_x(pitch) u'
    heading = wrap(np.arctan2(w[..., 0], w[..., 1]) - np.arctan2(vx, vy))
    return heading, pitch


def correct_readings(ins_az: ArrayLike, ins_el: ArrayLike, ins_roll: ArrayLike,
                     axis_az: ArrayLike, axis_el: ArrayLike
                     ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Attitude of the optical-axis frame ``C_b^n R_z(-gamma) R_x(lambda)`` from INS readings.

    The "system correction" of seed 003, section 2: the INS axis turned into the frame whose y
    axis is the optical axis. Its heading and pitch are those of ``C_b^n u``.

    Returns
    -------
    heading, pitch, roll : ndarray [rad]
    """
    C = attitude_matrix(ins_az, ins_el, ins_roll) @ attitude_matrix(axis_az, axis_el, 0.0)
    return attitude_angles(C)


# --------------------------------------------------------------------------- layout, simulation


def paper_layout(n_azimuth: int = 5, n_pitch: int = 5, azimuth_span: float = math.pi / 2,
                 pitch_span: float = math.pi / 3
                 ) -> tuple[FloatArray, FloatArray, NDArray[np.str_]]:
    """Mirror normals of a seed-003-like fixture (theodolite frame).

    Azimuth set: ``n_azimuth`` horizontal mirrors at azimuths ``linspace(0, azimuth_span)``
    (the reference mirror at 0; with the default span the last one is the roll reference at
    90 deg on the right, section 3.1). Pitch set: ``n_pitch`` mirrors at azimuth 0 and elevations
    ``pitch_span/n_pitch ... pitch_span`` equally spaced. The paper gives the families (7 + 7
    mirrors and a roll mirror) but not the angles ("set as the test needs"); its Table 1 (10
    mirrors) is withheld, so the default 5 + 5 with 90 deg and 60 deg spans is our assumption.

    Returns
    -------
    az, el : ndarray, shape (n_azimuth + n_pitch,) [rad]
    sets : ndarray of str, ``"azimuth"`` or ``"pitch"``
    """
    if n_azimuth < 0 or n_pitch < 0:
        raise ValueError("mirror counts must be >= 0")
    az = np.concatenate([np.linspace(0.0, azimuth_span, n_azimuth), np.zeros(n_pitch)])
    el = np.concatenate([np.zeros(n_azimuth),
                         pitch_span * np.arange(1, n_pitch + 1) / max(n_pitch, 1)])
    sets = np.array(["azimuth"] * n_azimuth + ["pitch"] * n_pitch)
    return az, el, sets


@dataclass(frozen=True)
class Noise:
    """Standard deviations of the simulated readings [rad].

    Attributes
    ----------
    theodolite : error of each theodolite azimuth and elevation reading (T3: 2 arc-seconds).
    ins_heading, ins_pitch, ins_roll : random error of each INS reading.
    mount_roll : spread of the true INS roll at the mirrors (0: level two-axis mount).
    """

    theodolite: float = 2.0 * ARCSEC
    ins_heading: float = 2.0 * ARCSEC
    ins_pitch: float = 2.0 * ARCSEC
    ins_roll: float = 2.0 * ARCSEC
    mount_roll: float = 0.0

    def residual_sigma(self) -> tuple[float, float]:
        """Standard deviation of heading and pitch residuals, ``hypot(INS, theodolite)`` [rad].

        The theodolite azimuth enters the predicted heading and its elevation the predicted pitch
        with derivative 1 (to the order of the offsets, below 1e-3 for offsets below 0.1 deg).
        """
        return (math.hypot(self.ins_heading, self.theodolite),
                math.hypot(self.ins_pitch, self.theodolite))


def simulate_readings(truth: Mapping[str, float], az: ArrayLike, el: ArrayLike, noise: Noise,
                      rng: int | np.random.Generator | None = None, n: int | None = None
                      ) -> dict[str, FloatArray]:
    """Simulate theodolite and INS readings of one or ``n`` calibrations.

    The true mirror normals are ``az, el`` in the theodolite frame; the theodolite reads them
    with error; the INS, at true roll ``N(0, mount_roll)``, reports :func:`predict_readings`
    of the truth plus error.

    Parameters
    ----------
    truth : true parameter values [rad] (names of :data:`EFFECTS`, missing ones zero).
    az, el : array_like, shape (m,) [rad]
    noise : Noise
    rng : seed or Generator (the only source of randomness).
    n : number of calibrations; None for one.

    Returns
    -------
    dict with ``theodolite_az, theodolite_el, ins_az, ins_el, ins_roll`` [rad], each of shape
    (m,) or (n, m).
    """
    rng = np.random.default_rng(rng)
    az, el = np.asarray(az, float), np.asarray(el, float)
    shape = az.shape if n is None else (n, *az.shape)
    roll = noise.mount_roll * rng.standard_normal(shape)
    heading, pitch = predict_readings(truth, az, el, roll)
    out = {
        "theodolite_az": az + noise.theodolite * rng.standard_normal(shape),
        "theodolite_el": el + noise.theodolite * rng.standard_normal(shape),
        "ins_az": wrap(heading + noise.ins_heading * rng.standard_normal(shape)),
        "ins_el": pitch + noise.ins_pitch * rng.standard_normal(shape),
        "ins_roll": roll + noise.ins_roll * rng.standard_normal(shape),
    }
    return out


# --------------------------------------------------------------------------- fit


_JAC_STEP = 1e-6
"""Central-difference step for the Jacobian [rad]; truncation error ~1e-12 relative."""


_SEPARABLE = 1e-4
"""Smallest accepted ratio of singular values of the column-normalised Jacobian: below it the
weakest parameter combination has a sigma above 1e4 times the reading noise (about 8 deg for
2.8 arc-seconds), far outside the linear regime of the fit."""


class NotSeparable(ValueError):
    """The mirrors do not determine all parameters (the Jacobian is rank deficient)."""


@dataclass(frozen=True)
class Fit:
    """Least-squares solution of one calibration.

    Attributes
    ----------
    names : parameter names; ``values`` [rad] in that order.
    covariance : (p, p) [rad^2], from the Jacobian at the solution, scaled by ``sigma`` given or
        estimated (``sigma_source`` ``"given"`` or ``"a posteriori"``).
    sigma : standard deviations of heading and pitch residuals used [rad].
    residuals : (m, 2) reading minus model, heading and pitch [rad], after the fit.
    residuals_before : (m, 2) the same with the axis offsets held at zero (reference terms fitted).
    chi2, dof : sum of squared normalised residuals and its degrees of freedom.
    passes : offset increment fitted in each pass of fit -> correct -> refit [rad].
    """

    names: tuple[str, ...]
    values: FloatArray
    covariance: FloatArray
    sigma: tuple[float, float]
    sigma_source: str
    residuals: FloatArray
    residuals_before: FloatArray
    chi2: float
    dof: int
    passes: list[float] = field(default_factory=list)

    @property
    def params(self) -> dict[str, float]:
        return dict(zip(self.names, self.values.tolist(), strict=True))

    @property
    def stderr(self) -> dict[str, float]:
        return dict(zip(self.names, np.sqrt(np.diag(self.covariance)).tolist(), strict=True))

    @property
    def chi2_red(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else math.nan


def min_mirrors(n_parameters: int) -> int:
    """Fewest mirrors for ``n_parameters``: two readings each, at least one degree of freedom."""
    return (n_parameters + 2) // 2


def _solve_once(names: tuple[str, ...], theodolite_az: FloatArray, theodolite_el: FloatArray,
                ins_az: FloatArray, ins_el: FloatArray, roll: FloatArray,
                sigma: tuple[float, float] | None) -> tuple[FloatArray, FloatArray, FloatArray,
                                                            tuple[float, float], int]:
    """One nonlinear least-squares fit; returns values, covariance, residuals, sigma, dof."""
    m = ins_az.size
    dof = 2 * m - len(names)
    if dof < 1:
        raise NotSeparable(f"{m} mirrors give {2 * m} readings; {len(names)} parameters need "
                           f"at least {min_mirrors(len(names))} mirrors")
    start = dict.fromkeys(names, 0.0)
    if "frame_heading" in start:
        start["frame_heading"] = float(np.angle(np.mean(np.exp(1j * (ins_az - theodolite_az)))))
    if "axis_el" in start:
        start["axis_el"] = float(np.mean(theodolite_el - ins_el))
    x_ref = np.array([start[k] for k in names])
    scale = (1.0, 1.0) if sigma is None else sigma

    def residuals(x: FloatArray) -> FloatArray:
        """Normalised residuals; x of shape (p,) or (k, p) gives (2m,) or (k, 2m)."""
        values = x_ref + x
        heading, pitch = predict_readings(
            {k: values[..., j, None] for j, k in enumerate(names)},
            theodolite_az, theodolite_el, roll)
        return np.concatenate([wrap(ins_az - heading) / scale[0], (ins_el - pitch) / scale[1]],
                              axis=-1)

    def jacobian(x: FloatArray) -> FloatArray:
        """Central differences, all 2p perturbed parameter vectors in one vectorised call."""
        steps = _JAC_STEP * np.eye(len(names))
        r = residuals(np.concatenate([x + steps, x - steps]))
        return (r[: len(names)] - r[len(names):]).T / (2 * _JAC_STEP)

    sol = least_squares(residuals, np.zeros(len(names)), jac=jacobian, method="lm",
                        xtol=1e-15, ftol=1e-15, gtol=1e-15)
    J = sol.jac
    norms = np.linalg.norm(J, axis=0)
    _, s, vt = np.linalg.svd(J / np.where(norms > 0, norms, 1.0), full_matrices=False)
    if norms.min() == 0.0 or s[-1] < _SEPARABLE * s[0]:
        weak = [names[i] for i in np.argsort(-np.abs(vt[-1]))[:2]]
        raise NotSeparable(f"parameters {' and '.join(weak)} are not separable with these "
                           "mirrors (axis_az needs mirrors at different elevations)")
    cov = np.linalg.inv(J.T @ J)
    r = residuals(sol.x)
    if sigma is None:
        s2 = float(r @ r) / dof
        sigma = (math.sqrt(s2), math.sqrt(s2))
        cov = cov * s2
    raw = np.stack([r[:m] * scale[0], r[m:] * scale[1]], axis=-1)
    return x_ref + sol.x, cov, raw, sigma, dof


def fit(theodolite_az: ArrayLike, theodolite_el: ArrayLike, ins_az: ArrayLike, ins_el: ArrayLike,
        ins_roll: ArrayLike | None = None, *, sigma: float | tuple[float, float] | None = None,
        effects: Sequence[str] = BASE_EFFECTS, tol: float = 0.01 * ARCSEC, max_passes: int = 5
        ) -> Fit:
    """Fit the axis offsets and reference terms to one calibration's readings.

    Nonlinear least squares (``scipy.optimize.least_squares``) of heading and pitch residuals
    ``reading - predict_readings(params, theodolite angles, roll)``, iterated as seed 003
    describes: fit, correct the readings with the fitted offsets (:func:`correct_readings`), fit
    the corrected readings again, until the offset fitted to corrected readings is below ``tol``.
    The paper fits approximate relations and needs the loop; our model is exact, so the second
    pass changes the offsets only by about 1e-3 arc-seconds (corrected readings weight the
    residuals very slightly differently from raw ones). ``Fit.passes`` records each increment.

    Parameters
    ----------
    theodolite_az, theodolite_el, ins_az, ins_el : array_like, shape (m,) [rad]
    ins_roll : array_like, shape (m,) [rad], or None to assume a level mount (roll 0).
    sigma : standard deviation of each heading and pitch residual (theodolite and INS
        combined) [rad], one value or (heading, pitch); None to estimate one value from the
        residuals.
    effects : effects fitted; must contain ``axis_misalignment``.

    Returns
    -------
    Fit

    Raises
    ------
    NotSeparable
        Too few mirrors, or parameters the mirror layout cannot separate.
    """
    if "axis_misalignment" not in effects:
        raise ValueError("effects must include 'axis_misalignment'")
    names = parameter_names(effects)
    theodolite_az, theodolite_el, ins_az, ins_el = (
        np.asarray(v, float) for v in (theodolite_az, theodolite_el, ins_az, ins_el))
    roll = np.zeros_like(ins_az) if ins_roll is None else np.asarray(ins_roll, float)
    if sigma is not None:
        sigma = (float(sigma), float(sigma)) if np.ndim(sigma) == 0 else tuple(map(float, sigma))
    reference = tuple(k for k in names if k not in EFFECTS["axis_misalignment"])
    i_az, i_el = names.index("axis_az"), names.index("axis_el")

    offset = np.eye(3)  # R_z(-gamma) R_x(lambda) accumulated over the passes
    az, el, rl = ins_az, ins_el, roll
    passes: list[float] = []
    for _ in range(max_passes):
        values, cov, _, used_sigma, dof = _solve_once(names, theodolite_az, theodolite_el,
                                                      az, el, rl, sigma)
        passes.append(math.hypot(values[i_az], values[i_el]))
        offset = offset @ attitude_matrix(values[i_az], values[i_el], 0.0)
        az, el, rl = correct_readings(az, el, rl, values[i_az], values[i_el])
        if passes[-1] < tol:
            break
    values[i_az], values[i_el] = azimuth_elevation(offset[:, 1])

    params = dict(zip(names, values, strict=True))
    heading, pitch = predict_readings(params, theodolite_az, theodolite_el, roll)
    res = np.stack([wrap(ins_az - heading), ins_el - pitch], axis=-1)
    scale = np.array(used_sigma)
    before = _solve_once(reference, theodolite_az, theodolite_el, ins_az, ins_el, roll, sigma)
    return Fit(names=names, values=values, covariance=cov, sigma=used_sigma,
               sigma_source="a posteriori" if sigma is None else "given", residuals=res,
               residuals_before=before[2], chi2=float(np.sum((res / scale) ** 2)), dof=dof,
               passes=passes)


def consistency_angles(params: Mapping[str, float], theodolite_az: ArrayLike,
                       theodolite_el: ArrayLike, ins_az: ArrayLike, ins_el: ArrayLike,
                       ins_roll: ArrayLike = 0.0) -> FloatArray:
    """Angle between the (corrected) optical axis and each mirror normal, shape (m,) [rad].

    ``angle(C_b^n u, C_t^n d)`` with the INS attitude as read and ``u`` from the fitted offsets:
    the per-mirror axis consistency that seed 003's 15 arc-second claim is about.
    """
    p = _getter(params)
    w = mirror_normal_in_nav(params, theodolite_az, theodolite_el)
    u = direction(p("axis_az"), p("axis_el"))
    axis = np.matmul(attitude_matrix(ins_az, ins_el, ins_roll), u[..., None])[..., 0]
    return np.arctan2(np.linalg.norm(np.cross(axis, w), axis=-1), np.sum(axis * w, axis=-1))


# --------------------------------------------------------------------------- measured data


@dataclass(frozen=True)
class Readings:
    """One calibration as read from a CSV file (angles [rad]; ``ins_roll`` None if absent)."""

    mirror: list[str]
    sets: list[str]
    theodolite_az: FloatArray
    theodolite_el: FloatArray
    ins_az: FloatArray
    ins_el: FloatArray
    ins_roll: FloatArray | None


def read_readings(path: str | Path, effects: Sequence[str] = BASE_EFFECTS) -> Readings:
    """Read and check a calibration CSV (columns :data:`CSV_COLUMNS`, optional ``ins_roll_deg``).

    Raises
    ------
    InputError
        Missing column, non-numeric or NaN value, unknown ``set``, or fewer mirrors than the
        parameters of ``effects`` need; one line naming file, row and column.
    """
    numeric = [c for c in CSV_COLUMNS if c.endswith("_deg")]
    table = read_table(path, numeric, optional_numeric=["ins_roll_deg"], text=["mirror", "set"],
                       choices={"set": SETS})
    need = min_mirrors(len(parameter_names(effects)))
    if len(table) < need:
        raise InputError(f"{path}: {len(table)} data rows, at least {need} needed for "
                         f"{len(parameter_names(effects))} parameters")
    rad = {c: np.radians(table[c].to_numpy(float)) for c in numeric}
    roll = np.radians(table["ins_roll_deg"].to_numpy(float)) if "ins_roll_deg" in table else None
    return Readings(table["mirror"].tolist(), table["set"].tolist(), rad["theodolite_az_deg"],
                    rad["theodolite_el_deg"], rad["ins_az_deg"], rad["ins_el_deg"], roll)


def write_readings(path: str | Path, mirror: Sequence[str], sets: Sequence[str],
                   data: Mapping[str, ArrayLike], with_roll: bool = False) -> None:
    """Write one calibration (arrays of shape (m,) [rad], keys as :func:`simulate_readings`).

    Degrees with 9 decimals (3.6e-6 arc-seconds); written to a temporary name, then renamed.
    """
    path = Path(path)
    cols = [("theodolite_az_deg", "theodolite_az"), ("theodolite_el_deg", "theodolite_el"),
            ("ins_az_deg", "ins_az"), ("ins_el_deg", "ins_el")]
    if with_roll:
        cols.append(("ins_roll_deg", "ins_roll"))
    values = [np.degrees(np.asarray(data[key], float)) for _, key in cols]
    lines = [",".join(["mirror", "set", *(c for c, _ in cols)])]
    for i, (name, kind) in enumerate(zip(mirror, sets, strict=True)):
        lines.append(",".join([name, kind, *(f"{v[i]:.9f}" for v in values)]))
    atomic_write_bytes(path, ("\n".join(lines) + "\n").encode())


# --------------------------------------------------------------------------- Figs. 3-6


def pair_deviation(kind: str, angle: ArrayLike, axis_az: float = 0.0, axis_el: float = 0.0,
                   view: str = "body") -> tuple[FloatArray, FloatArray]:
    """Deviations (delta_alpha, delta_beta) of the INS attitude change for a mirror pair.

    Mirror 1 at azimuth 0, elevation 0; mirror 2 at azimuth ``angle`` (``kind="horizontal"``,
    mirror change: azimuth alpha, pitch 0) or elevation ``angle`` (``"vertical"``: azimuth 0,
    pitch beta). The INS autocollimates both on a level mount (roll 0), reference frames
    aligned. Deviation = INS attitude change - mirror attitude change.

    ``view="body"``: the INS attitude change is the rotation ``C_1^T C_2`` between the two INS
    attitudes, resolved in the INS frame at mirror 1, as heading and pitch (Z-X-Y): this
    reproduces the paper's figures. ``view="readings"``: differences of the reported heading
    and pitch.

    Returns
    -------
    delta_alpha, delta_beta : ndarray [rad]

    References
    ----------
    seed 003, section 2, Figs. 3-4 (horizontal pair) and 5-6 (vertical pair).
    """
    angle = np.asarray(angle, float)
    zero = np.zeros_like(angle)
    if kind == "horizontal":
        az2, el2, change = angle, zero, (angle, zero)
    elif kind == "vertical":
        az2, el2, change = zero, angle, (zero, angle)
    else:
        raise ValueError(f"kind must be 'horizontal' or 'vertical', not {kind!r}")
    params = {"axis_az": axis_az, "axis_el": axis_el}
    h1, p1 = predict_readings(params, zero, zero)
    h2, p2 = predict_readings(params, az2, el2)
    if view == "body":
        rel = np.swapaxes(attitude_matrix(h1, p1, 0.0), -1, -2) @ attitude_matrix(h2, p2, 0.0)
        dh, dp, _ = attitude_angles(rel)
    elif view == "readings":
        dh, dp = h2 - h1, p2 - p1
    else:
        raise ValueError(f"view must be 'body' or 'readings', not {view!r}")
    return wrap(dh - change[0]), dp - change[1]


FIGURES = {
    "fig3": ("horizontal", "axis_az", "Fig. 3: horizontal pair, azimuth offset γ"),
    "fig4": ("horizontal", "axis_el", "Fig. 4: horizontal pair, pitch offset λ"),
    "fig5": ("vertical", "axis_az", "Fig. 5: vertical pair, azimuth offset γ"),
    "fig6": ("vertical", "axis_el", "Fig. 6: vertical pair, pitch offset λ"),
}
"""Figs. 3-6 of seed 003: mirror pair and which offset is non-zero."""

FIGURE_OFFSETS_DEG = (0.02, 0.05, 0.1)


def plot_pair_figures(outdir: str | Path) -> list[Path]:
    """Write Figs. 3-6 as PNG files (``fig3.png`` ... ``fig6.png``) into ``outdir``.

    Solid: attitude change in the INS frame (``view="body"``); dotted: difference of readings.
    """
    from matplotlib.figure import Figure

    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, (kind, offset, title) in FIGURES.items():
        top = 180.0 if kind == "horizontal" else 80.0
        deg = np.linspace(0.0, top, 321)
        fig = Figure(figsize=(9, 3.8), layout="constrained")
        axes = fig.subplots(1, 2)
        largest = [0.0, 0.0]
        for k, value in enumerate(FIGURE_OFFSETS_DEG):
            color = f"C{k}"
            for view, style in (("body", "-"), ("readings", ":")):
                dev = pair_deviation(kind, np.radians(deg), view=view,
                                     **{offset: math.radians(value)})
                label = f"{value}° ({'INS frame' if view == 'body' else 'readings'})"
                for j in (0, 1):
                    axes[j].plot(deg, dev[j] / ARCSEC, style, color=color, label=label)
                    largest[j] = max(largest[j], float(np.max(np.abs(dev[j]))) / ARCSEC)
        symbol = "α" if kind == "horizontal" else "β"
        for j, what in enumerate(("Δα (azimuth)", "Δβ (pitch)")):
            axes[j].set_xlabel(f"mirror angle {symbol} [deg]")
            axes[j].set_ylabel(f"{what} [arc-seconds]")
            axes[j].grid(alpha=0.3)
            if largest[j] < 1e-6:
                axes[j].set_ylim(-1.0, 1.0)
                axes[j].set_title(f"zero (largest {largest[j]:.0e}″)", fontsize=9)
        axes[0].legend(fontsize=7)
        fig.suptitle(f"seed 003, {title}")
        path = outdir / f"{name}.png"
        fig.savefig(path, dpi=110)
        written.append(path)
    return written


def paper_statements(offset: float = math.radians(0.1)) -> list[dict[str, object]]:
    """Each statement of seed 003, section 2, evaluated with the model (offset ``offset`` [rad]).

    Returns
    -------
    list of dict with ``statement``, ``quantity``, ``model`` (value in units of the offset
    unless said otherwise) and ``holds`` (bool), in the order of the text.
    """
    a = np.radians(np.linspace(0.0, 180.0, 721))
    b = np.radians(np.linspace(0.0, 85.0, 341))
    out = []

    def add(statement, quantity, value, holds):
        out.append({"statement": statement, "quantity": quantity, "model": float(value),
                    "holds": bool(holds)})

    h_g = np.abs(pair_deviation("horizontal", a, axis_az=offset))
    add("horizontal pair, azimuth offset: INS change almost equals the mirror change",
        "max |Δα|, |Δβ| over α in [0, 180°] / γ", np.max(h_g) / offset, np.max(h_g) < 0.05 * offset)
    da, db = pair_deviation("horizontal", a, axis_el=offset)
    add("horizontal pair, pitch offset: clear difference, especially in pitch",
        "max |Δβ| / λ (max |Δα| / λ in the next row)", np.max(np.abs(db)) / offset,
        np.max(np.abs(db)) > 10 * np.max(np.abs(da)))
    add("(same)", "max |Δα| / λ", np.max(np.abs(da)) / offset, True)
    _, db180 = pair_deviation("horizontal", math.pi, axis_el=offset)
    add("at α = 180°, Δβ is almost twice λ", "Δβ(180°) / λ", db180 / offset,
        abs(abs(db180) / offset - 2.0) < 0.05)
    _, db180r = pair_deviation("horizontal", math.pi, axis_el=offset, view="readings")
    add("(same, with differences of the reported pitch)", "Δβ(180°) / λ, readings",
        db180r / offset, abs(abs(db180r) / offset - 2.0) < 0.05)
    v_l = np.abs(pair_deviation("vertical", b, axis_el=offset))
    add("vertical pair, pitch offset: INS change almost equals the mirror change",
        "max |Δα|, |Δβ| over β in [0, 85°] / λ", np.max(v_l) / offset, np.max(v_l) < 0.05 * offset)
    da, db = pair_deviation("vertical", b, axis_az=offset)
    add("vertical pair, azimuth offset: clear difference, especially in azimuth",
        "max |Δα| / γ over β in [0, 85°]", np.max(np.abs(da)) / offset,
        np.max(np.abs(da)) > 10 * np.max(np.abs(db)))
    da60, db60 = pair_deviation("vertical", math.radians(60.0), axis_az=offset)
    add("at β = 60°, Δβ is almost equal to γ", "Δβ(60°) / γ", db60 / offset,
        abs(abs(db60) / offset - 1.0) < 0.05)
    add("(the same read as Δα)", "Δα(60°) / γ", da60 / offset, abs(abs(da60) / offset - 1.0) < 0.05)
    return out


# --------------------------------------------------------------------------- study hook

DEFAULT_PARAMS: dict[str, float | int] = {
    "axis_az": math.radians(0.05),
    "axis_el": math.radians(0.05),
    "frame_heading": math.radians(30.0),
    "frame_tilt_x": 0.0,
    "frame_tilt_y": 0.0,
    "n_azimuth": 5,
    "n_pitch": 5,
    "azimuth_span": math.radians(90.0),
    "pitch_span": math.radians(60.0),
    "theodolite_sigma": 2.0 * ARCSEC,
    "ins_heading_sigma": 2.0 * ARCSEC,
    "ins_pitch_sigma": 2.0 * ARCSEC,
    "ins_roll_sigma": 2.0 * ARCSEC,
    "mount_roll_sigma": 0.0,
    "use_roll": 1,
    "fit_frame_tilt": 0,
}
"""Defaults of :func:`run_trials` (SI units, radians)."""

METRICS = ("axis_az_error", "axis_el_error", "axis_az_sigma", "axis_el_sigma",
           "axis_az_within_2sigma", "axis_el_within_2sigma", "axis_error_angle",
           "frame_heading_error", "residual_rms_before", "residual_rms_after",
           "residual_rms_ratio", "chi2_red", "consistency_max_after")
"""Names of the per-trial metrics returned by :func:`run_trials`."""


def run_trials(params: Mapping[str, float | int | str], rng: np.random.Generator, n: int
               ) -> dict[str, FloatArray]:
    """Monte Carlo trials of the seed 003 calibration for the study runner.

    Each trial simulates one calibration (:func:`simulate_readings`) on :func:`paper_layout`
    and fits it (:func:`fit`) with the known residual sigma (:meth:`Noise.residual_sigma`).

    Parameters
    ----------
    params : mapping; missing keys take :data:`DEFAULT_PARAMS`.
        ``axis_az``, ``axis_el`` [rad]: true offsets gamma, lambda (default 0.05 deg each).
        ``frame_heading`` [rad]: INS heading of the theodolite azimuth zero (30 deg).
        ``frame_tilt_x``, ``frame_tilt_y`` [rad]: true tilt of the theodolite frame (0).
        ``n_azimuth``, ``n_pitch`` [count]: mirrors per family (5, 5).
        ``azimuth_span``, ``pitch_span`` [rad]: spread of each family (90 deg, 60 deg).
        ``theodolite_sigma`` [rad]: error of each theodolite reading (2 arc-seconds).
        ``ins_heading_sigma``, ``ins_pitch_sigma``, ``ins_roll_sigma`` [rad]: INS reading
        errors (2 arc-seconds each).
        ``mount_roll_sigma`` [rad]: spread of the true INS roll at the mirrors (0, level mount).
        ``use_roll`` [0/1]: fit with the reported roll (1) or assume roll 0 (0).
        ``fit_frame_tilt`` [0/1]: also fit ``frame_tilt_x``, ``frame_tilt_y``.
    rng : numpy Generator, the only source of randomness.
    n : number of trials.

    Returns
    -------
    dict of metric name -> ndarray, shape (n,), float64, NaN for a trial whose fit failed:
        ``axis_az_error``, ``axis_el_error`` [rad]: fitted minus true gamma, lambda.
        ``axis_az_sigma``, ``axis_el_sigma`` [rad]: their 1-sigma from the fit covariance.
        ``axis_az_within_2sigma``, ``axis_el_within_2sigma`` [0/1]: |error| <= 2 sigma.
        ``axis_error_angle`` [rad]: angle between the fitted and the true optical axis.
        ``frame_heading_error`` [rad]: fitted minus true frame heading.
        ``residual_rms_before``, ``residual_rms_after`` [rad]: RMS of the 2m heading and
        pitch residuals without the offsets (reference terms fitted) and after the full fit.
        ``residual_rms_ratio`` [1]: ``residual_rms_after`` / injected residual noise
        ``sqrt((sigma_h^2 + sigma_p^2) / 2)``; its expectation is about ``sqrt(dof / 2m)``.
        ``chi2_red`` [1]: chi-square per degree of freedom with the injected sigma.
        ``consistency_max_after`` [rad]: largest :func:`consistency_angles` over the mirrors.
    """
    unknown = set(params) - set(DEFAULT_PARAMS)
    if unknown:
        raise ValueError(f"unknown parameter(s) {sorted(unknown)}; known: {sorted(DEFAULT_PARAMS)}")
    p = {**DEFAULT_PARAMS, **params}
    az, el, _ = paper_layout(int(p["n_azimuth"]), int(p["n_pitch"]), float(p["azimuth_span"]),
                             float(p["pitch_span"]))
    truth = {k: float(p[k]) for k in parameter_names(EFFECTS)}
    noise = Noise(float(p["theodolite_sigma"]), float(p["ins_heading_sigma"]),
                  float(p["ins_pitch_sigma"]), float(p["ins_roll_sigma"]),
                  float(p["mount_roll_sigma"]))
    sim = simulate_readings(truth, az, el, noise, rng, n)
    effects = BASE_EFFECTS + (("frame_misalignment",) if int(p["fit_frame_tilt"]) else ())
    sigma = noise.residual_sigma()
    known_sigma = sigma if min(sigma) > 0 else None
    injected = math.sqrt((sigma[0] ** 2 + sigma[1] ** 2) / 2)
    u_true = direction(truth["axis_az"], truth["axis_el"])

    out = {k: np.full(n, np.nan) for k in METRICS}
    for i in range(n):
        roll = sim["ins_roll"][i] if int(p["use_roll"]) else None
        try:
            f = fit(sim["theodolite_az"][i], sim["theodolite_el"][i], sim["ins_az"][i],
                    sim["ins_el"][i], roll, sigma=known_sigma, effects=effects)
        except NotSeparable:
            continue
        got, se = f.params, f.stderr
        for k in ("axis_az", "axis_el"):
            out[f"{k}_error"][i] = got[k] - truth[k]
            out[f"{k}_sigma"][i] = se[k]
            out[f"{k}_within_2sigma"][i] = float(abs(got[k] - truth[k]) <= 2 * se[k])
        u = direction(got["axis_az"], got["axis_el"])
        out["axis_error_angle"][i] = np.arctan2(np.linalg.norm(np.cross(u, u_true)), u @ u_true)
        out["frame_heading_error"][i] = wrap(got["frame_heading"] - truth["frame_heading"])
        out["residual_rms_before"][i] = np.sqrt(np.mean(f.residuals_before ** 2))
        out["residual_rms_after"][i] = np.sqrt(np.mean(f.residuals ** 2))
        if injected > 0:
            out["residual_rms_ratio"][i] = out["residual_rms_after"][i] / injected
        out["chi2_red"][i] = f.chi2_red
        out["consistency_max_after"][i] = np.max(consistency_angles(
            got, sim["theodolite_az"][i], sim["theodolite_el"][i], sim["ins_az"][i],
            sim["ins_el"][i], sim["ins_roll"][i] if int(p["use_roll"]) else 0.0))
    return out


# --------------------------------------------------------------------------- reports


def fit_report(readings: Readings, result: Fit, source: str) -> dict[str, object]:
    """JSON-ready summary of a fit: parameters, sigmas and residuals in arc-seconds."""
    roll = readings.ins_roll if readings.ins_roll is not None else np.zeros_like(readings.ins_az)
    params = result.params
    corr_az, corr_el, _ = correct_readings(readings.ins_az, readings.ins_el, roll,
                                           params["axis_az"], params["axis_el"])
    consistency = consistency_angles(params, readings.theodolite_az, readings.theodolite_el,
                                     readings.ins_az, readings.ins_el, roll)
    before, after = result.residuals_before / ARCSEC, result.residuals / ARCSEC
    mirrors = []
    for i, (name, kind) in enumerate(zip(readings.mirror, readings.sets, strict=True)):
        mirrors.append({
            "mirror": name, "set": kind,
            "residual_before_az_arcsec": before[i, 0], "residual_before_el_arcsec": before[i, 1],
            "residual_after_az_arcsec": after[i, 0], "residual_after_el_arcsec": after[i, 1],
            "consistency_after_arcsec": consistency[i] / ARCSEC,
            "corrected_ins_az_deg": math.degrees(corr_az[i]),
            "corrected_ins_el_deg": math.degrees(corr_el[i]),
        })

    def rms(r):
        return {"az": float(np.sqrt(np.mean(r[:, 0] ** 2))),
                "el": float(np.sqrt(np.mean(r[:, 1] ** 2))), "all": float(np.sqrt(np.mean(r ** 2)))}

    return {
        "system": "collimation",
        "file": source,
        "n_mirrors": len(readings.mirror),
        "roll": "reported" if readings.ins_roll is not None else "assumed zero (level mount)",
        "effects": [e for e in EFFECTS if set(EFFECTS[e]) <= set(result.names)],
        "unit": "arcsec",
        "parameters": {k: v / ARCSEC for k, v in params.items()},
        "stderr": {k: v / ARCSEC for k, v in result.stderr.items()},
        "covariance_arcsec2": (result.covariance / ARCSEC**2).tolist(),
        "sigma_arcsec": {"heading": result.sigma[0] / ARCSEC, "pitch": result.sigma[1] / ARCSEC},
        "sigma_source": result.sigma_source,
        "chi2": result.chi2, "dof": result.dof, "chi2_red": result.chi2_red,
        "passes_arcsec": [v / ARCSEC for v in result.passes],
        "mirrors": mirrors,
        "rms_arcsec": {"before": rms(before), "after": rms(after)},
    }


def format_report(report: Mapping[str, object]) -> str:
    """Human-readable text of :func:`fit_report`."""
    p, se = report["parameters"], report["stderr"]
    sets = [m["set"] for m in report["mirrors"]]
    lines = [
        f"seed 003 axis calibration: {report['file']}, {report['n_mirrors']} mirrors "
        f"({sets.count('azimuth')} azimuth, {sets.count('pitch')} pitch); "
        f"INS roll {report['roll']}",
        f"residual sigma: heading {report['sigma_arcsec']['heading']:.2f}″, pitch "
        f"{report['sigma_arcsec']['pitch']:.2f}″ ({report['sigma_source']})",
        "optical axis relative to the INS axis (±1σ):",
        f"  axis_az  γ = {p['axis_az']:10.2f} ± {se['axis_az']:.2f} arc-seconds (right +)",
        f"  axis_el  λ = {p['axis_el']:10.2f} ± {se['axis_el']:.2f} arc-seconds (up +)",
        "reference terms:",
    ]
    for k in p:
        if k in EFFECTS["axis_misalignment"]:
            continue
        if k == "frame_heading":
            lines.append(f"  frame_heading = {p[k] / 3600:.6f}° ± {se[k]:.2f} arc-seconds")
        else:
            lines.append(f"  {k} = {p[k]:.2f} ± {se[k]:.2f} arc-seconds")
    lines += [
        "offset increment per pass (fit, correct, refit): "
        + ", ".join(f"{v:.4f}″" for v in report["passes_arcsec"]),
        f"chi2/dof = {report['chi2']:.2f}/{report['dof']} = {report['chi2_red']:.3f}",
        "",
        "per-mirror residuals, INS reading - model [arc-seconds]; consistency = angle between",
        "corrected optical axis and mirror normal:",
        f"{'mirror':>10} {'set':>8} {'before az':>10} {'before el':>10} {'after az':>9} "
        f"{'after el':>9} {'consistency':>11}",
    ]
    for m in report["mirrors"]:
        lines.append(
            f"{m['mirror']:>10} {m['set']:>8} {m['residual_before_az_arcsec']:10.2f} "
            f"{m['residual_before_el_arcsec']:10.2f} {m['residual_after_az_arcsec']:9.2f} "
            f"{m['residual_after_el_arcsec']:9.2f} {m['consistency_after_arcsec']:11.2f}")
    b, a = report["rms_arcsec"]["before"], report["rms_arcsec"]["after"]
    lines.append(f"{'RMS':>10} {'':>8} {b['az']:10.2f} {b['el']:10.2f} {a['az']:9.2f} "
                 f"{a['el']:9.2f}")
    lines.append(f"RMS of all residuals: before {b['all']:.2f}″, after {a['all']:.2f}″")
    return "\n".join(lines)
