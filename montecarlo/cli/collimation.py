"""Seed 003: ``collimation fit | simulate | figures``."""

from __future__ import annotations

import argparse
import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from montecarlo.cli.common import (
    Parser,
    add_json_option,
    check_json_option,
    emit_json,
    finite,
    nonnegative,
    nonnegative_int,
    positive,
    write_provenance,
)
from montecarlo.errors import InputError
from montecarlo.io.files import OutputDir, writable_file
from montecarlo.units import ARCSEC

if TYPE_CHECKING:
    from montecarlo.io.collimation_csv import MirrorData
    from montecarlo.seed003.conventions import Choice
    from montecarlo.seed003.fit import Fit
    from montecarlo.seed003.procedure import ProcedureData, ProcedureFit


def _cmd_collimation_fit(args: argparse.Namespace) -> int:
    from montecarlo.io.collimation_csv import REFERENCE_SETS, SETS, read_mirror_csv
    from montecarlo.seed003.fit import NotSeparable, fit, min_mirrors
    from montecarlo.seed003.model import BASE_EFFECTS, parameter_names

    check_json_option(args)
    if args.readings == "reference":
        return _fit_reference(args)
    for flag, used in (("--free-roll", args.free_roll), ("--roll-mirror", args.roll_mirror),
                       ("--azimuth-sense", args.azimuth_sense), ("--verify", args.verify),
                       ("--roll-sigma-deg", args.roll_sigma_deg),
                       ("--ins-sigma-arcsec", args.ins_sigma_arcsec),
                       ("--theodolite-sigma-arcsec", args.theodolite_sigma_arcsec)):
        if used is not None and used is not False:
            raise InputError(f"{flag}: only with --readings reference")
    effects = BASE_EFFECTS + (("frame_misalignment",) if args.fit_frame_tilt else ())
    n = len(parameter_names(effects))
    readings = read_mirror_csv(args.data, min_mirrors(n), f"{n} parameters",
                               sets=SETS + REFERENCE_SETS)
    sigma = None if args.angle_sigma_arcsec is None else args.angle_sigma_arcsec * ARCSEC
    try:
        result = fit(readings.theodolite_az, readings.theodolite_el, readings.ins_az,
                     readings.ins_el, readings.ins_roll, sigma=sigma, effects=effects)
    except NotSeparable as exc:
        raise InputError(f"{args.data}: {exc}") from None
    report = fit_report(readings, result, str(args.data))
    if args.json is not None:
        from montecarlo.output.provenance import provenance

        record = provenance("collimation fit", input=str(args.data),
                            angle_sigma_arcsec=args.angle_sigma_arcsec, effects=list(effects))
        if emit_json(args, {**report, "provenance": record}):
            return 0
    print(format_report(report))
    return 0


def _fit_reference(args: argparse.Namespace) -> int:
    """``collimation fit --readings reference``: seed 003's procedure (section 3.2)."""
    import sys

    from montecarlo.io.collimation_csv import REFERENCE_SETS, SETS, procedure_data, read_mirror_csv
    from montecarlo.seed003.conventions import fit_with_conventions
    from montecarlo.seed003.procedure import NotDetermined

    if args.fit_frame_tilt:
        raise InputError("--fit-frame-tilt: only with --readings absolute (under the procedure "
                         "a frame tilt is degenerate with lambda)")
    readings = read_mirror_csv(args.data, 2, "gamma and lambda", sets=SETS + REFERENCE_SETS)
    data = procedure_data(readings)
    sigmas = _reference_sigmas(args)
    roll_sigma = math.radians(2.0 if args.roll_sigma_deg is None else args.roll_sigma_deg)
    try:
        result, used, choices = fit_with_conventions(
            data, side=args.roll_mirror or "auto", sense=args.azimuth_sense or "auto",
            free_roll=args.free_roll, roll_sigma=roll_sigma, sigma_ins=sigmas[0],
            sigma_theodolite=sigmas[1])
    except NotDetermined as exc:
        raise InputError(f"{args.data}: {exc}") from None
    report = reference_report(readings, used, result, str(args.data), args.free_roll,
                              roll_sigma, choices)
    if args.verify == "leave-one-out":
        from montecarlo.seed003.verification import leave_one_out

        try:
            check = leave_one_out(used, side=result.side, free_roll=args.free_roll,
                                  roll_sigma=roll_sigma, sigma_ins=result.sigma_ins,
                                  sigma_theodolite=result.sigma_theodolite)
        except NotDetermined as exc:
            raise InputError(f"{args.data}: --verify leave-one-out: {exc}") from None
        report["verification"] = verification_report(
            check, [m["mirror"] for m in report["mirrors"]], "leave-one-out")
    for choice in choices.values():
        line = choice.warning()
        if line:
            print(line, file=sys.stderr)
    if args.json is not None:
        from montecarlo.output.provenance import provenance

        record = provenance("collimation fit", input=str(args.data), readings="reference",
                            free_roll=args.free_roll, roll_mirror=args.roll_mirror or "auto",
                            azimuth_sense=args.azimuth_sense or "auto",
                            roll_sigma_deg=math.degrees(roll_sigma),
                            angle_sigma_arcsec=args.angle_sigma_arcsec,
                            ins_sigma_arcsec=args.ins_sigma_arcsec,
                            theodolite_sigma_arcsec=args.theodolite_sigma_arcsec,
                            verify=args.verify)
        if emit_json(args, {**report, "provenance": record}):
            return 0
    print(format_reference_report(report))
    return 0


