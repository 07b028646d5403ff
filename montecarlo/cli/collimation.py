"""Seed 003: ``collimation fit | simulate | figures``."""

from __future__ import annotations

import argparse
import math
from collections.abc import Mapping
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
    from montecarlo.seed003.fit import Fit


def _cmd_collimation_fit(args: argparse.Namespace) -> int:
    from montecarlo.io.collimation_csv import read_mirror_csv
    from montecarlo.seed003.fit import NotSeparable, fit, min_mirrors
    from montecarlo.seed003.model import BASE_EFFECTS, parameter_names

    check_json_option(args)
    effects = BASE_EFFECTS + (("frame_misalignment",) if args.fit_frame_tilt else ())
    n = len(parameter_names(effects))
    readings = read_mirror_csv(args.data, min_mirrors(n), f"{n} parameters")
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


def _cmd_collimation_simulate(args: argparse.Namespace) -> int:
    from montecarlo.io.collimation_csv import MirrorData, write_mirror_csv
    from montecarlo.seed003.model import Noise, paper_layout, simulate_readings

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


def _cmd_collimation_figures(args: argparse.Namespace) -> int:
    from montecarlo.io.files import save_figure
    from montecarlo.seed003.figures import pair_figures, paper_statements

    with OutputDir(args.outdir, "collimation figures") as staging:
        for name, fig in pair_figures().items():
            save_figure(fig, staging / f"{name}.png")
        write_provenance(staging, "collimation figures")
    print(f"wrote {args.outdir}/fig3.png ... fig6.png")
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
                   help="also fit the tilt of the theodolite frame against the INS level")
    p.set_defaults(func=_cmd_collimation_fit)

    p = csub.add_parser("simulate", help="write a simulated calibration CSV")
    p.add_argument("out", help="CSV file to write")
    p.add_argument("--seed", type=nonnegative_int, default=0)
    p.add_argument("--axis-az-arcsec", type=finite, default=180.0)
    p.add_argument("--axis-el-arcsec", type=finite, default=180.0)
    p.add_argument("--frame-heading-deg", type=finite, default=30.0)
    p.add_argument("--n-azimuth", type=nonnegative_int, default=5)
    p.add_argument("--n-pitch", type=nonnegative_int, default=5)
    p.add_argument("--azimuth-span-deg", type=finite, default=90.0)
    p.add_argument("--pitch-span-deg", type=finite, default=60.0)
    p.add_argument("--theodolite-sigma-arcsec", type=nonnegative, default=2.0)
    p.add_argument("--ins-sigma-arcsec", type=nonnegative, default=2.0)
    p.add_argument("--mount-roll-sigma-deg", type=nonnegative, default=0.0,
                   help="spread of the true INS roll (0: level mount)")
    p.add_argument("--with-roll", action="store_true", help="write the ins_roll_deg column")
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
