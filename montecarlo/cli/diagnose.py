"""The discrepancy workflow: ``diagnose ground | collimation | stabilization | camera``,
``synth ground | collimation``."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from montecarlo.cli.camera import add_diagnose_parser
from montecarlo.cli.common import (
    Parser,
    add_force_option,
    add_json_option,
    add_n_jobs_option,
    check_json_option,
    emit_json,
    field_of_view,
    finite,
    nonnegative,
    nonnegative_int,
    number,
    positive,
    positive_int,
    probability,
    write_provenance,
    write_text,
)
from montecarlo.cli.noise_options import (
    AUTO,
    AUTO_HELP,
    diagnose_collimation,
    diagnose_ground,
    diagnose_stabilization_auto,
    nonnegative_or_auto,
    positive_or_auto,
    report_entry,
)
from montecarlo.cli.stabilization import conventions_json, conventions_text
from montecarlo.cli.steps import LIBRARIES, Steps, fit_why
from montecarlo.errors import InputError
from montecarlo.io.files import OutputDir, writable_file
from montecarlo.units import ARCSEC

if TYPE_CHECKING:
    from collections.abc import Sequence

    from montecarlo.discrepancy.engine import Diagnosis
    from montecarlo.discrepancy.view import SystemView
    from montecarlo.io.collimation_csv import MirrorData


def _unit(unit: str) -> str:
    return "" if unit == "1" else f" {unit}"


START_IMAGE_NOISE = 0.1
"""Image noise [px] the estimator's start and the first pass use under ``auto``."""


def _check_outputs(args: argparse.Namespace) -> None:
    """Refuse, before any work, a --report directory or --json file that cannot be written,
    --check-sets without --identifiability, and --identifiability with a noise left to
    ``auto`` (its rates are those of the tests at a known noise)."""
    if getattr(args, "check_sets", 0) and not args.identifiability:
        raise InputError("--check-sets: only with --identifiability")
    if getattr(args, "identifiability", False):
        for flag in ("pixel_sigma_px", "survey_sigma_m", "angle_sigma_arcsec"):
            if getattr(args, flag, None) == "auto":
                raise InputError(f"--identifiability: needs --{flag.replace('_', '-')} stated "
                                 "(not auto): its rates are those of the tests at a known "
                                 "noise; state the value auto estimated")
    if args.report:
        OutputDir(args.report, "diagnose", inputs=(Path(args.data),)).check()
    check_json_option(args)


def _check_files(args: argparse.Namespace) -> None:
    """Refuse, before any work, data and truth files that cannot be written."""
    writable_file(args.out, args.force)
    if args.truth:
        writable_file(args.truth, args.force)


def _diagnosis_output(args: argparse.Namespace, d: Diagnosis, view: SystemView,
                      source: str, steps: Steps, extra: dict | None = None,
                      preface: tuple[str, ...] = (),
                      groups: tuple[str, Sequence[str]] | None = None) -> int:
    """Print or write the diagnosis; ``groups``: (kind, the label of each observation) for the
    test of residuals clustering by group."""
    from montecarlo.discrepancy.groups import clustering_by, format_clustering
    from montecarlo.discrepancy.view import format_text, to_json
    from montecarlo.output.provenance import provenance

    report = {**to_json(d, view, source), **(extra or {})}
    grouped = None if groups is None else clustering_by(d, *groups)
    if grouped is not None:
        report["clustering"] = grouped
    record = {"input": source, "alpha": args.alpha, "seed": args.seed, "trials": args.trials}
    if getattr(args, "identifiability", False):
        from montecarlo.systems import identifiability

        with steps("the identifiability", f"{args.sets} linearised sets per size"
                   + (f", {args.check_sets} nonlinear diagnoses per size and candidate "
                      "(--check-sets)" if args.check_sets else "")):
            identifiability.annotate(report, d, view, args.pci_target, args.sets, args.seed,
                                     args.n_jobs, args.check_sets)
    if args.report:
        from montecarlo.output.diagnosis import (  # matplotlib: only for reports
            write_html_report,
            write_report,
        )
        from montecarlo.systems.discrepancy import monte_carlo_gap

        with OutputDir(args.report, "diagnose", inputs=(Path(source),)) as staging:
            with steps("the report's Monte Carlo", f"{args.trials} simulated data sets per "
                       "model, each fitted; --trials sets how many"):
                mc = monte_carlo_gap(d, view, args.trials, args.seed, args.n_jobs) \
                    if args.trials > 0 else None
            with steps("the report's plots", "matplotlib"):
                write_report(staging, d, view, report, mc, args.trials, args.seed)
            write_provenance(staging, "diagnose", **record)
            write_html_report(staging, d, view, mc)
    if emit_json(args, {**report, "provenance": provenance("diagnose", **record)}):
        steps.report(to_stderr=True)
        return 0
    print("\n".join([*preface, format_text(report),
                     *([format_clustering(report["clustering"])] if "clustering" in report
                       else [])]))
    if "identifiability" in report:
        from montecarlo.systems.identifiability import format_table

        print(format_table(report))
    if args.report:
        print(f"report written to {args.report}/ (report.md, report.html, diagnosis.json, "
              "residuals.png, gap.png)")
    steps.report(to_stderr=False)
    return 0