def verification_report(check, mirrors: list[str], kind: str) -> dict[str, object]:
    """JSON-ready out-of-sample deviations (arc-seconds) and the 15″ verdict on them."""
    from montecarlo.seed003.procedure import CLAIM

    rows = []
    for i, name in enumerate(mirrors):
        rows.append({"mirror": name,
                     "axis_az_arcsec": float(check.offsets[i, 0] / ARCSEC),
                     "axis_el_arcsec": float(check.offsets[i, 1] / ARCSEC),
                     "deviation_az_arcsec": float(check.deviation_az[i] / ARCSEC),
                     "deviation_el_arcsec": float(check.deviation_el[i] / ARCSEC)})
    return {"kind": kind, "in_sample": False, "mirrors": rows,
            "claim_15_arcsec": {"max_deviation_arcsec": check.max_deviation / ARCSEC,
                                "holds": check.holds, "limit_arcsec": CLAIM / ARCSEC}}


def _cmd_collimation_verify(args: argparse.Namespace) -> int:
    """``collimation verify FIT.json NEW.csv``: a saved fit applied to another data set."""
    import json

    import numpy as np

    from montecarlo.io.collimation_csv import REFERENCE_SETS, SETS, procedure_data, read_mirror_csv
    from montecarlo.seed003.conventions import SENSES, with_sense
    from montecarlo.seed003.procedure import NotDetermined
    from montecarlo.seed003.reference import SIDES
    from montecarlo.seed003.verification import verify

    check_json_option(args)
    try:
        saved = json.loads(Path(args.fit).read_text())
    except OSError as exc:
        raise InputError(f"{args.fit}: cannot read ({exc.strerror})") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{args.fit}: not JSON ({exc.msg}, line {exc.lineno})") from None
    try:
        if saved.get("readings") != "reference":
            raise KeyError("readings")
        gamma = float(saved["parameters"]["axis_az"]) * ARCSEC
        lam = float(saved["parameters"]["axis_el"]) * ARCSEC
        side = SIDES[saved["roll_mirror"]["chosen"]]
        sense = saved["azimuth_sense"]["chosen"]
        SENSES[sense]
        settings = saved["settings"]
        free_roll = bool(settings["free_roll"])
        roll_sigma = math.radians(float(settings["roll_sigma_deg"]))
        s_ins = float(saved["sigma_arcsec"]["ins"]) * ARCSEC
        s_theo = float(saved["sigma_arcsec"]["theodolite"]) * ARCSEC
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise InputError(f"{args.fit}: not a fit saved by 'collimation fit --json' under "
                         f"--readings reference (field {exc})") from None
    readings = read_mirror_csv(args.data, 1, "one mirror", sets=SETS + REFERENCE_SETS)
    data = with_sense(procedure_data(readings), sense)
    if not data.measured.size:
        raise InputError(f"{args.data}: no measured (azimuth/pitch) mirror")
    try:
        check = verify(data, gamma, lam, side=side, free_roll=free_roll, roll_sigma=roll_sigma,
                       sigma_ins=s_ins, sigma_theodolite=s_theo)
    except (NotDetermined, np.linalg.LinAlgError) as exc:
        raise InputError(f"{args.data}: the saved offsets cannot be applied ({exc})") from None
    names = [readings.mirror[i] for i in data.measured]
    report = {"system": "collimation", "fit": str(args.fit), "file": str(args.data),
              "axis_az_arcsec": gamma / ARCSEC, "axis_el_arcsec": lam / ARCSEC,
              **verification_report(check, names, "new data set")}
    if args.json is not None:
        from montecarlo.output.provenance import provenance

        record = provenance("collimation verify", fit=str(args.fit), input=str(args.data))
        if emit_json(args, {**report, "provenance": record}):
            return 0
    print(format_verification(report))
    return 0


