"""The discrepancy workflow: ``diagnose ground | collimation | stabilization | camera``
(stabilization in :mod:`montecarlo.cli.stabilization`, camera in :mod:`montecarlo.cli.camera`;
the data sets to try it on: :mod:`montecarlo.cli.synth`)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import TYPE_CHECKING

from montecarlo.cli.camera import add_diagnose_parser
from montecarlo.cli.common import (
    Parser,
    add_json_option,
    add_n_jobs_option,
    check_json_option,
    emit_json,
    field_of_view,
    nonnegative_int,
    positive,
    positive_int,
    probability,
    refraction_option,
    write_provenance,
)
from montecarlo.cli.noise_options import (
    AUTO,
    AUTO_HELP,
    diagnose_collimation,
    diagnose_ground,
    nonnegative_or_auto,
    positive_or_auto,
)
from montecarlo.cli.stabilization import (
    add_diagnose_parser as add_stabilization_diagnose_parser,
)
from montecarlo.cli.steps import Steps, fit_why
from montecarlo.errors import InputError
from montecarlo.io.files import OutputDir
from montecarlo.units import ARCSEC

if TYPE_CHECKING:
    from collections.abc import Sequence

    from montecarlo.discrepancy.engine import Diagnosis
    from montecarlo.discrepancy.view import SystemView
    from montecarlo.io.collimation_csv import MirrorData


START_IMAGE_NOISE = 0.1
"""Image noise [px] the estimator's start and the first pass use under ``auto``."""


def _check_outputs(args: argparse.Namespace) -> None:
    """Refuse, before any work, a --report directory or --json file that cannot be written,
    --check-sets without --identifiability, --identifiability with a noise left to ``auto``
    (its rates are those of the tests at a known noise) and --leave-one-out on the
    procedure's relative readings (which share the reference readings' errors)."""
    if getattr(args, "check_sets", 0) and not args.identifiability:
        raise InputError("--check-sets: only with --identifiability")
    if args.leave_one_out and getattr(args, "readings", None) == "reference":
        raise InputError("--leave-one-out: only with --readings absolute (under the procedure "
                         "every relative reading shares the reference readings' errors, so "
                         "one mirror cannot be left out on its own)")
    if getattr(args, "identifiability", False):
        for flag in ("pixel_sigma_px", "survey_sigma_m", "angle_sigma_arcsec"):
            if getattr(args, flag, None) == "auto":
                raise InputError(f"--identifiability: needs --{flag.replace('_', '-')} stated "
                                 "(not auto): its rates are those of the tests at a known "
                                 "noise; state the value auto estimated")
    if args.report:
        OutputDir(args.report, "diagnose", inputs=(Path(args.data),)).check()
    check_json_option(args)


def _diagnosis_output(args: argparse.Namespace, d: Diagnosis, view: SystemView,
                      source: str, steps: Steps, extra: dict | None = None,
                      preface: tuple[str, ...] = (),
                      groups: tuple[str, Sequence[str]] | None = None) -> int:
    """Print or write the diagnosis; ``groups``: (kind, the label of each observation) for the
    test of residuals clustering by group and for --leave-one-out."""
    from montecarlo.discrepancy.groups import clustering_by, format_clustering
    from montecarlo.discrepancy.view import format_text, to_json
    from montecarlo.output.provenance import provenance

    report = {**to_json(d, view, source), **(extra or {})}
    grouped = None if groups is None else clustering_by(d, *groups)
    if grouped is not None:
        report["clustering"] = grouped
    loo_text, loo_md = _leave_one_out(d, view, groups, report, steps) \
        if args.leave_one_out and groups is not None else ([], [])
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
                write_report(staging, d, view, report, mc, args.trials, args.seed, loo_md)
            write_provenance(staging, "diagnose", **record)
            write_html_report(staging, d, view, mc)
    if emit_json(args, {**report, "provenance": provenance("diagnose", **record)}):
        steps.report(to_stderr=True)
        return 0
    print("\n".join([*preface, format_text(report),
                     *([format_clustering(report["clustering"])] if "clustering" in report
                       else []), *loo_text]))
    if "identifiability" in report:
        from montecarlo.systems.identifiability import format_table

        print(format_table(report))
    if args.report:
        print(f"report written to {args.report}/ (report.md, report.html, diagnosis.json, "
              "residuals.png, gap.png)")
    steps.report(to_stderr=False)
    return 0


def _leave_one_out(d: Diagnosis, view: SystemView, groups: tuple[str, Sequence[str]],
                   report: dict, steps: Steps) -> tuple[list[str], list[str]]:
    """--leave-one-out: each group (target, mirror) predicted from the others, with and without
    each named effect, beside the effects' practical significance in sample; into ``report``
    (keys ``leave_one_out``, ``practical_significance``); the text and Markdown lines."""
    from montecarlo.discrepancy.groups import label_groups
    from montecarlo.discrepancy.out_of_sample import (
        format_leave_one_out,
        leave_one_group_out,
        markdown_leave_one_out,
        no_table,
    )
    from montecarlo.discrepancy.significance import format_significance, practical_significance

    kind, labels = groups
    members = label_groups(labels)
    why = no_table(d, members, kind)
    if why is not None:
        report["leave_one_out"] = {"kind": kind, "groups": list(members), "no_table": why}
        return [why], [why, ""]
    significance = practical_significance(d, view)
    with steps(f"leave one {kind} out", f"a fit per {kind} and model, {len(members)} "
               f"{kind}s"):
        loo = leave_one_group_out(d, view, members, kind)
    report.update({"practical_significance": significance, "leave_one_out": loo})
    return ([format_significance(significance), format_leave_one_out(loo, significance)],
            markdown_leave_one_out(loo, significance))


def _cmd_diagnose_ground(args: argparse.Namespace) -> int:
    steps = Steps()
    with steps.loading():
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
    with steps.loading():
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


def add_commands(sub: argparse._SubParsersAction) -> None:
    diag = sub.add_parser("diagnose", help="detect, identify and adapt a missing effect in "
                          "measured data")
    dsub = diag.add_subparsers(dest="diagnose_command", required=True, parser_class=Parser)

    def basic(p: argparse.ArgumentParser) -> None:
        add_json_option(p, "the diagnosis")
        p.add_argument("--alpha", type=probability, default=0.01,
                       help="significance of the tests (default 0.01)")

    def common(p: argparse.ArgumentParser, kind: str, extra: str = "") -> None:
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
        p.add_argument("--leave-one-out", action="store_true", help="out-of-sample evidence: "
                       f"refit the final model (and it without each named effect) on all "
                       f"{kind}s but one and predict that {kind}, for each {kind}; an effect "
                       "predicts when leaving it out raises the prediction error (paired t "
                       f"test over the {kind}s at --alpha)" + extra)
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
    common(p, "target")
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
    common(p, "mirror", "; only with --readings absolute")
    p.set_defaults(func=_cmd_diagnose_collimation)

    add_stabilization_diagnose_parser(dsub, basic)
    add_diagnose_parser(dsub, basic)
