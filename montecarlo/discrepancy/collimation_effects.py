"""Autocollimator-INS calibration with candidate effects for the discrepancy workflow (issue 5).

The forward model is seed 003's, :func:`montecarlo.collimation.predict_readings` (INS heading
and pitch reported when the autocollimator is autocollimated on a mirror whose normal the
theodolite measured), extended by the candidate effects of issue 5. The base model is the
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

Known degeneracies (docs/collimation.md): the collimation c has exactly gamma's signature, an INS
pitch bias lambda's, an INS heading bias frame_heading's; the engine finds them as absorbed or
confounded from the Jacobian, nothing here encodes it.

References
----------
seed 003, section 2 (method), section 3.1 (fixture: 7 azimuth and 7 pitch mirrors, T3
theodolite 2 arc-seconds).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from montecarlo.seed003 import model as col
from montecarlo.discrepancy import engine as dia
from montecarlo.discrepancy.view import SystemView
from montecarlo.errors import InputError
from montecarlo.systems.params import ParamSystem
from montecarlo.engine.system import Metric

FloatArray = NDArray[np.float64]
ARCSEC = col.ARCSEC

BASE = dia.Effect("frame_heading", ("frame_heading",), ((-np.inf, np.inf),), (1e-7,),
                  "INS heading of the theodolite's azimuth zero [rad]")

CANDIDATES = (
    dia.Effect("axis_misalignment", ("axis_az", "axis_el"), ((-math.radians(5.0),
               math.radians(5.0)),) * 2, (1e-7,) * 2,
               "optical axis vs INS axis: azimuth gamma, elevation lambda [rad]", (1.0, 1.0)),
    dia.Effect("frame_misalignment", ("frame_tilt_x", "frame_tilt_y"), ((-math.radians(1.0),
               math.radians(1.0)),) * 2, (1e-7,) * 2,
               "tilt of the theodolite/mirror frame against the INS level [rad]", (1.0, 1.0)),
    dia.Effect("ins_scale_factor", ("ins_heading_scale", "ins_pitch_scale"), ((-0.01, 0.01),) * 2,
               (1e-7,) * 2, "INS heading and pitch scale factors [1]", (1.0, 1.0)),
    dia.Effect("ins_bias", ("ins_heading_bias", "ins_pitch_bias"), ((-math.radians(0.5),
               math.radians(0.5)),) * 2, (1e-7,) * 2, "INS heading and pitch biases [rad]",
               (1.0, 1.0)),
    dia.Effect("theodolite_collimation", ("theodolite_c",), ((-math.radians(0.1),
               math.radians(0.1)),), (1e-7,),
               "theodolite collimation c: azimuth read + c / cos(el) [rad]"),
)
CANDIDATE_NAMES = tuple(c.name for c in CANDIDATES)

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


@dataclass(frozen=True)
class MirrorData:
    """One calibration: theodolite and INS readings at each mirror (angles [rad]).

    ``ins_az``/``ins_el`` are zero for a layout (no readings); ``ins_roll`` None when not
    reported (level mount assumed).
    """

    mirror: tuple[str, ...]
    sets: tuple[str, ...]
    theodolite_az: FloatArray
    theodolite_el: FloatArray
    ins_az: FloatArray
    ins_el: FloatArray
    ins_roll: FloatArray | None = None

    @classmethod
    def from_readings(cls, r: col.Readings) -> MirrorData:
        return cls(tuple(r.mirror), tuple(r.sets), r.theodolite_az, r.theodolite_el, r.ins_az,
                   r.ins_el, r.ins_roll)

    @property
    def roll(self) -> FloatArray:
        return np.zeros_like(self.ins_az) if self.ins_roll is None else self.ins_roll

    def layout(self) -> dict[str, object]:
        """The mirrors without the INS readings, JSON-able (for studies)."""
        return {"mirror": list(self.mirror), "set": list(self.sets),
                "theodolite_az": self.theodolite_az.tolist(),
                "theodolite_el": self.theodolite_el.tolist(),
                "ins_roll": None if self.ins_roll is None else self.ins_roll.tolist()}


def layout_from_json(text: str) -> MirrorData:
    raw = json.loads(text)
    az = np.asarray(raw["theodolite_az"], float)
    roll = raw.get("ins_roll")
    return MirrorData(tuple(raw["mirror"]), tuple(raw["set"]), az,
                      np.asarray(raw["theodolite_el"], float), np.zeros_like(az),
                      np.zeros_like(az), None if roll is None else np.asarray(roll, float))


def paper_mirrors(n_azimuth: int = 7, n_pitch: int = 7, azimuth_span: float = math.pi / 2,
                  pitch_span: float = math.pi / 3) -> MirrorData:
    """Seed 003's fixture (:func:`montecarlo.collimation.paper_layout`), no readings."""
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
    seed 003, section 2, through :func:`montecarlo.collimation.predict_readings`; the extra
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