def _cmd_diagnose_ground(args: argparse.Namespace) -> int:
    steps = Steps()
    with steps("loading", LIBRARIES):
        from montecarlo.discrepancy import ground_effects as ge
        from montecarlo.discrepancy.fit import FitError
        from montecarlo.geometry.camera import Camera
        from montecarlo.io.ground_csv import read_ground_csv

    _check_outputs(args)
    try:
        camera = Camera.from_degrees(args.fov_deg[0], args.fov_deg[1], args.pixels[0],
                                     args.pixels[1])
    except ValueError as exc:
        raise InputError(f"montecarlo diagnose ground: {exc}") from None
    data = read_ground_csv(args.data, camera, ge.min_targets(), "3 mounting angles + up to 3 "
                           "parameters of an effect + 1 degree of freedom, 2 image coordinates "
                           "per row")
    ge.check_in_front(data, camera, str(args.data))
    try:
        with steps("the diagnosis", fit_why(2 * len(data.pixels), 6)):
            d, sigma, survey, extra = diagnose_ground(data, camera, args.pixel_sigma_px,
                                                      args.survey_sigma_m, args.refraction_k,
                                                      args.alpha)
    except FitError as exc:
        raise InputError(f"{args.data}: {exc}") from None
    return _diagnosis_output(args, d, ge.report_view(data, camera, sigma, survey,
                                                     args.refraction_k), str(args.data), steps,
                             extra, groups=("target", data.targets))


def _cmd_diagnose_collimation(args: argparse.Namespace) -> int:
    steps = Steps()
    with steps("loading", LIBRARIES):
        from montecarlo.discrepancy import collimation_effects as ce
        from montecarlo.discrepancy.fit import FitError
        from montecarlo.io.collimation_csv import read_mirror_csv

    _check_outputs(args)
    sigma = math.nan if args.angle_sigma_arcsec == AUTO else args.angle_sigma_arcsec * ARCSEC
    if args.readings == "reference":
        return _diagnose_procedure(args, sigma, steps)
    for flag, used in (("--roll-mirror", args.roll_mirror),
                       ("--azimuth-sense", args.azimuth_sense),
                       ("--roll-sigma-deg", args.roll_sigma_deg)):
        if used is not None:
            raise InputError(f"{flag}: only with --readings reference")
    data = read_mirror_csv(args.data, ce.min_mirrors(), "frame heading + up to 2 parameters "
                           "of an effect + 1 degree of freedom, 2 readings per mirror")
    _check_separable(args.data, data)
    try:
        with steps("the diagnosis", fit_why(2 * len(data.sets), 4)):
            d, sigma, extra = diagnose_collimation(lambda s: ce.collimation_problem(data, s),
                                                   args.angle_sigma_arcsec, args.alpha)
    except FitError as exc:
        raise InputError(f"{args.data}: {exc}") from None
    return _diagnosis_output(args, d, ce.report_view(data, sigma), str(args.data), steps,
                             extra, groups=("mirror", data.mirror))


def _check_separable(path: str, data: MirrorData) -> None:
    """Refuse mirrors that ``collimation fit --readings absolute`` refuses: its base model
    (frame heading and the optical-axis offsets) must be determined before any effect is
    looked for (e.g. mirrors all at one elevation leave axis_az and frame_heading confounded).
    """
    from montecarlo.seed003.fit import NotSeparable, fit

    try:
        fit(data.theodolite_az, data.theodolite_el, data.ins_az, data.ins_el, data.ins_roll)
    except NotSeparable as exc:
        raise InputError(f"{path}: {exc}") from None


