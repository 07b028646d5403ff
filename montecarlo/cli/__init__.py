"""Command-line interface: ``montecarlo SUBCOMMAND ...``.

Every subcommand reports bad input as one line on stderr and exits with code 2.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
from collections.abc import Sequence

import numpy as np

from montecarlo import __version__
from montecarlo.errors import InputError

EXIT_BAD_INPUT = 2


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line (no usage block), exit code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise InputError(f"{self.prog}: {message}")


def _cmd_table1(args: argparse.Namespace) -> int:
    from montecarlo.seed000 import table1

    table = table1.reproduce_table1()
    if args.json:
        rows = table[list(table1.JSON_KEYS)].to_dict(orient="records")
        print(json.dumps(rows, indent=2))
    else:
        print(table1.format_table1(table))
    return 0


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1: {text!r}")
    return value


def _nonnegative_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must not be negative: {text!r}")
    return value


def _cmd_run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from montecarlo.engine.runner import Checkpoints, RunOptions, run_study
    from montecarlo.engine.study import load_study

    study = load_study(args.study, trials=args.trials, seed=args.seed)
    out = Path(args.out) if args.out else Path("results") / study.header.name
    options = RunOptions(n_jobs=args.n_jobs, backend=args.backend, scheduler=args.scheduler,
                         chunk_size=args.chunk_size, progress=not args.quiet,
                         checkpoint_dir=out.parent / ".checkpoints", reference=args.reference)
    result = run_study(study, options)

    from montecarlo.output.outputs import write_outputs  # matplotlib: only once results exist
    from montecarlo.output.report import spec_verdicts

    write_outputs(result, out, options)
    Checkpoints(options.checkpoint_dir, study).remove()
    verdicts = spec_verdicts(result, result.to_frame())
    print(f"{study.header.name}: {len(study.points)} grid points written to {out}/ "
          f"(report.md, summary.csv, plots/)")
    if verdicts is not None:
        print(verdicts.to_string(index=False))
    return 0


def _cmd_nightly(args: argparse.Namespace) -> int:
    from pathlib import Path

    from montecarlo.tools.nightly import run_nightly

    passed, checks = run_nightly(Path(args.studies), Path(args.out), args.n_jobs,
                                 progress=not args.quiet)
    for c in checks:
        print(f"{'pass' if c.passed else 'FAIL'}  {c.name}: {c.value} (expected {c.expected})")
    print(f"nightly: {sum(c.passed for c in checks)}/{len(checks)} checks pass; "
          f"report {args.out}/report.md")
    return 0 if passed else 1


def _cmd_air(args: argparse.Namespace) -> int:
    from montecarlo.seed000 import air

    table = air.reproduce_paper(n=args.trials, rng=args.seed)
    if args.json:
        out = {
            "paper_mrad": {"one_sigma": air.PAPER_1SIGMA / air.MRAD,
                           "three_sigma": air.PAPER_3SIGMA / air.MRAD},
            "rss_of_inputs_mrad": air.rss_of_inputs() / air.MRAD,
            "one_d_from_1sigma_inputs_mrad": {
                k: v / air.MRAD for k, v in air.one_sigma_rotation(1).items()},
            "consistent_readings": air.consistent_readings(table).to_dict(orient="records"),
            "seed": args.seed,
            "rows": table.to_dict(orient="records"),
        }
        print(json.dumps(out, indent=2))
    else:
        print(air.format_reproduction(table))
    return 0


def _add_air_commands(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("air", help="seed 000, section 2: reproduce 1.70 / 5.10 mrad of the air "
                       "dynamic calibration with every rotation metric")
    p.add_argument("--json", action="store_true", help="print JSON instead of text")
    p.add_argument("--trials", type=_positive_int, default=200_000,
                   help="Monte Carlo trials per reading (default 200000)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.set_defaults(func=_cmd_air)


def _cmd_transfer_alignment(args: argparse.Namespace) -> int:
    from montecarlo.seed000 import transfer_alignment as ta

    try:
        cfg = ta.AlignmentConfig(manoeuvre=args.manoeuvre, duration=args.duration,
                                 bank=math.radians(args.bank), period=args.period,
                                 attitude_matching=args.attitude_matching)
    except ValueError as exc:
        raise InputError(f"montecarlo transfer-alignment: {exc}") from None
    table = ta.table2_grid(cfg, rng=args.seed, runs=args.runs)
    if args.json:
        print(json.dumps({"config": ta.describe(cfg), "seed": args.seed,
                          "rows": table.to_dict(orient="records")}, indent=2))
    else:
        print(ta.format_table2(table, cfg))
    return 0


def _add_transfer_alignment_commands(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("transfer-alignment", help="seed 000, Table 2: Kalman-filter transfer "
                       "alignment for the five IMU grades, paper vs ours")
    p.add_argument("--json", action="store_true", help="print JSON instead of text")
    p.add_argument("--runs", type=_positive_int, default=100,
                   help="Monte Carlo runs per IMU grade (default 100)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--manoeuvre", default="s_turn",
                   help="flight profile: s_turn (default), wing_rock or level")
    p.add_argument("--duration", type=float, default=120.0,
                   help="alignment time [s] (default 120)")
    p.add_argument("--bank", type=float, default=30.0,
                   help="peak bank of the S-turn, roll amplitude of the wing rock [deg] "
                   "(default 30)")
    p.add_argument("--period", type=float, default=60.0,
                   help="period of the S-turn or the wing rock [s] (default 60)")
    p.add_argument("--attitude-matching", action="store_true",
                   help="add attitude matching to velocity matching")
    p.set_defaults(func=_cmd_transfer_alignment)


def _positive(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive number")
    return value


def _non_negative(text: str) -> float:
    value = float(text)
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number >= 0")
    return value


def _write_text_atomic(path: str, text: str) -> None:
    from pathlib import Path

    from montecarlo.io.files import atomic_write_bytes

    atomic_write_bytes(Path(path), text.encode())


def _cmd_collimation_fit(args: argparse.Namespace) -> int:
    from montecarlo.seed003 import model as col

    effects = col.BASE_EFFECTS + (("frame_misalignment",) if args.fit_frame_tilt else ())
    readings = col.read_readings(args.data, effects)
    sigma = None if args.angle_sigma_arcsec is None else args.angle_sigma_arcsec * col.ARCSEC
    try:
        result = col.fit(readings.theodolite_az, readings.theodolite_el, readings.ins_az,
                         readings.ins_el, readings.ins_roll, sigma=sigma, effects=effects)
    except col.NotSeparable as exc:
        raise InputError(f"{args.data}: {exc}") from None
    report = col.fit_report(readings, result, str(args.data))
    if args.json:
        _write_text_atomic(args.json, json.dumps(report, indent=2) + "\n")
    print(col.format_report(report))
    return 0


def _cmd_collimation_simulate(args: argparse.Namespace) -> int:
    import math

    from montecarlo.seed003 import model as col

    az, el, sets = col.paper_layout(args.n_azimuth, args.n_pitch,
                                    math.radians(args.azimuth_span_deg),
                                    math.radians(args.pitch_span_deg))
    truth = {"axis_az": args.axis_az_arcsec * col.ARCSEC,
             "axis_el": args.axis_el_arcsec * col.ARCSEC,
             "frame_heading": math.radians(args.frame_heading_deg)}
    ins = args.ins_sigma_arcsec * col.ARCSEC
    noise = col.Noise(theodolite=args.theodolite_sigma_arcsec * col.ARCSEC, ins_heading=ins,
                      ins_pitch=ins, ins_roll=ins,
                      mount_roll=math.radians(args.mount_roll_sigma_deg))
    data = col.simulate_readings(truth, az, el, noise, args.seed)
    names = ([f"A{i + 1}" for i in range(args.n_azimuth)]
             + [f"P{i + 1}" for i in range(args.n_pitch)])
    col.write_readings(args.out, names, sets.tolist(), data, with_roll=args.with_roll)
    print(f"wrote {args.out}: {len(names)} mirrors, seed {args.seed}, axis_az "
          f"{args.axis_az_arcsec}″, axis_el {args.axis_el_arcsec}″, frame_heading "
          f"{args.frame_heading_deg}°")
    return 0


def _cmd_collimation_figures(args: argparse.Namespace) -> int:
    from montecarlo.seed003 import model as col

    for path in col.plot_pair_figures(args.outdir):
        print(f"wrote {path}")
    print("seed 003, section 2 statements, evaluated with offsets of 0.1° (level mount):")
    for row in col.paper_statements():
        verdict = "holds" if row["holds"] else "DOES NOT HOLD"
        print(f"  {row['statement']}: {row['quantity']} = {row['model']:.4g} -> {verdict}")
    return 0


def _add_collimation_commands(sub: argparse._SubParsersAction) -> None:
    col = sub.add_parser("collimation", help="autocollimator-INS axis calibration (seed 003)")
    csub = col.add_subparsers(dest="collimation_command", required=True, parser_class=_Parser)

    p = csub.add_parser("fit", help="fit the optical-axis offsets to a calibration CSV")
    p.add_argument("data", help="CSV: mirror, set, theodolite_az_deg, theodolite_el_deg, "
                   "ins_az_deg, ins_el_deg[, ins_roll_deg]")
    p.add_argument("--json", metavar="OUT.json", help="also write the results as JSON")
    p.add_argument("--angle-sigma-arcsec", type=_positive, metavar="S",
                   help="known sigma of each heading/pitch residual (default: from residuals)")
    p.add_argument("--fit-frame-tilt", action="store_true",
                   help="also fit the tilt of the theodolite frame against the INS level")
    p.set_defaults(func=_cmd_collimation_fit)

    p = csub.add_parser("simulate", help="write a simulated calibration CSV")
    p.add_argument("out", help="CSV file to write")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--axis-az-arcsec", type=float, default=180.0)
    p.add_argument("--axis-el-arcsec", type=float, default=180.0)
    p.add_argument("--frame-heading-deg", type=float, default=30.0)
    p.add_argument("--n-azimuth", type=int, default=5)
    p.add_argument("--n-pitch", type=int, default=5)
    p.add_argument("--azimuth-span-deg", type=float, default=90.0)
    p.add_argument("--pitch-span-deg", type=float, default=60.0)
    p.add_argument("--theodolite-sigma-arcsec", type=_non_negative, default=2.0)
    p.add_argument("--ins-sigma-arcsec", type=_non_negative, default=2.0)
    p.add_argument("--mount-roll-sigma-deg", type=_non_negative, default=0.0,
                   help="spread of the true INS roll (0: level mount)")
    p.add_argument("--with-roll", action="store_true", help="write the ins_roll_deg column")
    p.set_defaults(func=_cmd_collimation_simulate)

    p = csub.add_parser("figures", help="plot seed 003 Figs. 3-6 and check the text's statements")
    p.add_argument("outdir", help="directory for fig3.png ... fig6.png")
    p.set_defaults(func=_cmd_collimation_figures)


def _cmd_bench(args: argparse.Namespace) -> int:
    from montecarlo.tools.bench import format_bench, run_bench

    result = run_bench(quick=args.quick, repeats=args.repeats)
    print(json.dumps(result, indent=2) if args.json else format_bench(result))
    return 0


ARCMIN = np.pi / (180.0 * 60.0)
"""One arc-minute [rad]: the unit of installation angles at the stabilization command line."""
DEG_PER_HOUR = np.pi / (180.0 * 3600.0)
"""One degree per hour [rad/s]: the unit of gyro biases."""
DEG_PER_ROOT_HOUR = np.pi / (180.0 * 60.0)
"""One degree per root hour [rad/s/sqrt(Hz)]: the unit of gyro angle random walk."""


def _stabilization_camera(args: argparse.Namespace):
    from montecarlo.geometry.camera import Camera

    if not 0.0 < args.fov_deg < 180.0 or args.pixels <= 0:
        raise InputError(f"--fov-deg must be in (0, 180) and --pixels positive, got "
                         f"{args.fov_deg} and {args.pixels}")
    return Camera.from_degrees(args.fov_deg, args.fov_deg, args.pixels, args.pixels)


def _stabilization_setup(args: argparse.Namespace):
    from montecarlo.seed001 import kinematics as stab

    if args.duration <= 0.0 or args.rate <= 0.0:
        raise InputError(f"--duration and --rate must be positive, got {args.duration} and "
                         f"{args.rate}")
    rocking = stab.Rocking(np.radians(args.rock_amp_deg), args.rock_freq_hz,
                           np.radians(args.rock_phase_deg))
    setup = stab.Setup(duration=args.duration, rate=args.rate,
                       aim_azimuth=np.radians(args.aim_deg[0]),
                       aim_pitch=np.radians(args.aim_deg[1]), camera=_stabilization_camera(args),
                       image_noise=args.image_noise_px,
                       gyro_noise=args.gyro_arw_deg_per_rt_h * DEG_PER_ROOT_HOUR)
    return rocking, setup


def _cmd_stabilization_simulate(args: argparse.Namespace) -> int:
    from montecarlo.seed001 import kinematics as stab

    rocking, setup = _stabilization_setup(args)
    delta_g = np.asarray(args.delta_g_arcmin) * ARCMIN
    delta_p = np.asarray(args.delta_p_arcmin) * ARCMIN
    bias = np.asarray(args.gyro_bias_deg_per_h) * DEG_PER_HOUR
    record = stab.simulate(rocking, setup, delta_g, delta_p, bias, rng=args.seed)
    stab.write_csv(args.out, record)
    truth = {"delta_px": delta_p[0], "delta_gx": delta_g[0], "delta_gy": delta_g[1],
             "delta_z": delta_p[2] - delta_g[2], "delta_py": delta_p[1]}
    print(f"wrote {args.out}: {record.t.size} rows, {setup.duration:g} s at {setup.rate:g} Hz")
    print("true values [arcmin]: " + ", ".join(f"{k} = {v / ARCMIN:.4f}"
                                                for k, v in truth.items()))
    print(f"LOS stabilisation error RMS: {np.sqrt(np.mean(record.los_error**2)) / ARCMIN:.4f}"
          " arcmin")
    return 0


def _cmd_stabilization_estimate(args: argparse.Namespace) -> int:
    from montecarlo.seed001 import kinematics as stab
    from montecarlo.seed001 import estimate as se

    if not 0.0 < args.forgetting <= 1.0 or args.passes < 1 or args.image_noise_px <= 0.0:
        raise InputError("--forgetting must be in (0, 1], --passes >= 1, --image-noise-px > 0")
    record = stab.read_csv(args.csv)
    est = se.estimate(record.t, record.gyro, record.eta, record.eps, record.los_px,
                      _stabilization_camera(args), args.image_noise_px,
                      args.gyro_arw_deg_per_rt_h * DEG_PER_ROOT_HOUR,
                      forgetting=args.forgetting, max_passes=args.passes)
    units = [ARCMIN] * 5 + [DEG_PER_HOUR] * 3
    rows = {name: (float(v / u), float(s / u)) for name, v, s, u in
            zip(se.PARAMETER_NAMES, est.values, est.sigma, units, strict=True)}
    if args.json:
        print(json.dumps({
            "file": str(args.csv), "rows": int(record.t.size), "passes": est.passes,
            "converged": bool(est.converged), "residual_rms_px": float(est.residual_rms),
            "units": {"delta_*": "arcmin", "bias_*": "deg/h", "sigma": "1 standard deviation"},
            "parameters": {k: {"value": v, "sigma": s} for k, (v, s) in rows.items()},
        }, indent=2))
        return 0
    if args.passes == 1:
        state = "the patent's single linear pass about zero (error ~ angles squared)"
    else:
        state = "converged" if est.converged else "NOT converged: raise --passes"
    print(f"installation angles (seed 001) from {args.csv}: {record.t.size} rows, "
          f"{record.t[-1] - record.t[0]:g} s; {est.passes} RLS passes, {state}")
    print("angles in arc-minutes (1 arcmin = 0.2909 mrad), gyro biases in deg/h; "
          "± is one standard deviation")
    notes = {"delta_z": "= dpz - dgz (dpz and dgz are not separable)",
             "delta_py": "camera roll about the LOS (seen only at second order)"}
    for name, (v, s) in rows.items():
        unit = "arcmin" if name.startswith("delta") else "deg/h"
        print(f"  {name:9s} {v:12.4f} ± {s:8.4f} {unit:7s}{notes.get(name, '')}")
    print(f"image residual RMS: {float(est.residual_rms):.3f} px (includes the LOS walk of gyro "
          f"noise; image noise assumed {args.image_noise_px:g} px per axis)")
    return 0


def _cmd_stabilization_observability(args: argparse.Namespace) -> int:
    from montecarlo.seed001 import kinematics as stab

    rocking, setup = _stabilization_setup(args)
    record = stab.simulate(rocking, dataclasses.replace(setup, gyro_noise=0.0), 0.0, 0.0)
    obs = stab.observability(record, setup.camera, setup.image_noise)
    print(f"rank {obs.rank} of 4 for X = [delta_px, delta_gx, delta_gy, delta_z]; "
          f"rank {obs.raw_rank} of 5 for [dpx, dpz, dgx, dgy, dgz]")
    for row in obs.raw_null_space:
        print("  unseen direction of [dpx, dpz, dgx, dgy, dgz]: "
              + "[" + ", ".join(f"{x:+.3f}" for x in row) + "]")
    print("Cramer-Rao sigma from image noise (gyro biases and aim point estimated too) "
          "[arcmin]:")
    for name, sigma in zip(stab.OBSERVABLE_NAMES, obs.sigma, strict=True):
        print(f"  {name:9s} {sigma / ARCMIN:10.4f}" if np.isfinite(sigma)
              else f"  {name:9s} not observable")
    return 0


def _add_stabilization_profile(p: argparse.ArgumentParser) -> None:
    p.add_argument("--duration", type=float, default=60.0, help="run length [s] (60)")
    p.add_argument("--rate", type=float, default=100.0,
                   help="gyro, gimbal-loop and camera frame rate [Hz] (100)")
    p.add_argument("--rock-amp-deg", type=float, nargs=3, default=[5.0, 5.0, 5.0],
                   metavar=("YAW", "PITCH", "ROLL"), help="rocking amplitudes [deg] (5 5 5)")
    p.add_argument("--rock-freq-hz", type=float, nargs=3, default=[0.25, 0.4, 0.32],
                   metavar=("YAW", "PITCH", "ROLL"),
                   help="rocking frequencies [Hz] (0.25 0.4 0.32)")
    p.add_argument("--rock-phase-deg", type=float, nargs=3, default=[0.0, 60.0, 120.0],
                   metavar=("YAW", "PITCH", "ROLL"), help="rocking phases [deg] (0 60 120)")
    p.add_argument("--aim-deg", type=float, nargs=2, default=[20.0, 10.0],
                   metavar=("AZIMUTH", "PITCH"), help="gimbal angles at the start [deg] (20 10)")
    p.add_argument("--image-noise-px", type=float, default=0.1,
                   help="image noise per axis [px] (0.1)")
    p.add_argument("--gyro-arw-deg-per-rt-h", type=float, default=0.01,
                   help="gyro angle random walk [deg/sqrt(h)] (0.01)")


def _add_stabilization_camera(p: argparse.ArgumentParser) -> None:
    p.add_argument("--fov-deg", type=float, default=5.0, help="square field of view [deg] (5)")
    p.add_argument("--pixels", type=int, default=1024, help="pixels across the image (1024)")


def _add_stabilization_commands(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("stabilization", help="seed 001: installation angles of a gyro "
                       "indirect-stabilisation gimbal from the image drift of a target")
    ssub = p.add_subparsers(dest="stabilization_command", required=True, parser_class=_Parser)

    sim = ssub.add_parser("simulate", help="simulate a rocking run and write it as CSV")
    sim.add_argument("out", help="CSV file to write (t_s, gyro_x, gyro_y, gyro_z, eta_rad, "
                     "eps_rad, los_x_px, los_z_px)")
    _add_stabilization_profile(sim)
    _add_stabilization_camera(sim)
    sim.add_argument("--delta-g-arcmin", type=float, nargs=3, default=[30.0, -18.0, 42.0],
                     metavar=("GX", "GY", "GZ"), help="IMU installation angles [arcmin]")
    sim.add_argument("--delta-p-arcmin", type=float, nargs=3, default=[24.0, 0.0, -36.0],
                     metavar=("PX", "PY", "PZ"), help="camera installation angles [arcmin]")
    sim.add_argument("--gyro-bias-deg-per-h", type=float, nargs=3, default=[0.0, 0.0, 0.0],
                     metavar=("X", "Y", "Z"), help="gyro biases [deg/h] (0 0 0)")
    sim.add_argument("--seed", type=int, default=0, help="random seed (0)")
    sim.set_defaults(func=_cmd_stabilization_simulate)

    est = ssub.add_parser("estimate", help="estimate installation angles from a CSV run")
    est.add_argument("csv", help="CSV file with the columns written by 'simulate'")
    _add_stabilization_camera(est)
    est.add_argument("--image-noise-px", type=float, default=0.1,
                     help="image noise per axis [px] (0.1)")
    est.add_argument("--gyro-arw-deg-per-rt-h", type=float, default=0.01,
                     help="gyro angle random walk [deg/sqrt(h)] (0.01; 0: no LOS walk)")
    est.add_argument("--forgetting", type=float, default=1.0,
                     help="RLS forgetting factor in (0, 1] (1: none)")
    est.add_argument("--passes", type=int, default=10,
                     help="most RLS passes (1: the patent's single linear pass) (10)")
    est.add_argument("--json", action="store_true", help="print JSON instead of a table")
    est.set_defaults(func=_cmd_stabilization_estimate)

    obs = ssub.add_parser("observability", help="rank and Cramer-Rao bounds of a rocking "
                          "profile")
    _add_stabilization_profile(obs)
    _add_stabilization_camera(obs)
    obs.set_defaults(func=_cmd_stabilization_observability)


def _unit(unit: str) -> str:
    return "" if unit == "1" else f" {unit}"


def _diagnosis_output(args: argparse.Namespace, d, view, source: str) -> int:
    from montecarlo.discrepancy import view as rep

    report = rep.to_json(d, view, source)
    if args.report:
        rep.write_report(args.report, d, view, report, trials=args.trials, seed=args.seed,
                         n_jobs=args.n_jobs)
    if args.json:
        _write_text_atomic(args.json, json.dumps(report, indent=2) + "\n")
    print(rep.format_text(report))
    if args.report:
        print(f"report written to {args.report}/ (report.md, diagnosis.json, residuals.png, "
              "gap.png)")
    return 0


def _cmd_diagnose_ground(args: argparse.Namespace) -> int:
    from montecarlo.discrepancy import engine as dia
    from montecarlo.discrepancy import ground_effects as ge
    from montecarlo.geometry.camera import Camera

    try:
        camera = Camera.from_degrees(args.fov_deg[0], args.fov_deg[1], args.pixels[0],
                                     args.pixels[1])
    except ValueError as exc:
        raise InputError(f"montecarlo diagnose ground: {exc}") from None
    data = ge.read_ground_csv(args.data, camera)
    sigma, survey = args.pixel_sigma, args.survey_sigma_m
    try:
        d = dia.diagnose(ge.ground_problem(data, camera, sigma, survey), args.alpha)
    except dia.FitError as exc:
        raise InputError(f"{args.data}: {exc}") from None
    return _diagnosis_output(args, d, ge.report_view(data, camera, sigma, survey),
                             str(args.data))


def _cmd_diagnose_collimation(args: argparse.Namespace) -> int:
    from montecarlo.seed003 import model as col
    from montecarlo.discrepancy import collimation_effects as ce
    from montecarlo.discrepancy import engine as dia

    data = ce.read_mirror_csv(args.data)
    sigma = args.angle_sigma_arcsec * col.ARCSEC
    try:
        d = dia.diagnose(ce.collimation_problem(data, sigma), args.alpha)
    except dia.FitError as exc:
        raise InputError(f"{args.data}: {exc}") from None
    return _diagnosis_output(args, d, ce.report_view(data, sigma), str(args.data))


def _cmd_synth_ground(args: argparse.Namespace) -> int:
    import numpy as np

    from montecarlo.discrepancy import ground_effects as ge
    from montecarlo.discrepancy import synth
    from montecarlo.geometry.camera import Camera

    try:
        camera = Camera.from_degrees(args.fov_deg[0], args.fov_deg[1], args.pixels[0],
                                     args.pixels[1])
    except ValueError as exc:
        raise InputError(f"montecarlo synth ground: {exc}") from None
    candidates = {c.name: c for c in ge.candidates_for(ge.GroundData(
        (), np.zeros((0, 3)), np.zeros((0, 2)), None, None if args.sessions < 2 else
        tuple(f"S{i + 1}" for i in range(args.sessions))))[0] if c.parameters}
    effects = synth.parse_effects(args.effect, candidates, ge.display_unit)
    at_mdb = synth.parse_multiples(args.at_mdb, candidates)
    mounting = dict(zip(("psi", "theta", "gamma"), map(math.radians, args.mounting_deg),
                        strict=True))
    data, truth, dropped = synth.synth_ground(
        seed=args.seed, camera=camera, pixel_sigma=args.pixel_sigma,
        survey_sigma=args.survey_sigma_m, mounting=mounting, ranges=args.ranges_m,
        grid=tuple(args.grid), spread=args.spread, duration=args.duration_s,
        sessions=args.sessions, effects=effects, at_mdb=at_mdb,
        atmosphere=not args.no_atmosphere, with_time=not args.no_time)
    if data.n < ge.min_targets():
        raise InputError(f"montecarlo synth ground: only {data.n} targets on the detector")
    ge.write_ground_csv(args.out, data)
    if args.truth:
        _write_text_atomic(args.truth, synth.truth_report(
            "ground", args.seed, truth, ge.display_unit, pixel_sigma=args.pixel_sigma,
            survey_sigma_m=args.survey_sigma_m, dropped_targets=dropped))
    shown = {k: v / ge.display_unit(k)[1] for k, v in truth.items()
             if k not in ("psi", "theta", "gamma") and v != 0.0}
    print(f"wrote {args.out}: {data.n} observations ({dropped} off the detector dropped), "
          f"seed {args.seed}; injected: "
          + (", ".join(f"{k} = {v:.4g}{_unit(ge.display_unit(k)[0])}" for k, v in shown.items())
             or "nothing"))
    return 0


def _cmd_synth_collimation(args: argparse.Namespace) -> int:
    from montecarlo.seed003 import model as col
    from montecarlo.discrepancy import collimation_effects as ce
    from montecarlo.discrepancy import synth

    candidates = {c.name: c for c in ce.CANDIDATES}
    effects = synth.parse_effects(args.effect, candidates, ce.display_unit)
    at_mdb = synth.parse_multiples(args.at_mdb, candidates)
    ins = args.ins_sigma_arcsec * col.ARCSEC
    noise = col.Noise(args.theodolite_sigma_arcsec * col.ARCSEC, ins, ins, ins,
                      math.radians(args.mount_roll_sigma_deg))
    data, truth = synth.synth_collimation(
        seed=args.seed, n_azimuth=args.n_azimuth, n_pitch=args.n_pitch,
        azimuth_span=math.radians(args.azimuth_span_deg),
        pitch_span=math.radians(args.pitch_span_deg),
        frame_heading=math.radians(args.frame_heading_deg), noise=noise, effects=effects,
        at_mdb=at_mdb, with_roll=args.with_roll or args.mount_roll_sigma_deg > 0)
    synth.write_collimation_csv(args.out, data)
    sigma = math.hypot(args.theodolite_sigma_arcsec, args.ins_sigma_arcsec)
    if args.truth:
        _write_text_atomic(args.truth, synth.truth_report(
            "collimation", args.seed, truth, ce.display_unit, angle_sigma_arcsec=sigma))
    shown = {k: v / ce.display_unit(k)[1] for k, v in truth.items()
             if k != "frame_heading" and v != 0.0}
    print(f"wrote {args.out}: {len(data.mirror)} mirrors, seed {args.seed}; diagnose with "
          f"--angle-sigma-arcsec {sigma:.4g}; injected: "
          + (", ".join(f"{k} = {v:.4g}{_unit(ce.display_unit(k)[0])}" for k, v in shown.items())
             or "nothing"))
    return 0


def _add_discrepancy_commands(sub: argparse._SubParsersAction) -> None:
    diag = sub.add_parser("diagnose", help="detect, identify and adapt a missing effect in "
                          "measured data (issue 5)")
    dsub = diag.add_subparsers(dest="diagnose_command", required=True, parser_class=_Parser)

    def common(p: argparse.ArgumentParser) -> None:
        p.add_argument("--json", metavar="OUT.json", help="write the diagnosis as JSON")
        p.add_argument("--report", metavar="DIR", help="write report.md, diagnosis.json and "
                       "plots (residuals, gap, Monte Carlo of the residual statistic)")
        p.add_argument("--alpha", type=_probability, default=0.01,
                       help="significance of the tests (default 0.01)")
        p.add_argument("--trials", type=_nonnegative_int, default=200,
                       help="Monte Carlo data sets per model in --report (default 200; 0: none)")
        p.add_argument("--seed", type=_nonnegative_int, default=0,
                       help="seed of the --report Monte Carlo (default 0)")
        p.add_argument("--n-jobs", type=_positive_int, default=1,
                       help="workers of the --report Monte Carlo (default 1)")

    p = dsub.add_parser("ground", help="targets surveyed in frame b observed by the sensor")
    p.add_argument("data", help="CSV: target, x_m, y_m, z_m, px, pz[, t_s][, session]")
    p.add_argument("--fov-deg", type=_positive, nargs=2, required=True, metavar=("FY", "FP"),
                   help="full fields of view about z (yaw) and x (pitch) [deg]")
    p.add_argument("--pixels", type=_positive_int, nargs=2, required=True,
                   metavar=("NX", "NZ"), help="pixel counts across x and z")
    p.add_argument("--pixel-sigma", type=_positive, required=True, metavar="S",
                   help="standard deviation of each image coordinate [px]")
    p.add_argument("--survey-sigma-m", type=_non_negative, default=0.0, metavar="S",
                   help="standard deviation of each surveyed coordinate [m] (default 0)")
    common(p)
    p.set_defaults(func=_cmd_diagnose_ground)

    p = dsub.add_parser("collimation", help="autocollimator-INS mirror readings (seed 003)")
    p.add_argument("data", help="CSV: mirror, set, theodolite_az_deg, theodolite_el_deg, "
                   "ins_az_deg, ins_el_deg[, ins_roll_deg]")
    p.add_argument("--angle-sigma-arcsec", type=_positive, required=True, metavar="S",
                   help="standard deviation of each heading and pitch residual [arc-seconds]")
    common(p)
    p.set_defaults(func=_cmd_diagnose_collimation)

    syn = sub.add_parser("synth", help="write a measured-like data set with chosen effects")
    ssub = syn.add_subparsers(dest="synth_command", required=True, parser_class=_Parser)

    def effect_options(p: argparse.ArgumentParser) -> None:
        p.add_argument("out", help="CSV file to write")
        p.add_argument("--seed", type=_nonnegative_int, default=0)
        p.add_argument("--effect", action="append", default=[], metavar="NAME=V[,V...]",
                       help="inject an effect, one value per parameter in report units "
                       "(repeatable)")
        p.add_argument("--at-mdb", action="append", default=[], metavar="NAME=MULT",
                       help="inject an effect at MULT times its minimal detectable bias "
                       "(repeatable)")
        p.add_argument("--truth", metavar="OUT.json", help="also write how the data were made")

    p = ssub.add_parser("ground", help="targets spread over the field at several ranges")
    effect_options(p)
    p.add_argument("--fov-deg", type=_positive, nargs=2, default=[90.0, 90.0])
    p.add_argument("--pixels", type=_positive_int, nargs=2, default=[512, 512])
    p.add_argument("--pixel-sigma", type=_non_negative, default=0.3, help="[px] (0.3)")
    p.add_argument("--survey-sigma-m", type=_non_negative, default=0.01, help="[m] (0.01)")
    p.add_argument("--mounting-deg", type=float, nargs=3, default=[30.0, 20.0, 10.0],
                   metavar=("PSI", "THETA", "GAMMA"), help="true mounting (seed 000: 30 20 10)")
    p.add_argument("--ranges-m", type=_positive, nargs="+", default=[50.0, 100.0])
    p.add_argument("--grid", type=_positive_int, nargs=2, default=[6, 6],
                   metavar=("NX", "NZ"), help="targets across and up the field (6 6)")
    p.add_argument("--spread", type=_positive, default=0.8,
                   help="fraction of the field covered (0.8)")
    p.add_argument("--duration-s", type=_non_negative, default=3600.0)
    p.add_argument("--sessions", type=_positive_int, default=1,
                   help="observe the layout in this many sessions (session column if > 1)")
    p.add_argument("--no-atmosphere", action="store_true",
                   help="no earth curvature and refraction (default: physical c = 1, k = 0.13)")
    p.add_argument("--no-time", action="store_true", help="omit the t_s column")
    p.set_defaults(func=_cmd_synth_ground)

    p = ssub.add_parser("collimation", help="seed 003 fixture: azimuth and pitch mirrors")
    effect_options(p)
    p.add_argument("--n-azimuth", type=_positive_int, default=7)
    p.add_argument("--n-pitch", type=_positive_int, default=7)
    p.add_argument("--azimuth-span-deg", type=float, default=90.0)
    p.add_argument("--pitch-span-deg", type=float, default=60.0)
    p.add_argument("--frame-heading-deg", type=float, default=30.0)
    p.add_argument("--theodolite-sigma-arcsec", type=_non_negative, default=2.0)
    p.add_argument("--ins-sigma-arcsec", type=_non_negative, default=2.0)
    p.add_argument("--mount-roll-sigma-deg", type=_non_negative, default=0.0)
    p.add_argument("--with-roll", action="store_true", help="write the ins_roll_deg column")
    p.set_defaults(func=_cmd_synth_collimation)


def _probability(text: str) -> float:
    value = float(text)
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"{text!r} is not in (0, 1)")
    return value




def _knob_assignment(text: str) -> tuple[str, str]:
    name, sep, value = text.partition("=")
    if not sep or not name or not value:
        raise argparse.ArgumentTypeError(f"expected KNOB=VALUE (got {text!r})")
    return name.strip(), value.strip()


def _float_of(option: str, name: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{option} {name}: not a number: {text!r}") from None
    if not math.isfinite(value):
        raise InputError(f"{option} {name}: not a finite number: {text!r}")
    return value


def _design_base(args: argparse.Namespace) -> tuple[dict, dict | None]:
    """The base ground design (--study or the built-in one) and its [spec] table, if any."""
    import tomllib
    from pathlib import Path

    from montecarlo.design import sizing

    if args.study is None:
        return sizing.DEFAULT_DESIGN, None
    try:
        raw = tomllib.loads(Path(args.study).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{args.study}: no such study file") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{args.study}: not valid TOML: {exc}") from None
    return raw, raw.get("spec")


def _requirement(args: argparse.Namespace, spec: dict | None):
    from montecarlo.design.sizing import Requirement

    spec = spec or {}
    limit = args.limit if args.limit is not None else spec.get("limit")
    if limit is None:
        raise InputError("--limit: required (the study file has no [spec] limit)")
    return Requirement(limit=float(limit), metric=args.metric or spec.get("metric",
                                                                            "rotation_angle"),
                       statistic=args.statistic or spec.get("statistic", "p95"),
                       confidence=args.confidence,
                       variant=args.variant or spec.get("variant") or "normalised")


def _cmd_size(args: argparse.Namespace) -> int:
    from pathlib import Path

    from montecarlo.design import sizing

    base, spec = _design_base(args)
    weights = {n: _float_of("--weight", n, v) for n, v in args.weight}
    if args.vary:
        bounds = {}
        for name, text in args.vary:
            lo, sep, hi = text.partition(":")
            bounds[name] = (_float_of("--vary", name, lo),
                            _float_of("--vary", name, hi if sep else lo))
    else:
        bounds = dict(sizing.DEFAULT_BOUNDS)
    unknown = set(weights) - set(bounds)
    if unknown:
        raise InputError(f"--weight: {', '.join(sorted(unknown))} is not a varied knob")
    knobs = tuple(sizing.Knob(n, lo, hi, weights.get(n, 1.0)) for n, (lo, hi) in bounds.items())
    problem = sizing.SizingProblem(base, _requirement(args, spec), knobs)
    order = tuple(k.strip() for k in args.order.split(",")) if args.order else None
    options = sizing.SizingOptions(levels=args.levels, trials=args.trials, seed=args.seed,
                                   tolerance=args.tolerance,
                                   replication_margin=not args.no_margin, order=order,
                                   n_jobs=args.n_jobs)
    confirm_seed = None if args.no_confirm else (
        args.confirm_seed if args.confirm_seed is not None else args.seed + 1)
    result = sizing.size(problem, options, relations=args.relations, confirm_seed=confirm_seed)
    out = Path(args.out)
    sizing.write_outputs(result, out)
    print(sizing.format_result(result))
    print(f"\nwritten to {out}/ (report.md, frontier.png, answers.csv, grid-*.csv, corners-*.csv)")
    return 0


def _cmd_budget(args: argparse.Namespace) -> int:
    from pathlib import Path

    from montecarlo.design import budget
    from montecarlo.design import sizing

    base, spec = _design_base(args)
    point = {n: _float_of("--point", n, v) for n, v in args.point}
    for n in point:
        if n not in sizing.KNOBS:
            raise InputError(f"--point {n}: unknown knob; choose from {', '.join(sizing.KNOBS)}")
    if args.from_sizing and point:
        raise InputError("--from-sizing: give either --point or --from-sizing, not both")
    points = _sizing_answers(args.from_sizing, args.relations) if args.from_sizing \
        else dict.fromkeys(args.relations, point)
    req = _requirement(args, spec)
    results = [budget.budget(base, req, rel, pt, samples=args.samples, seed=args.seed,
                             trials=args.trials, resamples=args.resamples, n_jobs=args.n_jobs)
               for rel, pt in points.items()]
    out = Path(args.out)
    budget.write_budget(results, out)
    for r in results:
        print(budget.format_budget(r))
        print()
    print(f"written to {out}/ (report.md, budget.png, budget-*.csv)")
    return 0


def _sizing_answers(path: str, relations: Sequence[str]) -> dict[str, dict[str, float]]:
    """Each relation's answer (knob -> value) from a sizing run's answers.csv."""
    from montecarlo.io.table import read_table
    from montecarlo.design.sizing import KNOBS, RELATIONS

    table = read_table(path, (), text=("pixel_relation",), choices={"pixel_relation": RELATIONS})
    knobs = [c for c in table.columns if c in KNOBS]
    points = {}
    for row, (_, r) in enumerate(table.iterrows(), start=2):
        rel = r["pixel_relation"]
        if rel not in relations:
            continue
        if all(str(r[k]).strip() == "" for k in knobs):
            raise InputError(f"{path}: row {row}: no answer for pixel relation {rel!r} "
                             f"(nothing met the spec); leave it out with --relations")
        points[rel] = {k: _float_of(f"{path}: row {row}: column", k, r[k]) for k in knobs}
    if not points:
        raise InputError(f"{path}: no row for pixel relation(s) {', '.join(relations)}")
    return points


def _add_spec_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--study", help="base ground study (TOML); default: seed 000's Table 1 set-up "
                   "with the distributions of studies/range_sizing.toml")
    p.add_argument("--metric", help="metric (default: the study's [spec] or rotation_angle)")
    p.add_argument("--variant", help="solver variant (default: [spec] or normalised)")
    p.add_argument("--statistic", choices=("p50", "p90", "p95", "p99"),
                   help="percentile of the spec (default: [spec] or p95)")
    p.add_argument("--limit", type=_positive, help="spec limit in the metric's display unit "
                   "(mrad for angles; default: the study's [spec])")
    p.add_argument("--confidence", type=float, default=0.9,
                   help="confidence of the percentile bounds (default 0.9)")
    p.add_argument("--relations", nargs="+", choices=("common", "independent"),
                   default=["common", "independent"], help="pixel-noise relations (both)")
    p.add_argument("--seed", type=_nonnegative_int, default=0, help="random seed (default 0)")
    p.add_argument("--n-jobs", type=_positive_int, default=2, help="parallel workers (2)")


def _add_sizing_commands(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("size", help="cheapest range, mast, centroid and survey that meet a spec "
                       "(Pareto corners, common and independent pixel noise)")
    _add_spec_arguments(p)
    p.add_argument("--vary", action="append", type=_knob_assignment, default=[],
                   metavar="KNOB=LO:HI", help="a knob and its bounds (repeatable; LO alone fixes "
                   "it); knobs: L_m, H_m, pixel_px, survey_m, scale_m; default: all five with "
                   "L 25:400, H 0.5:10, pixel 0.05:1, survey 0.01:0.2, scale 0.0002:0.005")
    p.add_argument("--weight", action="append", type=_knob_assignment, default=[],
                   metavar="KNOB=W", help="cost of one doubling of a knob (default 1)")
    p.add_argument("--order", help="lexicographic cost instead of weights: KNOB,KNOB,... "
                   "(minimise the first, then the second, ...)")
    p.add_argument("--levels", type=_positive_int, default=3,
                   help="grid levels per knob (default 3)")
    p.add_argument("--trials", type=_positive_int, default=10000,
                   help="trials per evaluated design (default 10000)")
    p.add_argument("--tolerance", type=_positive, default=0.02,
                   help="bisection stops at this relative bracket (default 0.02)")
    p.add_argument("--no-margin", action="store_true",
                   help="no replication margin: return the boundary of 'meets' itself")
    p.add_argument("--confirm-seed", type=_nonnegative_int,
                   help="seed of the independent confirmation run (default seed + 1)")
    p.add_argument("--no-confirm", action="store_true", help="skip the confirmation run")
    p.add_argument("--out", default="results/sizing", help="output directory")
    p.set_defaults(func=_cmd_size)

    p = sub.add_parser("budget", help="Sobol variance shares of each error source and a split "
                       "of the spec among them, at a design point")
    _add_spec_arguments(p)
    p.add_argument("--point", action="append", type=_knob_assignment, default=[],
                   metavar="KNOB=VALUE", help="design point as sizing knobs (repeatable), e.g. "
                   "L_m=50 H_m=5 pixel_px=0.2; default: the base study's values")
    p.add_argument("--from-sizing", metavar="ANSWERS.csv",
                   help="take each relation's design point from a sizing run's answers.csv")
    p.add_argument("--samples", type=_positive_int, default=8192,
                   help="Sobol base sample size, a power of 2 (default 8192)")
    p.add_argument("--resamples", type=_positive_int, default=200,
                   help="bootstrap resamples for the Sobol intervals (default 200)")
    p.add_argument("--trials", type=_positive_int, default=20000,
                   help="trials of the study runs (design total, sources alone; default 20000)")
    p.add_argument("--out", default="results/budget", help="output directory")
    p.set_defaults(func=_cmd_budget)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="montecarlo",
        description="Monte Carlo error budgets for boresight calibration of strapdown "
        "electro-optical sensors.",
    )
    parser.add_argument("--version", action="version", version=f"montecarlo {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    p = sub.add_parser("table1", help="reproduce seed 000, Table 1 and compare with the paper")
    p.add_argument("--json", action="store_true", help="print a JSON list of six rows")
    p.set_defaults(func=_cmd_table1)

    p = sub.add_parser("run", help="run a study file and write results/<study>/")
    p.add_argument("study", help="study definition (TOML), e.g. studies/table1.toml")
    p.add_argument("--n-jobs", type=_positive_int, default=2, help="parallel workers (2)")
    p.add_argument("--backend", choices=("loky", "dask"), default="loky",
                   help="loky: local processes; dask: a dask.distributed cluster")
    p.add_argument("--scheduler", help="dask scheduler address (default: start a LocalCluster)")
    p.add_argument("--trials", type=_positive_int, help="override the trials per grid point")
    p.add_argument("--seed", type=_nonnegative_int, help="override the study seed")
    p.add_argument("--out", help="output directory (default results/<study name>)")
    p.add_argument("--chunk-size", type=_positive_int,
                   help="trials per task, a multiple of the block size (results do not change)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--reference", action="store_true",
                   help="use the literal reference implementation instead of the fast kernel")
    p.set_defaults(func=_cmd_run)

    p = sub.add_parser("nightly", help="rerun Table 1 and the trend checks; exit 1 on regression")
    p.add_argument("--studies", default="studies", help="directory with table1.toml, trends.toml")
    p.add_argument("--out", default="results/nightly", help="output directory")
    p.add_argument("--n-jobs", type=_positive_int, default=2)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_nightly)

    p = sub.add_parser("bench", help="trials per second of the reference and fast ground paths")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--quick", action="store_true", help="small sizes (seconds, for tests)")
    p.add_argument("--repeats", type=_positive_int, default=5, help="timed runs per figure (5)")
    p.set_defaults(func=_cmd_bench)
    _add_air_commands(sub)
    _add_transfer_alignment_commands(sub)
    _add_collimation_commands(sub)
    _add_stabilization_commands(sub)
    _add_discrepancy_commands(sub)
    _add_sizing_commands(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
        return args.func(args)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT


def entry_point() -> None:
    """Console-script entry point."""
    try:
        code = main()
        sys.stdout.flush()
    except BrokenPipeError:  # e.g. `montecarlo table1 | head`
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        code = 0
    sys.exit(code)


if __name__ == "__main__":
    entry_point()
