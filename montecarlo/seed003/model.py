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
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from montecarlo.geometry.rotations import euler_zxy_from_matrix, mounting_matrix
from montecarlo.units import ARCSEC

FloatArray = NDArray[np.float64]


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


def getter(params: Mapping[str, ArrayLike]):
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
    p = getter(params)
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
    p = getter(params)
    w = mirror_normal_in_nav(params, theodolite_az, theodolite_el)
    return autocollimate(direction(p("axis_az"), p("axis_el")), w, roll)


def autocollimate(u: ArrayLike, w: ArrayLike, roll: ArrayLike = 0.0
                  ) -> tuple[FloatArray, FloatArray]:
    """Heading and pitch [rad] of the attitude ``C`` with roll ``roll`` for which ``C u = w``.

    The closed form of :func:`predict_readings` for an optical axis ``u`` (frame b, shape
    (..., 3)) and a target direction ``w`` (shape (..., 3)) in whatever levelled frame the
    attitude is wanted; heading in [-pi, pi), NaN where no pitch reaches ``w``.

    References
    ----------
    seed 003, section 2 (the INS attitude recorded at each autocollimation).
    """
    u, w = np.asarray(u, float), np.asarray(w, float)
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