def _cmd_diagnose_stabilization(args: argparse.Namespace) -> int:
    steps = Steps()
    with steps("loading", LIBRARIES):
        from montecarlo.discrepancy import stabilization_effects as ste
        from montecarlo.discrepancy.engine import diagnose
        from montecarlo.discrepancy.fit import FitError
        from montecarlo.discrepancy.view import format_text, to_json
        from montecarlo.geometry.camera import Camera
        from montecarlo.io.stabilization_csv import read_csv
        from montecarlo.output.provenance import provenance
        from montecarlo.seed001 import estimate as se
        from montecarlo.units import DEG_PER_ROOT_HOUR

    check_json_option(args)
    with steps("reading the recording", "a CSV row per sample"):
        record = read_csv(args.data)
    camera = Camera.from_degrees(args.fov_deg, args.fov_deg, args.pixels, args.pixels)
    gyro_noise = args.gyro_arw_deg_per_rt_h * DEG_PER_ROOT_HOUR
    n = len(record.t)
    image_noise = START_IMAGE_NOISE if args.image_noise_px == AUTO else args.image_noise_px
    noise = None
    try:
        with steps("the estimator's start", f"recursive least squares over the {n} samples, "
                   "then the image walk's Kalman whitening"):
            est = se.estimate(record.t, record.gyro, record.eta, record.eps, record.los_px,
                              camera, image_noise, gyro_noise, mount=args.mount,
                              gyro_sampling=args.gyro_sampling)
            problem = ste.stabilization_problem(record, camera, image_noise, gyro_noise,
                                                args.mount, args.gyro_sampling, est)
        with steps("the diagnosis", fit_why(2 * n, len(problem.base.parameters))):
            if args.image_noise_px == AUTO:
                d, used, found = diagnose_stabilization_auto(
                    lambda s: ste.stabilization_problem(record, camera, s, gyro_noise,
                                                        args.mount, args.gyro_sampling, est),
                    gyro_noise, image_noise, args.alpha)
                image_noise = used["image_noise_px"]
                noise = report_entry(used, found)
            else:
                d = diagnose(problem, args.alpha)
    except FitError as exc:
        raise InputError(f"{args.data}: {exc}") from None
    report = to_json(d, ste.report_view(record, camera, args.mount, args.gyro_sampling),
                     str(args.data))
    if noise is not None:
        report["noise_estimate"] = noise
    else:
        report["stated_noise"] = {"image noise px": image_noise}
    check = ste.convention_check(record, camera, image_noise, gyro_noise, args.mount,
                                 args.gyro_sampling, d.before, args.alpha)
    report["conventions"] = conventions_json(check)
    record_args = {"input": str(args.data), "alpha": args.alpha, "mount": args.mount,
                   "gyro_sampling": args.gyro_sampling, "image_noise_px": args.image_noise_px,
                   "gyro_arw_deg_per_rt_h": args.gyro_arw_deg_per_rt_h}
    if emit_json(args, {**report, "provenance": provenance("diagnose", **record_args)}):
        steps.report(to_stderr=True)
        return 0
    print(format_text(report))
    for line in conventions_text(report["conventions"]):
        print(line)
    steps.report(to_stderr=False)
    return 0