def format_verification(report: Mapping[str, object]) -> str:
    """Text of an out-of-sample check (:func:`verification_report`)."""
    claim = report["claim_15_arcsec"]
    head = ("offsets fitted without the mirror, applied to it" if report["kind"] ==
            "leave-one-out" else f"offsets of {report.get('fit')} applied to {report.get('file')}")
    lines = [f"out-of-sample check ({report['kind']}): {head}",
             f"{'mirror':>8} {'γ used″':>9} {'λ used″':>9} {'dev az″':>8} {'dev el″':>8}"]
    for m in report["mirrors"]:
        lines.append(f"{m['mirror']:>8} {m['axis_az_arcsec']:9.1f} {m['axis_el_arcsec']:9.1f} "
                     f"{m['deviation_az_arcsec']:8.2f} {m['deviation_el_arcsec']:8.2f}")
    lines.append(f"largest out-of-sample deviation {claim['max_deviation_arcsec']:.2f}″ -> the "
                 "paper's 15″ claim " + ("holds" if claim["holds"] else "DOES NOT HOLD")
                 + " out of sample")
    return "\n".join(lines)


def _reference_sigmas(args: argparse.Namespace) -> tuple[float | None, float | None]:
    """(INS, theodolite) reading sigma [rad] from the options; (None, None): a posteriori."""
    ins, theo = args.ins_sigma_arcsec, args.theodolite_sigma_arcsec
    if args.angle_sigma_arcsec is not None:
        if ins is not None or theo is not None:
            raise InputError("--angle-sigma-arcsec: give it or --ins-sigma-arcsec/"
                             "--theodolite-sigma-arcsec, not both")
        ins = theo = args.angle_sigma_arcsec / math.sqrt(2.0)
    if ins is None and theo is None:
        return None, None
    ins, theo = (ins or 0.0) * ARCSEC, (theo or 0.0) * ARCSEC
    if ins == 0.0 and theo == 0.0:
        raise InputError("--ins-sigma-arcsec, --theodolite-sigma-arcsec: at least one must be > 0")
    return ins, theo


def _cmd_collimation_simulate(args: argparse.Namespace) -> int:
    from montecarlo.io.collimation_csv import MirrorData, write_mirror_csv
    from montecarlo.seed003.model import Noise, paper_layout, simulate_readings

    layout = {"--n-azimuth": args.n_azimuth, "--n-pitch": args.n_pitch,
              "--azimuth-span-deg": args.azimuth_span_deg,
              "--pitch-span-deg": args.pitch_span_deg}
    if args.readings == "reference":
        given = ", ".join(f"{k} {v:g}" for k, v in layout.items() if v is not None)
        if given:
            raise InputError(f"{given}: only with --readings absolute (the procedure's mirrors "
                             "are --azimuths-deg and --pitch-elevations-deg)")
        return _simulate_reference(args)
    for key, default in (("n_azimuth", 5), ("n_pitch", 5), ("azimuth_span_deg", 90.0),
                         ("pitch_span_deg", 60.0)):
        if getattr(args, key) is None:
            setattr(args, key, default)
    if args.n_azimuth + args.n_pitch == 0:
        raise InputError("--n-azimuth, --n-pitch: no mirrors to simulate (both are 0)")
    writable_file(args.out)
    az, el, sets = paper_layout(args.n_azimuth, args.n_pitch, math.radians(args.azimuth_span_deg),
                                math.radians(args.pitch_span_deg))
    truth = {"axis_az": args.axis_az_arcsec * ARCSEC, "axis_el": args.axis_el_arcsec * ARCSEC,
             "frame_heading": math.radians(args.frame_heading_deg)}
    ins = args.ins_sigma_arcsec * ARCSEC
    noise = Noise(theodolite=args.theodolite_sigma_arcsec * ARCSEC, ins_heading=ins,
                  ins_pitch=ins, ins_roll=ins, mount_roll=math.radians(args.mount_roll_sigma_deg))
    sim = simulate_readings(truth, az, el, noise, args.seed)
    names = tuple([f"A{i + 1}" for i in range(args.n_azimuth)]
                  + [f"P{i + 1}" for i in range(args.n_pitch)])
    data = MirrorData(names, tuple(sets.tolist()), sim["theodolite_az"], sim["theodolite_el"],
                      sim["ins_az"], sim["ins_el"], sim["ins_roll"] if args.with_roll else None)
    write_mirror_csv(args.out, data)
    print(f"wrote {args.out}: {len(names)} mirrors, seed {args.seed}, axis_az "
          f"{args.axis_az_arcsec}″, axis_el {args.axis_el_arcsec}″, frame_heading "
          f"{args.frame_heading_deg}°")
    return 0


