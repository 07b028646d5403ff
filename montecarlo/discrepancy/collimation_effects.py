"""Autocollimator-INS calibration with candidate effects for the discrepancy workflow.

The forward model is seed 003's, :func:`montecarlo.seed003.model.predict_readings` (INS heading
and pitch reported when the autocollimator is autocollimated on a mirror whose normal the
theodolite measured), extended by candidate effects. The base model is the
nominal instrument, only the heading of the theodolite's azimuth zero (``frame_heading``) fitted;
every other effect is a candidate, absent when its parameters are zero:

* ``axis_misalignment`` (``axis_az`` = gamma, ``axis_el`` = lambda [rad]): the optical axis
  off the INS axis, the quantity seed 003 calibrates;
* ``frame_misalignment`` (``frame_tilt_x``, ``frame_tilt_y`` [rad]): tilt of the
  theodolite/mirror frame against the INS level (rotation between the frames beyond heading);
* ``ins_scale_factor`` (``ins_heading_scale``, ``ins_pitch_scale`` [1]): reported heading
  ``h + s_h wrap(h - h_ref)`` (``h_ref`` the mean heading of the data set; a constant is
  absorbed by ``frame_heading``) and pitch ``p (1 + s_p)``;
* ``ins_bias`` (``ins_heading_bias``, ``ins_pitch_bias`` [rad]): reported ``h + b_h``,
  ``p + b_p``;
* ``theodolite_collimation`` (``theodolite_c`` [rad]): the theodolite's line of sight off
  its tilting axis by c, read in one face: it reads azimuth ``az + c / cos(el)``.

Known degeneracies (docs/reference/collimation.md): the collimation c has exactly gamma's
signature, an INS pitch bias lambda's, an INS heading bias frame_heading's; the engine finds them
as absorbed or confounded from the Jacobian, nothing here encodes it.

References
----------
seed 003, section 2 (method), section 3.1 (fixture: 7 azimuth and 7 pitch mirrors, T3
theodolite 2 arc-seconds).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from montecarlo.discrepancy.problem import Effect, Problem, is_outlier
from montecarlo.discrepancy.view import SystemView
from montecarlo.io.collimation_csv import MirrorData
from montecarlo.lsq import LeastSquaresFit
from montecarlo.seed003 import model as col
from montecarlo.units import ARCSEC

FloatArray = NDArray[np.float64]

BASE = Effect("frame_heading", ("frame_heading",), ((-np.inf, np.inf),), (1e-7,),
                  "INS heading of the theodolite's azimuth zero [rad]")

CANDIDATES = (
    Effect("axis_misalignment", ("axis_az", "axis_el"), ((-math.radians(5.0),
               math.radians(5.0)),) * 2, (1e-7,) * 2,
               "optical axis vs INS axis: azimuth gamma, elevation lambda [rad]", (1.0, 1.0)),
    Effect("frame_misalignment", ("frame_tilt_x", "frame_tilt_y"), ((-math.radians(1.0),
               math.radians(1.0)),) * 2, (1e-7,) * 2,
               "tilt of the theodolite/mirror frame against the INS level [rad]", (1.0, 1.0)),
    Effect("ins_scale_factor", ("ins_heading_scale", "ins_pitch_scale"), ((-0.01, 0.01),) * 2,
               (1e-7,) * 2, "INS heading and pitch scale factors [1]", (1.0, 1.0)),
    Effect("ins_bias", ("ins_heading_bias", "ins_pitch_bias"), ((-math.radians(0.5),
               math.radians(0.5)),) * 2, (1e-7,) * 2, "INS heading and pitch biases [rad]",
               (1.0, 1.0)),
    Effect("theodolite_collimation", ("theodolite_c",), ((-math.radians(0.1),
               math.radians(0.1)),), (1e-7,),
               "theodolite collimation c: azimuth read + c / cos(el) [rad]"),
)

DISPLAY_UNITS = {
    **dict.fromkeys(("axis_az", "axis_el", "frame_tilt_x", "frame_tilt_y", "ins_heading_bias",
                     "ins_pitch_bias", "theodolite_c"), ("arcsec", ARCSEC)),
    "frame_heading": ("deg", math.pi / 180.0),
    **dict.fromkeys(("ins_heading_scale", "ins_pitch_scale"), ("ppm", 1e-6)),
}
"""Parameter -> (unit shown in reports and JSON, its size in SI/radians)."""

_COL_PARAMS = ("frame_heading", "axis_az", "axis_el", "frame_tilt_x", "frame_tilt_y")


def display_unit(name: str) -> tuple[str, float]:
    return DISPLAY_UNITS[name]


def paper_mirrors(n_azimuth: int = 7, n_pitch: int = 7, azimuth_span: float = math.pi / 2,
                  pitch_span: float = math.pi / 3) -> MirrorData:
    """Seed 003's fixture (:func:`montecarlo.seed003.model.paper_layout`), no readings."""
    az, el, sets = col.paper_layout(n_azimuth, n_pitch, azimuth_span, pitch_span)
    names = tuple([f"A{i + 1}" for i in range(n_azimuth)] + [f"P{i + 1}" for i in range(n_pitch)])
    zero = np.zeros_like(az)
    return MirrorData(names, tuple(sets.tolist()), az, el, zero, zero.copy())