def _diagnose_procedure(args: argparse.Namespace, sigma: float, steps: Steps) -> int:
    """``diagnose collimation --readings reference``: the procedure's reading model as base.

    The roll-mirror side and the azimuth sense are taken from the data under ``auto`` (the base
    model fitted under each, the smallest chi-square, as ``collimation fit`` does), then the
    diagnosis runs under them."""
    import sys

    from montecarlo.discrepancy import procedure_effects as pe
    from montecarlo.discrepancy.fit import FitError
    from montecarlo.io.collimation_csv import (
        REFERENCE_SETS,
        SETS,
        procedure_data,
        read_mirror_csv,
    )

    data = read_mirror_csv(args.data, pe.min_mirrors(), "gamma, lambda (+ reference azimuth) "
                           "+ up to 2 parameters of an effect + 1 degree of freedom",
                           sets=SETS + REFERENCE_SETS)
    measured = sum(s in SETS for s in data.sets)
    if measured < pe.min_mirrors():
        raise InputError(f"{args.data}: {measured} measured (azimuth/pitch) mirrors, at least "
                         f"{pe.min_mirrors()} needed")
    prior = math.radians(2.0 if args.roll_sigma_deg is None else args.roll_sigma_deg)
    try:
        if args.angle_sigma_arcsec == AUTO:  # conventions at the base model's a-posteriori S
            _, _, first = pe.choose_conventions(data, ARCSEC, args.roll_mirror or "auto",
                                                args.azimuth_sense or "auto", prior)
            best = min(first["roll_mirror"].chi2.values())
            sigma = ARCSEC * math.sqrt(best / (2 * measured - 4))
        data, side, choices = pe.choose_conventions(data, sigma, args.roll_mirror or "auto",
                                                    args.azimuth_sense or "auto", prior)
        with steps("the diagnosis", fit_why(2 * measured, 4)):
            d, sigma, noise = diagnose_collimation(
                lambda s: pe.procedure_problem(data, s, side, prior), args.angle_sigma_arcsec,
                args.alpha)
    except FitError as exc:
        raise InputError(f"{args.data}: {exc}") from None
    for choice in choices.values():
        line = choice.warning()
        if line:
            print(line, file=sys.stderr)
    extra: dict = {k: c.to_json() for k, c in choices.items()}
    extra.update(noise)
    preface = tuple(f"{k.replace('_', ' ')}: {c.chosen} (stated {c.stated}; "
                    + ", ".join(f"χ² {o} {v:.4g}" for o, v in c.chi2.items()) + "; "
                    + ("decided by the data" if c.decided else f"not decided: {c.reason}") + ")"
                    for k, c in choices.items())
    return _diagnosis_output(args, d, pe.report_view(data, sigma, side, prior), str(args.data),
                             steps, extra, preface,
                             ("mirror", [data.mirror[i] for i in procedure_data(data).measured]))


def _cmd_synth_ground(args: argparse.Namespace) -> int:

    from montecarlo.discrepancy import ground_effects as ge
    from montecarlo.discrepancy import synth
    from montecarlo.geometry.camera import Camera
    from montecarlo.io.ground_csv import GroundData, write_ground_csv

    _check_files(args)
    try:
        camera = Camera.from_degrees(args.fov_deg[0], args.fov_deg[1], args.pixels[0],
                                     args.pixels[1])
    except ValueError as exc:
        raise InputError(f"montecarlo synth ground: {exc}") from None
    candidates = {c.name: c for c in ge.candidates_for(GroundData(
        (), np.zeros((0, 3)), np.zeros((0, 2)), None, None if args.sessions < 2 else
        tuple(f"S{i + 1}" for i in range(args.sessions))))[0] if c.parameters}
    effects = synth.parse_effects(args.effect, candidates, ge.display_unit)
    at_mdb = synth.parse_multiples(args.at_mdb, candidates)
    mounting = dict(zip(("psi", "theta", "gamma"), map(math.radians, args.mounting_deg),
                        strict=True))
    data, truth, dropped = synth.synth_ground(
        seed=args.seed, camera=camera, pixel_sigma=args.pixel_sigma_px,
        survey_sigma=args.survey_sigma_m, mounting=mounting, ranges=args.ranges_m,
        grid=tuple(args.grid), spread=args.spread, duration=args.duration_s,
        sessions=args.sessions, effects=effects, at_mdb=at_mdb,
        refraction=args.refraction_k, with_time=not args.no_time)
    if data.n < ge.min_targets():
        raise InputError(f"montecarlo synth ground: only {data.n} targets on the detector")
    write_ground_csv(args.out, data)
    if args.truth:
        write_text(args.truth, synth.truth_report(
            "ground", args.seed, truth, ge.display_unit, pixel_sigma=args.pixel_sigma_px,
            survey_sigma_m=args.survey_sigma_m, refraction_k=args.refraction_k,
            dropped_targets=dropped))
    shown = {k: v / ge.display_unit(k)[1] for k, v in truth.items()
             if k not in ("psi", "theta", "gamma") and v != 0.0}
    print(f"wrote {args.out}: {data.n} observations ({dropped} off the detector dropped), "
          f"seed {args.seed}; injected: "
          + (", ".join(f"{k} = {v:.4g}{_unit(ge.display_unit(k)[0])}" for k, v in shown.items())
             or "nothing"))
    return 0