def _angle_list(option: str, text: str) -> list[float]:
    """Comma-separated degrees -> radians; one line naming the option on bad input."""
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise InputError(f"{option} {text!r}: comma-separated numbers expected") from None
    if not all(math.isfinite(v) and -90.0 < v < 90.0 for v in values):
        raise InputError(f"{option} {text!r}: angles must lie in (-90, 90) degrees")
    return [math.radians(v) for v in values]


def _simulate_reference(args: argparse.Namespace) -> int:
    """``collimation simulate --readings reference``: one calibration by the paper's procedure."""
    import numpy as np

    from montecarlo.io.collimation_csv import MirrorData, write_mirror_csv
    from montecarlo.seed003.model import Noise
    from montecarlo.seed003.procedure import procedure_layout, simulate_procedure
    from montecarlo.seed003.reference import SIDES

    azimuths = _angle_list("--azimuths-deg", args.azimuths_deg)
    pitches = _angle_list("--pitch-elevations-deg", args.pitch_elevations_deg)
    if len(azimuths) + len(pitches) < 2:
        raise InputError("--azimuths-deg, --pitch-elevations-deg: at least 2 mirrors needed")
    writable_file(args.out)
    az, el, sets = procedure_layout(azimuths, pitches)
    ins = args.ins_sigma_arcsec * ARCSEC
    noise = Noise(theodolite=args.theodolite_sigma_arcsec * ARCSEC, ins_heading=ins,
                  ins_pitch=ins, ins_roll=ins, mount_roll=math.radians(args.mount_roll_sigma_deg))
    rows = not args.no_reference_rows
    sim = simulate_procedure(args.axis_az_arcsec * ARCSEC, args.axis_el_arcsec * ARCSEC, az, el,
                             noise, args.seed, side=SIDES[args.roll_mirror],
                             frame_heading=math.radians(args.frame_heading_deg),
                             reference_rows=rows, with_roll=args.with_roll)
    names = [f"A{i + 1}" for i in range(len(azimuths))] + [f"P{i + 1}" for i in range(len(pitches))]
    kinds = list(sets)
    if rows:
        names, kinds = ["C", "R", *names], ["reference_center", "reference_roll", *kinds]
    data = MirrorData(tuple(names), tuple(kinds), sim.theodolite_az, sim.theodolite_el,
                      sim.ins_az, sim.ins_el, sim.ins_roll)
    write_mirror_csv(args.out, data)
    print(f"wrote {args.out}: {len(names)} rows ("
          + ("absolute readings with the two reference rows" if rows
             else "readings relative to the reference") + f"), seed {args.seed}, axis_az "
          f"{args.axis_az_arcsec}″, axis_el {args.axis_el_arcsec}″, roll mirror "
          f"{args.roll_mirror}, mount roll σ {args.mount_roll_sigma_deg}°"
          + ("" if np.isfinite(sim.ins_az).all() else " (some pointings unreachable)"))
    return 0


def _cmd_collimation_figures(args: argparse.Namespace) -> int:
    from montecarlo.io.files import save_figure
    from montecarlo.seed003.figures import pair_figures, paper_statements, procedure_figure

    with OutputDir(args.outdir, "collimation figures") as staging:
        for name, fig in {**pair_figures(), "procedure": procedure_figure()}.items():
            save_figure(fig, staging / f"{name}.png")
        write_provenance(staging, "collimation figures")
    print(f"wrote {args.outdir}/fig3.png ... fig6.png, procedure.png")
    print("seed 003, section 2 statements, evaluated with offsets of 0.1° (level mount):")
    for row in paper_statements():
        verdict = "holds" if row["holds"] else "DOES NOT HOLD"
        print(f"  {row['statement']}: {row['quantity']} = {row['model']:.4g} -> {verdict}")
    return 0


