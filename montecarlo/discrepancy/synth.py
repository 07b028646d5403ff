"""Measured-like synthetic data sets with chosen effects injected (``montecarlo synth``).

Each data set comes from its own seed (``SeedSequence(seed)``: one stream for the layout's
visiting order, one for the noise) and is written in the CSV format that
``montecarlo diagnose`` reads. How a data set was made (the truth) can be written to a separate
JSON file; the diagnosis never reads it.

Effects are given at the edge, in the units the reports use (``--effect NAME=V1[,V2...]``, one
value per parameter of the effect, see ``DISPLAY_UNITS`` of
:mod:`montecarlo.discrepancy.ground_effects` and :mod:`montecarlo.discrepancy.collimation_effects`),
or as a multiple of the effect's minimal detectable bias for the data set's own design and noise
(``--at-mdb NAME=MULT``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from montecarlo.discrepancy import collimation_effects as ce
from montecarlo.discrepancy import ground_effects as ge
from montecarlo.discrepancy import procedure_effects as pe
from montecarlo.discrepancy.design import inject_at_mdb
from montecarlo.discrepancy.problem import Effect, Problem
from montecarlo.errors import InputError
from montecarlo.geometry.camera import Camera
from montecarlo.io.collimation_csv import MirrorData
from montecarlo.io.ground_csv import GroundData
from montecarlo.seed003.model import Noise


def _effect_item(flag: str, item: str, effects: Mapping[str, Effect]) -> tuple[str, str]:
    """Split ``NAME=TEXT`` from ``flag`` and check that NAME is one of ``effects``."""
    name, _, text = item.partition("=")
    name = name.strip()
    if name not in effects:
        raise InputError(f"{flag} {item!r}: unknown effect; choose from {', '.join(effects)}")
    return name, text


def parse_effects(items: Sequence[str], effects: Mapping[str, Effect],
                  display_unit: Callable[[str], tuple[str, float]]) -> dict[str, float]:
    """``NAME=V1[,V2...]`` (display units) -> parameter values in SI units.

    Raises
    ------
    InputError
        Unknown effect, wrong number of values or a value that is not a number.
    """
    out: dict[str, float] = {}
    for item in items:
        name, text = _effect_item("--effect", item, effects)
        params = effects[name].parameters
        try:
            values = [float(v) for v in text.split(",")]
        except ValueError:
            raise InputError(f"--effect {item!r}: values must be numbers") from None
        if len(values) != len(params) or not all(math.isfinite(v) for v in values):
            units = ", ".join(f"{q} [{display_unit(q)[0]}]" for q in params)
            raise InputError(f"--effect {item!r}: {name} needs {len(params)} finite value(s): "
                             f"{units}")
        out.update({q: v * display_unit(q)[1] for q, v in zip(params, values, strict=True)})
    return out


def parse_multiples(items: Sequence[str], effects: Mapping[str, Effect]) -> dict[str, float]:
    """``NAME=MULT`` -> {effect: multiple of its MDB}."""
    out = {}
    for item in items:
        name, text = _effect_item("--at-mdb", item, effects)
        try:
            out[name] = float(text)
        except ValueError:
            raise InputError(f"--at-mdb {item!r}: the multiple must be a number") from None
        if not out[name] > 0:
            raise InputError(f"--at-mdb {item!r}: the multiple must be positive")
    return out


def _inject(exact: Callable[[Mapping[str, float]], Problem], truth: dict[str, float],
            multiples: Mapping[str, float]) -> dict[str, float]:
    for name, k in multiples.items():
        try:
            truth = inject_at_mdb(exact, truth, name, k)
        except ValueError as exc:
            raise InputError(f"--at-mdb {name}: {exc}") from None
    return truth


def synth_ground(*, seed: int, camera: Camera, pixel_sigma: float, survey_sigma: float,
                 mounting: Mapping[str, float], ranges: Sequence[float],
                 grid: tuple[int, int], spread: float, duration: float, sessions: int,
                 effects: Mapping[str, float], at_mdb: Mapping[str, float],
                 refraction: float = ge.STANDARD_REFRACTION, with_time: bool = True
                 ) -> tuple[GroundData, dict[str, float], int]:
    """One ground data set: targets of :func:`montecarlo.discrepancy.ground_effects.field_layout`.

    The data carry earth curvature and refraction with coefficient ``refraction`` [1] (plus
    the ``refraction`` effect's ``dk``, if injected). Targets imaged off the detector are
    dropped.

    Returns
    -------
    data, truth (SI), number of targets dropped.
    """
    layout_seed, noise_seed = np.random.SeedSequence(seed).spawn(2)
    layout = ge.field_layout(camera, mounting, ranges, grid, spread, duration, sessions,
                             layout_seed)
    if not with_time:
        layout = GroundData(layout.targets, layout.positions, layout.pixels, None,
                               layout.session)
    truth = {**mounting, **effects}
    truth = _inject(lambda tr: ge.exact_problem(layout, camera, tr, pixel_sigma, survey_sigma,
                                                refraction), truth, at_mdb)
    data = ge.simulate(layout, camera, truth, pixel_sigma, survey_sigma, noise_seed, refraction)
    visible = (np.abs(data.pixels[:, 0]) <= camera.n_x / 2) & \
        (np.abs(data.pixels[:, 1]) <= camera.n_z / 2)
    keep = np.flatnonzero(visible)
    data = GroundData(tuple(data.targets[i] for i in keep), data.positions[keep],
                         data.pixels[keep], None if data.t is None else data.t[keep],
                         None if data.session is None else tuple(data.session[i] for i in keep))
    return data, truth, int(visible.size - keep.size)


def synth_collimation(*, seed: int, n_azimuth: int, n_pitch: int, azimuth_span: float,
                      pitch_span: float, frame_heading: float, noise: Noise,
                      effects: Mapping[str, float], at_mdb: Mapping[str, float],
                      with_roll: bool = False) -> tuple[MirrorData, dict[str, float]]:
    """One collimation data set on seed 003's fixture (:func:`paper_mirrors`).

    The MDB of ``--at-mdb`` is for the residual sigma ``hypot(theodolite, INS heading)`` the
    diagnosis should be told.
    """
    layout = ce.paper_mirrors(n_azimuth, n_pitch, azimuth_span, pitch_span)
    if with_roll:
        layout = MirrorData(layout.mirror, layout.sets, layout.theodolite_az,
                               layout.theodolite_el, layout.ins_az, layout.ins_el,
                               np.zeros_like(layout.ins_az))
    sigma = math.hypot(noise.theodolite, noise.ins_heading)
    truth = {"frame_heading": frame_heading, **effects}
    truth = _inject(lambda tr: ce.exact_problem(layout, tr, sigma), truth, at_mdb)
    data = ce.simulate(layout, truth, noise, np.random.SeedSequence(seed).spawn(2)[1])
    return data, truth


def synth_procedure(*, seed: int, layout: MirrorData, frame_heading: float, noise: Noise,
                    effects: Mapping[str, float], at_mdb: Mapping[str, float], side: float = 1.0,
                    with_roll: bool = False) -> tuple[MirrorData, dict[str, float]]:
    """One calibration by seed 003's procedure on ``layout`` (reference rows or not), the
    readings of :func:`montecarlo.discrepancy.procedure_effects.simulate`.

    ``effects`` may hold the offsets ``axis_az``, ``axis_el`` (base parameters of the
    procedure) and any candidate's parameters. The MDB of ``--at-mdb`` is for the residual sigma
    ``hypot(theodolite, INS heading)`` the diagnosis should be told.
    """
    if with_roll:
        layout = MirrorData(layout.mirror, layout.sets, layout.theodolite_az,
                            layout.theodolite_el, layout.ins_az, layout.ins_el,
                            np.zeros_like(layout.ins_az))
    sigma = math.hypot(noise.theodolite, noise.ins_heading)
    truth = {"axis_az": 0.0, "axis_el": 0.0, **effects}
    truth = _inject(lambda tr: pe.exact_problem(layout, tr, sigma, side), truth, at_mdb)
    data = pe.simulate(layout, truth, noise, np.random.SeedSequence(seed).spawn(2)[1], side,
                       frame_heading)
    return data, {"frame_heading": frame_heading, **truth}


def truth_report(system: str, seed: int, truth: Mapping[str, float],
                 display_unit: Callable[[str], tuple[str, float]], **extra: Any) -> str:
    """JSON text of how a data set was made (display units)."""
    return json.dumps({"system": system, "seed": seed,
                       "truth": {k: v / display_unit(k)[1] for k, v in truth.items()},
                       "units": {k: display_unit(k)[0] for k in truth}, **extra}, indent=2) + "\n"