def predict_readings(params: Mapping[str, ArrayLike], data: MirrorData, heading_ref: float
                     ) -> tuple[FloatArray, FloatArray]:
    """INS heading and pitch reported at each mirror, shapes (..., m) [rad].

    Parameters
    ----------
    params : parameter name -> value (floats or arrays of shape (k, 1)); missing ones zero.
    data : theodolite readings (and INS roll) of the mirrors.
    heading_ref : heading at which the INS heading scale error is zero [rad].

    References
    ----------
    seed 003, section 2, through :func:`montecarlo.seed003.model.predict_readings`; the extra
    effects as in the module docstring.
    """
    def p(name: str) -> FloatArray:
        return np.asarray(params.get(name, 0.0), float)

    el = data.theodolite_el
    az = data.theodolite_az - p("theodolite_c") / np.cos(el)
    heading, pitch = col.predict_readings({k: p(k) for k in _COL_PARAMS}, az, el, data.roll)
    heading = col.wrap(heading + p("ins_heading_scale") * col.wrap(heading - heading_ref)
                       + p("ins_heading_bias"))
    pitch = pitch * (1.0 + p("ins_pitch_scale")) + p("ins_pitch_bias")
    return heading, pitch


def mean_heading(ins_az: FloatArray) -> float:
    """Circular mean of headings [rad]."""
    return float(np.angle(np.mean(np.exp(1j * ins_az))))


def collimation_problem(data: MirrorData, angle_sigma: float) -> Problem:
    """The DIA problem of one calibration; each heading and pitch residual has ``angle_sigma``.
    """
    ref = mean_heading(data.ins_az)

    def residuals(values: Mapping[str, FloatArray]) -> FloatArray:
        heading, pitch = predict_readings(values, data, ref)
        return np.concatenate([col.wrap(data.ins_az - heading) / angle_sigma,
                               (data.ins_el - pitch) / angle_sigma], axis=-1)

    start = {"frame_heading": mean_heading(data.ins_az - data.theodolite_az)}
    m = len(data.mirror)
    names = [mirror if data.mirror.count(mirror) == 1 else f"{mirror}/{s}"
             for mirror, s in zip(data.mirror, data.sets, strict=True)]
    observations = tuple((n if names.count(n) == 1 else f"{n} (row {i + 1})", i + 1,
                          (i, m + i)) for i, n in enumerate(names))
    return Problem("collimation", BASE, CANDIDATES, residuals, start,
                   observations=observations)


def raw_residuals(data: MirrorData, params: Mapping[str, float]) -> FloatArray:
    """Reading minus model, heading and pitch, shape (m, 2) [rad]."""
    heading, pitch = predict_readings(params, data, mean_heading(data.ins_az))
    return np.stack([col.wrap(data.ins_az - heading), data.ins_el - pitch], axis=-1)