def add_commands(sub: argparse._SubParsersAction) -> None:
    col = sub.add_parser("collimation", help="autocollimator-INS axis calibration (seed 003)")
    csub = col.add_subparsers(dest="collimation_command", required=True, parser_class=Parser)

    p = csub.add_parser("fit", help="fit the optical-axis offsets to a calibration CSV")
    p.add_argument("data", help="CSV: mirror, set, theodolite_az_deg, theodolite_el_deg, "
                   "ins_az_deg, ins_el_deg[, ins_roll_deg]")
    add_json_option(p, "the offsets, residuals and corrected readings")
    p.add_argument("--angle-sigma-arcsec", type=positive, metavar="S",
                   help="known sigma of each heading/pitch residual (default: from residuals)")
    p.add_argument("--fit-frame-tilt", action="store_true",
                   help="also fit the tilt of the theodolite frame against the INS level "
                   "(--readings absolute only)")
    p.add_argument("--readings", choices=("reference", "absolute"), default="reference",
                   help="reference (default): the paper's procedure, readings relative to the "
                   "reference the INS sets up at the central and the roll mirror; absolute: "
                   "absolute heading and pitch, theodolite frame linked by a heading only")
    p.add_argument("--free-roll", action="store_true",
                   help="fit one INS roll per pointing (prior N(0, --roll-sigma-deg))")
    p.add_argument("--roll-mirror", choices=("auto", "right", "left"), default=None,
                   help="side of the roll reference mirror: auto (default) fits both and takes "
                   "the one the data support; right (the paper's text) or left: used as stated, "
                   "with a warning when the data reject it")
    p.add_argument("--azimuth-sense", choices=("auto", "same", "opposite"), default=None,
                   help="theodolite azimuth turning the same way as the INS heading or the "
                   "opposite way: auto (default) fits both and takes the one the data support")
    p.add_argument("--verify", choices=("leave-one-out",), default=None,
                   help="also check the 15″ claim out of sample: fit without each mirror in "
                   "turn and apply the offsets to it")
    p.add_argument("--roll-sigma-deg", type=positive, default=None, metavar="DEG",
                   help="prior 1-sigma of each fitted roll (default 2)")
    p.add_argument("--ins-sigma-arcsec", type=nonnegative, metavar="S",
                   help="error of each INS heading, pitch and roll reading (reference only)")
    p.add_argument("--theodolite-sigma-arcsec", type=nonnegative, metavar="S",
                   help="error of each theodolite angle (reference only)")
    p.set_defaults(func=_cmd_collimation_fit)

    p = csub.add_parser("verify", help="apply a saved fit's offsets to another calibration "
                        "and judge the 15″ claim on it (seed 003, section 3.2)")
    p.add_argument("fit", help="JSON written by 'collimation fit --json' (--readings reference)")
    p.add_argument("data", help="CSV of another calibration of the same device")
    add_json_option(p, "the out-of-sample deviations and verdict")
    p.set_defaults(func=_cmd_collimation_verify)

    p = csub.add_parser("simulate", help="write a simulated calibration CSV")
    p.add_argument("out", help="CSV file to write")
    p.add_argument("--seed", type=nonnegative_int, default=0)
    p.add_argument("--axis-az-arcsec", type=finite, default=180.0)
    p.add_argument("--axis-el-arcsec", type=finite, default=180.0)
    p.add_argument("--frame-heading-deg", type=finite, default=30.0)
    p.add_argument("--n-azimuth", type=nonnegative_int, help="absolute readings (default 5)")
    p.add_argument("--n-pitch", type=nonnegative_int, help="absolute readings (default 5)")
    p.add_argument("--azimuth-span-deg", type=finite, help="absolute readings (default 90)")
    p.add_argument("--pitch-span-deg", type=finite, help="absolute readings (default 60)")
    p.add_argument("--theodolite-sigma-arcsec", type=nonnegative, default=2.0)
    p.add_argument("--ins-sigma-arcsec", type=nonnegative, default=2.0)
    p.add_argument("--mount-roll-sigma-deg", type=nonnegative, default=0.0,
                   help="spread of the true INS roll (0: level mount)")
    p.add_argument("--with-roll", action="store_true", help="write the ins_roll_deg column")
    p.add_argument("--readings", choices=("reference", "absolute"), default="reference",
                   help="reference (default): the paper's procedure (--azimuths-deg, "
                   "--pitch-elevations-deg, reference mirrors at 0 and ±90°); absolute: the "
                   "absolute-reading model on --n-azimuth/--n-pitch mirrors")
    p.add_argument("--azimuths-deg", default="-30,-15,15,30,45",
                   help="horizontal mirrors (reference readings; default the paper-like layout)")
    p.add_argument("--pitch-elevations-deg", default="4,7.5,11,14.5,18",
                   help="pitch mirrors at azimuth 0 (reference readings)")
    p.add_argument("--roll-mirror", choices=("right", "left"), default="right")
    p.add_argument("--no-reference-rows", action="store_true",
                   help="write readings relative to the reference, without the reference rows")
    p.set_defaults(func=_cmd_collimation_simulate)

    p = csub.add_parser("figures", help="plot seed 003 Figs. 3-6 and check the text's statements")
    p.add_argument("outdir", help="directory for fig3.png ... fig6.png")
    p.set_defaults(func=_cmd_collimation_figures)