def _cmd_synth_collimation(args: argparse.Namespace) -> int:
    from montecarlo.discrepancy import collimation_effects as ce
    from montecarlo.discrepancy import synth
    from montecarlo.io.collimation_csv import write_mirror_csv
    from montecarlo.seed003.model import Noise

    _check_files(args)
    absolute_only = {"--n-azimuth": args.n_azimuth, "--n-pitch": args.n_pitch,
                     "--azimuth-span-deg": args.azimuth_span_deg,
                     "--pitch-span-deg": args.pitch_span_deg}
    if args.readings == "reference":
        given = [k for k, v in absolute_only.items() if v is not None]
        if given:
            raise InputError(f"{', '.join(given)}: only with --readings absolute (the "
                             "procedure's mirrors are --azimuths-deg, --pitch-elevations-deg)")
        return _synth_procedure(args)
    for flag, used in (("--no-reference-rows", args.no_reference_rows),
                       ("--roll-mirror", args.roll_mirror),
                       ("--azimuths-deg", args.azimuths_deg),
                       ("--pitch-elevations-deg", args.pitch_elevations_deg)):
        if used:
            raise InputError(f"{flag}: only with --readings reference")
    for key, default in (("n_azimuth", 7), ("n_pitch", 7), ("azimuth_span_deg", 90.0),
                         ("pitch_span_deg", 60.0)):
        if getattr(args, key) is None:
            setattr(args, key, default)
    candidates = {c.name: c for c in ce.CANDIDATES}
    effects = synth.parse_effects(args.effect, candidates, ce.display_unit)
    at_mdb = synth.parse_multiples(args.at_mdb, candidates)
    ins = args.ins_sigma_arcsec * ARCSEC
    noise = Noise(args.theodolite_sigma_arcsec * ARCSEC, ins, ins, ins,
                      math.radians(args.mount_roll_sigma_deg))
    data, truth = synth.synth_collimation(
        seed=args.seed, n_azimuth=args.n_azimuth, n_pitch=args.n_pitch,
        azimuth_span=math.radians(args.azimuth_span_deg),
        pitch_span=math.radians(args.pitch_span_deg),
        frame_heading=math.radians(args.frame_heading_deg), noise=noise, effects=effects,
        at_mdb=at_mdb, with_roll=args.with_roll or args.mount_roll_sigma_deg > 0)
    write_mirror_csv(args.out, data)
    sigma = math.hypot(args.theodolite_sigma_arcsec, args.ins_sigma_arcsec)
    if args.truth:
        write_text(args.truth, synth.truth_report(
            "collimation", args.seed, truth, ce.display_unit, angle_sigma_arcsec=sigma))
    shown = {k: v / ce.display_unit(k)[1] for k, v in truth.items()
             if k != "frame_heading" and v != 0.0}
    print(f"wrote {args.out}: {len(data.mirror)} mirrors, seed {args.seed}; diagnose with "
          f"--angle-sigma-arcsec {sigma:.4g}; injected: "
          + (", ".join(f"{k} = {v:.4g}{_unit(ce.display_unit(k)[0])}" for k, v in shown.items())
             or "nothing"))
    return 0


def refraction_option(p: argparse.ArgumentParser, text: str) -> None:
    p.add_argument("--refraction-k", type=number(float, low=-5.0, high=5.0), default=0.13,
                   metavar="K", help=f"{text} [1] (default 0.13, Gauss's standard value)")