def min_mirrors() -> int:
    """Fewest mirrors: frame heading + the largest candidate (2) + 1 dof, two readings each."""
    return math.ceil((1 + 2 + 1) / 2)


def simulate(layout: MirrorData, truth: Mapping[str, float], noise: col.Noise,
             rng: int | np.random.Generator | None = None) -> MirrorData:
    """Measured-like readings of the layout's mirrors (true normals) under ``truth``.

    The theodolite reads each normal with its collimation and noise; the INS, at true roll
    ``layout roll + N(0, mount_roll)``, reports :func:`predict_readings` of the true normals
    plus noise (its scale reference the mean true heading); the reported roll carries
    ``noise.ins_roll``.
    """
    rng = np.random.default_rng(rng)
    m = layout.theodolite_az.size
    roll = layout.roll + noise.mount_roll * rng.standard_normal(m)
    true = MirrorData(layout.mirror, layout.sets, layout.theodolite_az, layout.theodolite_el,
                      layout.ins_az, layout.ins_el, roll)
    geometric = {k: v for k, v in truth.items() if k in _COL_PARAMS}
    ref = mean_heading(col.predict_readings(geometric, layout.theodolite_az,
                                            layout.theodolite_el, roll)[0])
    no_collimation = {k: v for k, v in truth.items() if k != "theodolite_c"}
    heading, pitch = predict_readings(no_collimation, true, ref)
    c = float(truth.get("theodolite_c", 0.0))
    theo_az = layout.theodolite_az + c / np.cos(layout.theodolite_el)
    return MirrorData(
        layout.mirror, layout.sets,
        col.wrap(theo_az + noise.theodolite * rng.standard_normal(m)),
        layout.theodolite_el + noise.theodolite * rng.standard_normal(m),
        col.wrap(heading + noise.ins_heading * rng.standard_normal(m)),
        pitch + noise.ins_pitch * rng.standard_normal(m),
        None if layout.ins_roll is None and noise.mount_roll == 0.0
        else roll + noise.ins_roll * rng.standard_normal(m))


def exact_problem(layout: MirrorData, truth: Mapping[str, float], angle_sigma: float
                  ) -> Problem:
    """The problem of noise-free readings generated by ``truth`` (for design MDBs)."""
    return collimation_problem(simulate(layout, truth, col.Noise(0.0, 0.0, 0.0, 0.0, 0.0)),
                               angle_sigma)


TRUTH_KEYS = tuple(p for c in CANDIDATES for p in c.parameters)
"""Parameters of every candidate effect."""


def report_view(data: MirrorData, angle_sigma: float) -> SystemView:
    """How reports show a collimation diagnosis: units, residual axes, Monte Carlo params."""
    axes = [("theodolite elevation [deg]", np.degrees(data.theodolite_el), None),
            ("theodolite azimuth [deg]", np.degrees(data.theodolite_az), None),
            ("mirror (file order)", np.arange(data.theodolite_az.size, dtype=float), None)]
    layout = json.dumps(data.layout())

    def study_params(fit: LeastSquaresFit) -> dict[str, object]:
        values = fit.params
        return {"layout": layout, "theodolite_sigma": angle_sigma / math.sqrt(2.0),
                "ins_sigma": angle_sigma / math.sqrt(2.0), "mount_roll_sigma": 0.0,
                **{k: float(values.get(k, 0.0)) for k in ("frame_heading", *TRUTH_KEYS)},
                "fit_effects": ",".join(e for e in fit.effects[1:] if not is_outlier(e)),
                "diagnose": 0}

    return SystemView("collimation", display_unit, "arcsec", ARCSEC, ("heading", "pitch"),
                      lambda params: raw_residuals(data, params), axes, "discrepancy_collimation",
                      study_params, lambda name: ("arcsec", ARCSEC) if name == "frame_heading"
                      else display_unit(name))