def fit_report(readings: MirrorData, result: Fit, source: str) -> dict[str, object]:
    """JSON-ready summary of a fit: parameters, sigmas and residuals in arc-seconds."""
    import numpy as np

    from montecarlo.seed003.fit import consistency_angles
    from montecarlo.seed003.model import EFFECTS, correct_readings

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
    from montecarlo.seed003.model import EFFECTS

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


def reference_report(readings: MirrorData, data: ProcedureData, result: ProcedureFit,
                     source: str, free_roll: bool, roll_sigma: float,
                     choices: Mapping[str, Choice] | None = None) -> dict[str, object]:
    """JSON-ready summary of a fit of the paper's procedure (arc-seconds unless named).

    Corrected readings and theodolite angles are given in the frame of the file's theodolite
    readings: azimuth relative to the central reference mirror plus that mirror's theodolite
    azimuth (its row, or the fitted ``reference_az``), turned back to the file's azimuth sense.
    When the file's theodolite azimuths are relative to the central mirror, as in the paper's
    table, this is the frame of the paper's corrected column.
    """
    import numpy as np
    from scipy.stats import chi2

    from montecarlo.seed003.conventions import SENSES
    from montecarlo.seed003.procedure import (
        CLAIM,
        central_azimuth,
        corrected_and_theodolite,
        heading_floor,
        pitch_reach,
    )

    k = data.measured
    names = [readings.mirror[i] for i in k]
    sets = [readings.sets[i] for i in k]
    c_az, c_el, t_az, t_el, rel_roll = corrected_and_theodolite(data, result)
    sense = "same" if choices is None else choices["azimuth_sense"].chosen
    zero = central_azimuth(data, result)
    c_az, t_az = (SENSES[sense] * (a + zero) for a in (c_az, t_az))  # the file's frame
    before, after = result.residuals_before / ARCSEC, result.residuals / ARCSEC
    dev_az = np.degrees(np.angle(np.exp(1j * (c_az - t_az)))) * 3600.0
    dev_el = (c_el - t_el) / ARCSEC
    mirrors = []
    for i, name in enumerate(names):
        ok = abs(dev_az[i]) <= CLAIM / ARCSEC and abs(dev_el[i]) <= CLAIM / ARCSEC
        mirrors.append({
            "mirror": name, "set": sets[i],
            "theodolite_az_deg": math.degrees(t_az[i]), "theodolite_el_deg": math.degrees(t_el[i]),
            "roll_deg": math.degrees(rel_roll[i]),
            "residual_before_az_arcsec": before[i, 0], "residual_before_el_arcsec": before[i, 1],
            "residual_after_az_arcsec": after[i, 0], "residual_after_el_arcsec": after[i, 1],
            "corrected_ins_az_deg": math.degrees(c_az[i]),
            "corrected_ins_el_deg": math.degrees(c_el[i]),
            "deviation_az_arcsec": float(dev_az[i]), "deviation_el_arcsec": float(dev_el[i]),
            "verdict": "within 15″" if ok else "exceeds 15″",
        })

    def rms(r):
        return {"az": float(np.sqrt(np.mean(r[:, 0] ** 2))),
                "el": float(np.sqrt(np.mean(r[:, 1] ** 2))), "all": float(np.sqrt(np.mean(r ** 2)))}

    se = result.stderr
    not_determined = []
    for name in ("axis_az", "axis_el", "reference_az"):
        if name in se and 2 * se[name] > CLAIM:
            item = {"parameter": name, "stderr_arcsec": se[name] / ARCSEC}
            if name == "axis_az":
                pitch = np.array([s == "pitch" for s in sets])
                reach = pitch_reach(data, result, pitch, free_roll, roll_sigma)
                item["pitch_reach_deg"] = None if reach is None else math.degrees(reach)
            not_determined.append(item)
    floor = None
    if result.roll_source.startswith("assumed"):
        per_deg = heading_floor(data, result) * math.radians(1.0) / ARCSEC
        floor = {"arcsec_per_deg_roll": per_deg}
    worst = float(max(np.max(np.abs(dev_az)), np.max(np.abs(dev_el))))
    return {
        "system": "collimation",
        "file": source,
        "readings": "reference",
        "reference": "reference rows (absolute readings)" if data.has_reference
        else "no reference rows (readings relative to the reference)",
        "roll_mirror": ({"chosen": "right" if result.side > 0 else "left"} if choices is None
                        else choices["roll_mirror"].to_json()),
        "azimuth_sense": ({"chosen": "same"} if choices is None
                          else choices["azimuth_sense"].to_json()),
        "settings": {"free_roll": bool(free_roll), "roll_sigma_deg": math.degrees(roll_sigma)},
        "corrected_frame": "theodolite readings of the file (azimuth relative to the central "
                           "reference mirror + its theodolite azimuth)",
        "n_mirrors": int(k.size),
        "roll": result.roll_source,
        "roll_prior_deg": math.degrees(roll_sigma) if result.names[-1].startswith("roll")
        else None,
        "unit": "arcsec",
        "parameters": {n: v / ARCSEC for n, v in result.params.items()},
        "stderr": {n: v / ARCSEC for n, v in se.items()},
        "correlation": {"names": list(result.names), "matrix": result.correlation.tolist()},
        "covariance_arcsec2": (result.covariance / ARCSEC**2).tolist(),
        "sigma_arcsec": {"ins": result.sigma_ins / ARCSEC,
                         "theodolite": result.sigma_theodolite / ARCSEC},
        "sigma_source": result.sigma_source,
        "chi2": result.chi2, "dof": result.dof, "chi2_red": result.chi2_red,
        "chi2_p_value": float(chi2.sf(result.chi2, result.dof))
        if result.sigma_source == "given" else None,
        "not_determined": not_determined,
        "heading_floor": floor,
        "mirrors": mirrors,
        "rms_arcsec": {"before": rms(before), "after": rms(after)},
        "claim_15_arcsec": {"max_deviation_arcsec": worst, "holds": worst <= CLAIM / ARCSEC,
                            "in_sample": True},
    }