def collimation_problem(data: MirrorData, angle_sigma: float) -> dia.Problem:
    """The DIA problem of one calibration; each heading and pitch residual has ``angle_sigma``.
    """
    ref = mean_heading(data.ins_az)

    def residuals(values: Mapping[str, FloatArray]) -> FloatArray:
        heading, pitch = predict_readings(values, data, ref)
        return np.concatenate([col.wrap(data.ins_az - heading) / angle_sigma,
                               (data.ins_el - pitch) / angle_sigma], axis=-1)

    start = {"frame_heading": mean_heading(data.ins_az - data.theodolite_az)}
    return dia.Problem("collimation", BASE, CANDIDATES, residuals, start)


def raw_residuals(data: MirrorData, params: Mapping[str, float]) -> FloatArray:
    """Reading minus model, heading and pitch, shape (m, 2) [rad]."""
    heading, pitch = predict_readings(params, data, mean_heading(data.ins_az))
    return np.stack([col.wrap(data.ins_az - heading), data.ins_el - pitch], axis=-1)


def min_mirrors() -> int:
    """Fewest mirrors: frame heading + the largest candidate (2) + 1 dof, two readings each."""
    return math.ceil((1 + 2 + 1) / 2)


def read_mirror_csv(path: str | Path) -> MirrorData:
    """Read a collimation CSV (:func:`montecarlo.collimation.read_readings`) for a diagnosis.

    Raises
    ------
    InputError
        As ``read_readings``, or fewer than :func:`min_mirrors` rows.
    """
    data = MirrorData.from_readings(col.read_readings(path, effects=()))
    if len(data.mirror) < min_mirrors():
        raise InputError(f"{path}: {len(data.mirror)} data rows, at least {min_mirrors()} "
                         "needed (frame heading + up to 2 parameters of an effect + 1 degree "
                         "of freedom, 2 readings per mirror)")
    return data


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
                  ) -> dia.Problem:
    """The problem of noise-free readings generated by ``truth`` (for design MDBs)."""
    return collimation_problem(simulate(layout, truth, col.Noise(0.0, 0.0, 0.0, 0.0, 0.0)),
                               angle_sigma)


# --------------------------------------------------------------------------- study hook

_TRUTH_KEYS = tuple(p for c in CANDIDATES for p in c.parameters)

DEFAULT_PARAMS: dict[str, float | int | str] = {
    "n_azimuth": 7, "n_pitch": 7, "azimuth_span": math.radians(90.0),
    "pitch_span": math.radians(60.0), "layout": "",
    "theodolite_sigma": 2.0 * ARCSEC, "ins_sigma": 2.0 * ARCSEC, "mount_roll_sigma": 0.0,
    "frame_heading": math.radians(30.0),
    **dict.fromkeys(_TRUTH_KEYS, 0.0),
    "fit_effects": "", "diagnose": 0, "expected": "", "inject_mdb": 0.0, "alpha": dia.ALPHA,
}
"""Defaults of :func:`run_trials` (SI units, radians); see its docstring."""

METRICS = dia.TRIAL_METRICS