def _synth_procedure(args: argparse.Namespace) -> int:
    """``synth collimation --readings reference``: one calibration by the paper's procedure."""
    from montecarlo.cli.collimation import _angle_list
    from montecarlo.discrepancy import collimation_effects as ce
    from montecarlo.discrepancy import procedure_effects as pe
    from montecarlo.discrepancy import synth
    from montecarlo.io.collimation_csv import write_mirror_csv
    from montecarlo.seed003.model import Noise
    from montecarlo.seed003.reference import SIDES

    rows = not args.no_reference_rows
    if args.with_roll and not rows:
        raise InputError("--with-roll: only with reference rows (relative files carry no roll)")
    azimuths = _angle_list("--azimuths-deg", args.azimuths_deg or "-30,-15,15,30,45")
    pitches = _angle_list("--pitch-elevations-deg", args.pitch_elevations_deg
                          or "4,7.5,11,14.5,18")
    if len(azimuths) + len(pitches) < pe.min_mirrors():
        raise InputError(f"--azimuths-deg, --pitch-elevations-deg: at least {pe.min_mirrors()} "
                         "mirrors needed")
    axis = next(c for c in ce.CANDIDATES if c.name == "axis_misalignment")
    candidates = {axis.name: axis, **{c.name: c for c in pe.CANDIDATES}}
    effects = synth.parse_effects(args.effect, candidates, pe.display_unit)
    side = SIDES[args.roll_mirror or "right"]
    layout = pe.paper_layout(rows, azimuths, pitches, side)
    at_mdb = synth.parse_multiples(args.at_mdb, {**{c.name: c for c in pe.CANDIDATES},
                                                 pe.ROLL: pe.roll_effect(layout)})
    ins = args.ins_sigma_arcsec * ARCSEC
    noise = Noise(args.theodolite_sigma_arcsec * ARCSEC, ins, ins, ins,
                  math.radians(args.mount_roll_sigma_deg))
    data, truth = synth.synth_procedure(
        seed=args.seed, layout=layout,
        frame_heading=math.radians(args.frame_heading_deg), noise=noise, effects=effects,
        at_mdb=at_mdb, side=side,
        with_roll=args.with_roll or (rows and args.mount_roll_sigma_deg > 0))
    write_mirror_csv(args.out, data)
    sigma = math.hypot(args.theodolite_sigma_arcsec, args.ins_sigma_arcsec)
    if args.truth:
        write_text(args.truth, synth.truth_report(
            "collimation", args.seed, truth, pe.display_unit, angle_sigma_arcsec=sigma,
            readings="reference", reference_rows=rows, roll_mirror=args.roll_mirror or "right"))
    shown = {k: v / pe.display_unit(k)[1] for k, v in truth.items()
             if k != "frame_heading" and v != 0.0}
    print(f"wrote {args.out}: {len(data.mirror)} rows ("
          + ("absolute readings with the two reference rows" if rows
             else "readings relative to the reference") + f"), seed {args.seed}; diagnose with "
          f"--angle-sigma-arcsec {sigma:.4g}; injected: "
          + (", ".join(f"{k} = {v:.4g}{_unit(pe.display_unit(k)[0])}" for k, v in shown.items())
             or "nothing"))
    return 0