def format_reference_report(report: Mapping[str, object]) -> str:
    """Human-readable text of :func:`reference_report`."""
    p, se = report["parameters"], report["stderr"]
    sets = [m["set"] for m in report["mirrors"]]
    sig = report["sigma_arcsec"]
    lines = [
        f"seed 003 axis calibration, the paper's procedure: {report['file']}, "
        f"{report['n_mirrors']} mirrors ({sets.count('azimuth')} azimuth, "
        f"{sets.count('pitch')} pitch); {report['reference']}; roll mirror on the "
        f"{report['roll_mirror']['chosen']}; INS roll {report['roll']}",
        *_convention_lines(report),
        f"reading sigma: INS {sig['ins']:.2f}″, theodolite {sig['theodolite']:.2f}″ "
        f"({report['sigma_source']})",
        "optical axis relative to the INS axis (±1σ):",
        f"  axis_az  γ = {p['axis_az']:10.2f} ± {se['axis_az']:.2f} arc-seconds (right +)",
        f"  axis_el  λ = {p['axis_el']:10.2f} ± {se['axis_el']:.2f} arc-seconds (up +)",
    ]
    if "reference_az" in p:
        lines.append(f"  reference azimuth (central mirror, theodolite) = "
                     f"{p['reference_az'] / 3600:.6f}° ± {se['reference_az']:.2f} arc-seconds")
    rolls = [n for n in p if n.startswith("roll")]
    if rolls:
        lines.append(f"  {len(rolls)} rolls fitted (prior 1σ {report['roll_prior_deg']:.2f}°): "
                     + ", ".join(f"{p[n] / 3600:.3f}°" for n in rolls))
    corr = report["correlation"]
    i, j = corr["names"].index("axis_az"), corr["names"].index("axis_el")
    lines.append(f"correlation γ-λ {corr['matrix'][i][j]:+.3f}"
                 + ("" if "reference_az" not in corr["names"] else
                    f", γ-reference azimuth "
                    f"{corr['matrix'][i][corr['names'].index('reference_az')]:+.3f}"))
    lines.append(f"chi2/dof = {report['chi2']:.2f}/{report['dof']} = {report['chi2_red']:.3f}")
    if report["chi2_p_value"] is not None and report["chi2_p_value"] < 1e-3:
        lines.append(f"MISFIT: χ² p-value {report['chi2_p_value']:.1e} with the given sigmas; "
                     "check the reading model (--readings absolute if the INS readings are "
                     "absolute and the file has no reference rows), the roll and the sigmas")
    for item in report["not_determined"]:
        text = (f"NOT DETERMINED: {item['parameter']} (σ {item['stderr_arcsec']:.1f}″, 2σ above "
                "15″) by this mirror layout")
        if "pitch_reach_deg" in item:
            reach = item["pitch_reach_deg"]
            text += ("; no pitch mirrors up to 85° would bring σ_γ to 7.5″" if reach is None else
                     f"; pitch mirrors must reach about {reach:.0f}° for σ_γ ≤ 7.5″")
        lines.append(text)
    if report["heading_floor"] is not None:
        f = report["heading_floor"]["arcsec_per_deg_roll"]
        lines.append(f"INS roll not recorded: a level mount is assumed. A roll of 1° (1σ) at each "
                     f"pointing would scatter the relative headings by {f:.1f}″ RMS at these "
                     f"offsets ({2 * f:.1f}″ at 2°): the heading floor of this assumption. "
                     "Record ins_roll_deg or use --free-roll.")
    lines += [
        "",
        "per mirror [arc-seconds]: residuals (INS reading - model) before/after; corrected INS "
        "reading (optical axis) vs theodolite, both in the file's theodolite frame:",
        f"{'mirror':>8} {'set':>8} {'bef az':>8} {'bef el':>8} {'aft az':>7} {'aft el':>7} "
        f"{'theo az°':>10} {'theo el°':>9} {'corr az°':>10} {'corr el°':>9} {'dev az':>7} "
        f"{'dev el':>7}  verdict",
    ]
    for m in report["mirrors"]:
        lines.append(
            f"{m['mirror']:>8} {m['set']:>8} {m['residual_before_az_arcsec']:8.2f} "
            f"{m['residual_before_el_arcsec']:8.2f} {m['residual_after_az_arcsec']:7.2f} "
            f"{m['residual_after_el_arcsec']:7.2f} {m['theodolite_az_deg']:10.5f} "
            f"{m['theodolite_el_deg']:9.5f} {m['corrected_ins_az_deg']:10.5f} "
            f"{m['corrected_ins_el_deg']:9.5f} {m['deviation_az_arcsec']:7.2f} "
            f"{m['deviation_el_arcsec']:7.2f}  {m['verdict']}")
    b, a = report["rms_arcsec"]["before"], report["rms_arcsec"]["after"]
    lines.append(f"{'RMS':>8} {'':>8} {b['az']:8.2f} {b['el']:8.2f} {a['az']:7.2f} {a['el']:7.2f}")
    lines.append(f"RMS of all residuals: before {b['all']:.2f}″, after {a['all']:.2f}″")
    claim = report["claim_15_arcsec"]
    lines.append(f"largest deviation of a corrected reading from the theodolite: "
                 f"{claim['max_deviation_arcsec']:.2f}″ -> the paper's 15″ claim "
                 + ("holds" if claim["holds"] else "DOES NOT HOLD")
                 + " in sample (the offsets were fitted to these readings; check it on another "
                 "set: collimation verify, or --verify leave-one-out)")
    if "verification" in report:
        lines += ["", format_verification(report["verification"])]
    return "\n".join(lines)


def _convention_lines(report: Mapping[str, object]) -> list[str]:
    """How the roll-mirror side and the azimuth sense were decided (text report)."""
    out = []
    for key, label in (("roll_mirror", "roll mirror"), ("azimuth_sense", "azimuth sense")):
        c = report[key]
        chi2 = {k[5:]: v for k, v in c.items() if k.startswith("chi2_")}
        if not chi2:
            continue
        shown = ", ".join(f"{k} {'-' if v is None else f'{v:.4g}'}" for k, v in chi2.items())
        verdict = ("decided by the data" if c["decided"] else f"not decided: {c['reason']}")
        out.append(f"{label}: {c['chosen']} (stated {c['stated']}; χ² {shown}; {verdict})")
    return out