def run_trials(params: Mapping[str, float | int | str], rng: np.random.Generator, n: int
               ) -> dict[str, FloatArray]:
    """Monte Carlo of the collimation diagnosis: simulate calibrations, fit or diagnose each.

    Parameters
    ----------
    params : mapping; missing keys take :data:`DEFAULT_PARAMS`.
        ``n_azimuth``, ``n_pitch`` [count] (7, 7), ``azimuth_span``, ``pitch_span`` [rad]
        (90, 60 deg): seed 003's fixture, or ``layout`` [JSON text] as
        :meth:`MirrorData.layout` ("" for the fixture). ``theodolite_sigma`` [rad] (2
        arc-seconds): each theodolite reading; ``ins_sigma`` [rad] (2 arc-seconds): each INS
        heading, pitch and roll reading; ``mount_roll_sigma`` [rad] (0): true roll spread
        (reported when > 0). The diagnosis is told ``hypot(theodolite_sigma, ins_sigma)`` per
        heading and pitch residual. ``frame_heading`` [rad] (30 deg) and every candidate
        parameter (``axis_az``, ``axis_el``, ``frame_tilt_x``, ``frame_tilt_y``,
        ``ins_heading_bias``, ``ins_pitch_bias``, ``theodolite_c`` [rad];
        ``ins_heading_scale``, ``ins_pitch_scale`` [1]): true values (0).
        ``fit_effects``, ``diagnose``, ``expected``, ``inject_mdb``, ``alpha``: as in
        :func:`montecarlo.ground_effects.run_trials`.
    rng : numpy Generator, the only source of randomness.
    n : number of simulated calibrations.

    Returns
    -------
    dict of metric -> ndarray (n,), float64: :data:`montecarlo.discrepancy.TRIAL_METRICS`
    (``rms`` [rad] of heading and pitch residuals; ``named_watched`` counts
    ``theodolite_collimation`` named).
    """
    unknown = set(params) - set(DEFAULT_PARAMS)
    if unknown:
        raise ValueError(f"unknown parameter(s) {sorted(unknown)}")
    p = {**DEFAULT_PARAMS, **params}
    layout = (paper_mirrors(int(p["n_azimuth"]), int(p["n_pitch"]), float(p["azimuth_span"]),
                            float(p["pitch_span"]))
              if not p["layout"] else layout_from_json(str(p["layout"])))
    ins = float(p["ins_sigma"])
    noise = col.Noise(float(p["theodolite_sigma"]), ins, ins, ins, float(p["mount_roll_sigma"]))
    sigma = math.hypot(noise.theodolite, ins)
    truth = {k: float(p[k]) for k in ("frame_heading", *_TRUTH_KEYS)}
    alpha = float(p["alpha"])
    expected = str(p["expected"])
    effects = tuple(e.strip() for e in str(p["fit_effects"]).split(",") if e.strip())
    if float(p["inject_mdb"]) > 0:
        if not expected:
            raise ValueError("inject_mdb needs an expected effect")
        truth = dia.inject_at_mdb(lambda tr: exact_problem(layout, tr, sigma), truth, expected,
                                  float(p["inject_mdb"]), alpha)
    return dia.score_trials(
        lambda g: simulate(layout, truth, noise, g),
        lambda data: collimation_problem(data, sigma),
        lambda data, fit: float(np.sqrt(np.mean(raw_residuals(data, fit.params) ** 2))),
        truth, effects, int(p["diagnose"]), expected, alpha, rng, n,
        watched=("theodolite_collimation",))


def report_view(data: MirrorData, angle_sigma: float) -> SystemView:
    """How reports show a collimation diagnosis: units, residual axes, Monte Carlo params."""
    axes = [("theodolite elevation [deg]", np.degrees(data.theodolite_el), None),
            ("theodolite azimuth [deg]", np.degrees(data.theodolite_az), None),
            ("mirror (file order)", np.arange(data.theodolite_az.size, dtype=float), None)]
    layout = json.dumps(data.layout())

    def study_params(fit: dia.ModelFit) -> dict[str, object]:
        values = fit.params
        return {"layout": layout, "theodolite_sigma": angle_sigma / math.sqrt(2.0),
                "ins_sigma": angle_sigma / math.sqrt(2.0), "mount_roll_sigma": 0.0,
                **{k: float(values.get(k, 0.0)) for k in ("frame_heading", *_TRUTH_KEYS)},
                "fit_effects": ",".join(fit.effects[1:]), "diagnose": 0}

    return SystemView("collimation", display_unit, "arcsec", ARCSEC, ("heading", "pitch"),
                      lambda params: raw_residuals(data, params), axes, STUDY_SYSTEM,
                      study_params, lambda name: ("arcsec", ARCSEC) if name == "frame_heading"
                      else display_unit(name))


STUDY_SYSTEM = ParamSystem(
    name="discrepancy_collimation",
    module="montecarlo.discrepancy.collimation_effects",
    units={"azimuth_span": "deg", "pitch_span": "deg", "theodolite_sigma": "arcsec",
           "ins_sigma": "arcsec", "mount_roll_sigma": "deg", "frame_heading": "deg",
           "axis_az": "arcsec", "axis_el": "arcsec", "frame_tilt_x": "arcsec",
           "frame_tilt_y": "arcsec", "ins_heading_bias": "arcsec", "ins_pitch_bias": "arcsec",
           "theodolite_c": "arcsec"},
    metrics_=(
        Metric("chi2", "χ² of the fitted model", "1", 1.0),
        Metric("chi2_red", "reduced χ² of the fitted model", "1", 1.0),
        Metric("p_value", "global test p-value", "1", 1.0),
        Metric("rms", "residual RMS", "arcsec", 1.0 / ARCSEC),
        *(Metric(m, m.replace("_", " "), "1", 1.0) for m in METRICS[4:]),
    ),
    default_block_size=32,
)
"""Study system ``discrepancy_collimation``: residual statistics and DIA rates (issue 5)."""
