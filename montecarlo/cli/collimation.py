"""Seed 003: ``collimation fit | simulate | figures``."""

from __future__ import annotations

import argparse
import math

from montecarlo.cli.collimation_report import (
    fit_report,
    format_reference_report,
    format_report,
    format_verification,
    reference_report,
    verification_report,
)
from montecarlo.cli.common import (
    Parser,
    add_force_option,
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

__all__ = [
    "add_commands",
    "fit_report",
    "format_reference_report",
    "format_report",
    "format_verification",
    "reference_report",
    "verification_report",
]


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


def _cmd_collimation_verify(args: argparse.Namespace) -> int:
    """``collimation verify FIT.json NEW.csv``: a saved fit applied to another data set."""
    import numpy as np

    from montecarlo.io.collimation_csv import REFERENCE_SETS, SETS, procedure_data, read_mirror_csv
    from montecarlo.io.json_file import field, read_json
    from montecarlo.seed003.conventions import SENSES, with_sense
    from montecarlo.seed003.procedure import NotDetermined
    from montecarlo.seed003.reference import SIDES
    from montecarlo.seed003.verification import verify

    check_json_option(args)
    fit = args.fit
    saved = read_json(fit, "fit file (written by 'collimation fit --json')")
    if not isinstance(saved, dict) or saved.get("readings") != "reference":
        raise InputError(f"{fit}: readings: not a fit saved by 'collimation fit --json' under "
                         "--readings reference")
    limit = 180.0 * 3600.0  # an offset beyond half a turn [arcsec] is not an offset
    gamma = field(saved, "parameters.axis_az", fit, float, low=-limit, high=limit) * ARCSEC
    lam = field(saved, "parameters.axis_el", fit, float, low=-limit, high=limit) * ARCSEC
    side = SIDES[field(saved, "roll_mirror.chosen", fit, str, choices=tuple(SIDES))]
    sense = field(saved, "azimuth_sense.chosen", fit, str, choices=tuple(SENSES))
    free_roll = field(saved, "settings.free_roll", fit, bool)
    roll_sigma = math.radians(field(saved, "settings.roll_sigma_deg", fit, float, positive=True,
                                    high=180.0))
    s_ins = field(saved, "sigma_arcsec.ins", fit, float, low=0.0, high=limit) * ARCSEC
    s_theo = field(saved, "sigma_arcsec.theodolite", fit, float, low=0.0, high=limit) * ARCSEC
    if s_ins == 0.0 and s_theo == 0.0:
        raise InputError(f"{fit}: sigma_arcsec: ins and theodolite are both 0; at least one "
                         "must be > 0")
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
    writable_file(args.out, args.force)
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
    writable_file(args.out, args.force)
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
        verdict = "judged in the row above" if row["holds"] is None else \
            "holds" if row["holds"] else "DOES NOT HOLD"
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
                   help="known sigma of a heading or pitch difference, theodolite and INS "
                   "combined: each angle of the file errs by S/sqrt(2) (default: from the "
                   "residuals)")
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
    add_force_option(p)
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