def add_commands(sub: argparse._SubParsersAction) -> None:
    diag = sub.add_parser("diagnose", help="detect, identify and adapt a missing effect in "
                          "measured data")
    dsub = diag.add_subparsers(dest="diagnose_command", required=True, parser_class=Parser)

    def basic(p: argparse.ArgumentParser) -> None:
        add_json_option(p, "the diagnosis")
        p.add_argument("--alpha", type=probability, default=0.01,
                       help="significance of the tests (default 0.01)")

    def common(p: argparse.ArgumentParser) -> None:
        basic(p)
        p.add_argument("--report", metavar="DIR", help="write report.md, diagnosis.json and "
                       "plots (residuals, gap, Monte Carlo of the residual statistic)")
        p.add_argument("--trials", type=nonnegative_int, default=200,
                       help="Monte Carlo data sets per model in --report (default 200; 0: none)")
        p.add_argument("--seed", type=nonnegative_int, default=0,
                       help="seed of the --report and --identifiability Monte Carlo (default 0)")
        p.add_argument("--identifiability", action="store_true",
                       help="also the PCI and the MIB of each candidate, by Monte Carlo of "
                       "the linearised first step on the data's design (seconds)")
        p.add_argument("--pci-target", type=probability, default=0.8,
                       help="PCI at which the MIB is stated (default 0.8)")
        p.add_argument("--sets", type=positive_int, default=10_000,
                       help="simulated whitened misclosure vectors per size for "
                       "--identifiability (default 10000)")
        p.add_argument("--check-sets", type=nonnegative_int, default=0, metavar="N",
                       help="with --identifiability: also the nonlinear Monte Carlo (the "
                       "whole diagnosis of N simulated data sets per size) at each "
                       "candidate's PCI size and linear MIB, as a check (default 0: none; "
                       "costly: 2 N diagnoses a candidate)")
        add_n_jobs_option(p)

    p = dsub.add_parser("ground", help="targets surveyed in frame b observed by the sensor")
    p.add_argument("data", help="CSV: target, x_m, y_m, z_m, px, pz[, t_s][, session]")
    p.add_argument("--fov-deg", type=field_of_view, nargs=2, required=True, metavar=("FY", "FP"),
                   help="full fields of view about z (yaw) and x (pitch) [deg]")
    p.add_argument("--pixels", type=positive_int, nargs=2, required=True,
                   metavar=("NX", "NZ"), help="pixel counts across x and z")
    p.add_argument("--pixel-sigma-px", type=positive_or_auto, required=True, metavar="S",
                   help="standard deviation of each image coordinate [px]" + AUTO_HELP)
    p.add_argument("--survey-sigma-m", type=nonnegative_or_auto, default=0.0, metavar="S",
                   help="standard deviation of each surveyed coordinate [m] (default 0)"
                   + AUTO_HELP + "; both auto: REML variance components")
    refraction_option(p, "standard coefficient of refraction of the base model, which also "
                      "has earth curvature")
    common(p)
    p.set_defaults(func=_cmd_diagnose_ground)

    p = dsub.add_parser("collimation", help="autocollimator-INS mirror readings (seed 003)")
    p.add_argument("data", help="CSV: mirror, set, theodolite_az_deg, theodolite_el_deg, "
                   "ins_az_deg, ins_el_deg[, ins_roll_deg]")
    p.add_argument("--angle-sigma-arcsec", type=positive_or_auto, required=True, metavar="S",
                   help="standard deviation of a heading or pitch difference, theodolite and "
                   "INS combined [arc-seconds]; under --readings reference each angle of the "
                   "file is taken to err by S/sqrt(2) and the relative readings' covariance "
                   "is propagated from that" + AUTO_HELP)
    p.add_argument("--readings", choices=("reference", "absolute"), default="reference",
                   help="reference (default): the paper's procedure, readings relative to the "
                   "INS's reference (reference rows, or relative readings); absolute: the "
                   "absolute-reading model")
    p.add_argument("--roll-mirror", choices=("auto", "right", "left"), default=None,
                   help="side of the roll reference mirror (--readings reference): auto "
                   "(default) takes the side the data support; right (the paper's text) or left "
                   "as stated, with a warning when the data reject it")
    p.add_argument("--azimuth-sense", choices=("auto", "same", "opposite"), default=None,
                   help="theodolite azimuth turning the same way as the INS heading or not "
                   "(--readings reference; auto by default)")
    p.add_argument("--roll-sigma-deg", type=positive, default=None, metavar="DEG",
                   help="size (1σ) of an unrecorded INS roll, the ins_roll candidate's prior "
                   "(--readings reference; default 2)")
    common(p)
    p.set_defaults(func=_cmd_diagnose_collimation)

    p = dsub.add_parser("stabilization", help="gyro indirect-stabilisation run (seed 001): "
                        "the estimator's model against a scale factor, delays, the camera mount")
    p.add_argument("data", help="CSV: t_s, gyro_x, gyro_y, gyro_z, eta_rad, eps_rad, "
                   "los_x_px, los_z_px")
    p.add_argument("--fov-deg", type=field_of_view, default=5.0,
                   help="square field of view [deg] (5)")
    p.add_argument("--pixels", type=positive_int, default=1024,
                   help="pixels across the image (1024)")
    p.add_argument("--image-noise-px", type=positive_or_auto, default=0.1,
                   help="image noise per axis [px] (0.1)" + AUTO_HELP + " (the gyro walk "
                   "known)")
    p.add_argument("--gyro-arw-deg-per-rt-h", type=nonnegative, default=0.01,
                   help="gyro angle random walk [deg/sqrt(h)] (0.01; 0: no LOS walk)")
    p.add_argument("--mount", choices=("patent", "inner-gimbal"), default="patent",
                   help="camera mount of the base model (patent)")
    p.add_argument("--gyro-sampling", choices=("point", "interval-mean"), default="point",
                   help="what a gyro row holds (point)")
    basic(p)
    p.set_defaults(func=_cmd_diagnose_stabilization)

    add_diagnose_parser(dsub, basic)

    syn = sub.add_parser("synth", help="write a measured-like data set with chosen effects")
    ssub = syn.add_subparsers(dest="synth_command", required=True, parser_class=Parser)

    def effect_options(p: argparse.ArgumentParser) -> None:
        p.add_argument("out", help="CSV file to write")
        p.add_argument("--seed", type=nonnegative_int, default=0)
        p.add_argument("--effect", action="append", default=[], metavar="NAME=V[,V...]",
                       help="inject an effect, one value per parameter in report units "
                       "(repeatable)")
        p.add_argument("--at-mdb", action="append", default=[], metavar="NAME=MULT",
                       help="inject an effect at MULT times its minimal detectable bias "
                       "(repeatable)")
        p.add_argument("--truth", metavar="OUT.json", help="also write how the data were made")
        add_force_option(p)

    p = ssub.add_parser("ground", help="targets spread over the field at several ranges")
    effect_options(p)
    p.add_argument("--fov-deg", type=field_of_view, nargs=2, default=[90.0, 90.0])
    p.add_argument("--pixels", type=positive_int, nargs=2, default=[512, 512])
    p.add_argument("--pixel-sigma-px", type=nonnegative, default=0.3, help="[px] (0.3)")
    p.add_argument("--survey-sigma-m", type=nonnegative, default=0.01, help="[m] (0.01)")
    p.add_argument("--mounting-deg", type=finite, nargs=3, default=[30.0, 20.0, 10.0],
                   metavar=("PSI", "THETA", "GAMMA"), help="true mounting (seed 000: 30 20 10)")
    p.add_argument("--ranges-m", type=positive, nargs="+", default=[50.0, 100.0])
    p.add_argument("--grid", type=positive_int, nargs=2, default=[6, 6],
                   metavar=("NX", "NZ"), help="targets across and up the field (6 6)")
    p.add_argument("--spread", type=positive, default=0.8,
                   help="fraction of the field covered (0.8)")
    p.add_argument("--duration-s", type=nonnegative, default=3600.0)
    p.add_argument("--sessions", type=positive_int, default=1,
                   help="observe the layout in this many sessions (session column if > 1)")
    refraction_option(p, "coefficient of refraction of the data, which also have earth "
                      "curvature; --effect refraction=DK adds DK")
    p.add_argument("--no-time", action="store_true", help="omit the t_s column")
    p.set_defaults(func=_cmd_synth_ground)

    p = ssub.add_parser("collimation", help="seed 003 fixture: azimuth and pitch mirrors")
    effect_options(p)
    p.add_argument("--readings", choices=("reference", "absolute"), default="reference",
                   help="reference (default): the paper's procedure (reference mirrors at 0 and "
                   "±90°, --azimuths-deg, --pitch-elevations-deg); absolute: the "
                   "absolute-reading model on --n-azimuth/--n-pitch mirrors")
    p.add_argument("--azimuths-deg", default=None,
                   help="horizontal mirrors (reference readings; default -30,-15,15,30,45)")
    p.add_argument("--pitch-elevations-deg", default=None,
                   help="pitch mirrors at azimuth 0 (reference readings; default "
                   "4,7.5,11,14.5,18)")
    p.add_argument("--roll-mirror", choices=("right", "left"), default=None,
                   help="side of the roll reference mirror (reference readings; right)")
    p.add_argument("--no-reference-rows", action="store_true",
                   help="write readings relative to the reference, without the reference rows")
    p.add_argument("--n-azimuth", type=positive_int, default=None,
                   help="absolute readings (default 7)")
    p.add_argument("--n-pitch", type=positive_int, default=None,
                   help="absolute readings (default 7)")
    p.add_argument("--azimuth-span-deg", type=finite, default=None,
                   help="absolute readings (default 90)")
    p.add_argument("--pitch-span-deg", type=finite, default=None,
                   help="absolute readings (default 60)")
    p.add_argument("--frame-heading-deg", type=finite, default=30.0)
    p.add_argument("--theodolite-sigma-arcsec", type=nonnegative, default=2.0)
    p.add_argument("--ins-sigma-arcsec", type=nonnegative, default=2.0)
    p.add_argument("--mount-roll-sigma-deg", type=nonnegative, default=0.0)
    p.add_argument("--with-roll", action="store_true", help="write the ins_roll_deg column")
    p.set_defaults(func=_cmd_synth_collimation)
