"""Seed 001: ``stabilization simulate | estimate | observability``, and ``diagnose
stabilization`` (the estimator's model of a recording against its candidates)."""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Callable

import numpy as np

from montecarlo.cli.common import (
    Parser,
    add_json_option,
    check_json_option,
    emit_json,
    field_of_view,
    finite,
    nonnegative,
    nonnegative_int,
    number,
    positive,
    positive_int,
)
from montecarlo.cli.noise_options import (
    AUTO,
    AUTO_HELP,
    diagnose_stabilization_auto,
    positive_or_auto,
    report_entry,
)
from montecarlo.cli.steps import Steps, fit_why
from montecarlo.errors import InputError
from montecarlo.units import ARCMIN, DEG_PER_HOUR, DEG_PER_ROOT_HOUR


def conventions_json(check: dict) -> dict:
    """The convention check of a stabilisation diagnosis with its angles in degrees."""
    def degrees(angles: dict) -> dict:
        return {k: math.degrees(v) for k, v in angles.items()}

    return {"checked": check["checked"], "large_angles_deg": degrees(check["large_angles"]),
            "named": check["named"],
            "fits": {c: {"chi2_red": f["chi2_red"], "p_value": f["p_value"],
                         "large_angles_deg": degrees(f["large_angles"])}
                     for c, f in check["fits"].items()}}


def conventions_text(conventions: dict) -> list[str]:
    """The lines ``diagnose stabilization`` prints about the recording's conventions."""
    from montecarlo.discrepancy.stabilization_effects import CONVENTIONS

    lines = []
    if conventions["large_angles_deg"]:
        angles = ", ".join(f"{k} = {v:.1f} deg" for k, v in conventions["large_angles_deg"].items())
        lines.append(f"installation angles not small ({angles}): the recording's frames or signs "
                     "differ from the model's (docs/reference/stabilization.md, 'Conventions of "
                     "the recordings')")
    for column in conventions["named"]:
        lines.append(f"convention: the model fits with {column} negated: the recording has "
                     f"{CONVENTIONS[column]}")
    if conventions["checked"] and not conventions["named"]:
        lines.append("convention: no single sign change of eta, eps or an image axis makes the "
                     "model fit")
    return lines


forgetting = number(float, low=0.0, high=1.0, open_low=True)
"""An RLS forgetting factor, in (0, 1]."""


def _stabilization_camera(args: argparse.Namespace):
    from montecarlo.geometry.camera import Camera

    return Camera.from_degrees(args.fov_deg, args.fov_deg, args.pixels, args.pixels)


def _stabilization_setup(args: argparse.Namespace):
    from montecarlo.seed001.kinematics import Rocking
    from montecarlo.seed001.simulate import Setup


    rocking = Rocking(np.radians(args.rock_amp_deg), args.rock_freq_hz,
                           np.radians(args.rock_phase_deg))
    setup = Setup(duration=args.duration_s, rate=args.rate_hz,
                       aim_azimuth=np.radians(args.aim_deg[0]),
                       aim_pitch=np.radians(args.aim_deg[1]), camera=_stabilization_camera(args),
                       image_noise=args.image_noise_px,
                       gyro_noise=args.gyro_arw_deg_per_rt_h * DEG_PER_ROOT_HOUR,
                       target_px=tuple(getattr(args, "target_px", (0.0, 0.0))),
                       mount=args.mount, gyro_sampling=getattr(args, "gyro_sampling", "point"))
    return rocking, setup


def _cmd_stabilization_simulate(args: argparse.Namespace) -> int:
    from montecarlo.io.stabilization_csv import write_csv
    from montecarlo.seed001.simulate import simulate


    rocking, setup = _stabilization_setup(args)
    delta_g = np.asarray(args.delta_g_arcmin) * ARCMIN
    delta_p = np.asarray(args.delta_p_arcmin) * ARCMIN
    bias = np.asarray(args.gyro_bias_deg_per_h) * DEG_PER_HOUR
    record = simulate(rocking, setup, delta_g, delta_p, bias, rng=args.seed)
    write_csv(args.out, record)
    truth = {"delta_px": delta_p[0], "delta_gx": delta_g[0], "delta_gy": delta_g[1],
             "delta_z": delta_p[2] - delta_g[2], "delta_py": delta_p[1]}
    if setup.mount == "inner-gimbal":
        truth["delta_gz"] = delta_g[2]
    print(f"wrote {args.out}: {record.t.size} rows, {setup.duration:g} s at {setup.rate:g} Hz; "
          f"{setup.mount} mount, gyro rows {setup.gyro_sampling}, target at "
          f"({setup.target_px[0]:g}, {setup.target_px[1]:g}) px")
    print("true values [arcmin]: " + ", ".join(f"{k} = {v / ARCMIN:.4f}"
                                                for k, v in truth.items()))
    print(f"LOS stabilisation error RMS: {np.sqrt(np.mean(record.los_error**2)) / ARCMIN:.4f}"
          " arcmin")
    return 0


def _cmd_stabilization_estimate(args: argparse.Namespace) -> int:
    from montecarlo.io.stabilization_csv import read_csv
    from montecarlo.seed001.estimate import estimate

    check_json_option(args)
    record = read_csv(args.csv)
    est = estimate(record.t, record.gyro, record.eta, record.eps, record.los_px,
                      _stabilization_camera(args), args.image_noise_px,
                      args.gyro_arw_deg_per_rt_h * DEG_PER_ROOT_HOUR, mount=args.mount,
                      gyro_sampling=args.gyro_sampling, forgetting=args.forgetting,
                      max_passes=args.passes)
    units = [ARCMIN if name.startswith("delta") else DEG_PER_HOUR for name in est.names]
    rows = {name: (float(v / u), float(s / u)) for name, v, s, u in
            zip(est.names, est.values, est.sigma, units, strict=True)}
    aim = [float(a) for a in est.aim_px]
    if args.json is not None:
        from montecarlo.output.provenance import provenance

        if emit_json(args, {
            "file": str(args.csv), "rows": int(record.t.size), "passes": est.passes,
            "converged": bool(est.converged), "residual_rms_px": float(est.residual_rms),
            "mount": args.mount, "gyro_sampling": args.gyro_sampling, "aim_px": aim,
            "units": {"delta_*": "arcmin", "bias_*": "deg/h", "aim_px": "px",
                      "sigma": "1 standard deviation"},
            "parameters": {k: {"value": v, "sigma": s} for k, (v, s) in rows.items()},
            "provenance": provenance("stabilization estimate", input=str(args.csv),
                                     image_noise_px=args.image_noise_px,
                                     gyro_arw_deg_per_rt_h=args.gyro_arw_deg_per_rt_h,
                                     mount=args.mount, gyro_sampling=args.gyro_sampling,
                                     forgetting=args.forgetting, passes=args.passes),
        }):
            return 0
    if args.passes == 1:
        state = "the patent's single linear pass about zero (error ~ angles squared)"
    else:
        state = "converged" if est.converged else "NOT converged: raise --passes"
    print(f"installation angles (seed 001) from {args.csv}: {record.t.size} rows, "
          f"{record.t[-1] - record.t[0]:g} s; {args.mount} mount, gyro rows "
          f"{args.gyro_sampling}; {est.passes} RLS passes, {state}")
    print("angles in arc-minutes (1 arcmin = 0.2909 mrad), gyro biases in deg/h; "
          "± is one standard deviation")
    notes = {"delta_z": "= dpz - dgz (dpz and dgz are not separable)"
             if args.mount == "patent" else "= dpz - dgz",
             "delta_py": "camera roll about the LOS (seen only at second order)",
             "delta_gz": "IMU yaw (separable from dpz with this mount)"}
    for name, (v, s) in rows.items():
        unit = "arcmin" if name.startswith("delta") else "deg/h"
        print(f"  {name:9s} {v:12.4f} ± {s:8.4f} {unit:7s}{notes.get(name, '')}")
    print(f"aim point (target's image at the first sample): ({aim[0]:.3f}, {aim[1]:.3f}) px")
    print(f"image residual RMS per axis: {float(est.residual_rms):.3f} px (includes the LOS walk "
          f"of gyro noise; image noise assumed {args.image_noise_px:g} px per axis)")
    return 0


def _cmd_stabilization_observability(args: argparse.Namespace) -> int:
    from montecarlo.seed001.linear_model import model_names, observability
    from montecarlo.seed001.simulate import simulate


    rocking, setup = _stabilization_setup(args)
    record = simulate(rocking, dataclasses.replace(setup, gyro_noise=0.0), 0.0, 0.0)
    obs = observability(record, setup.camera, setup.image_noise, mount=setup.mount)
    names = model_names(setup.mount)
    print(f"{setup.mount} mount: rank {obs.rank} of {len(names)} for X = [{', '.join(names)}]; "
          f"rank {obs.raw_rank} of 5 for [dpx, dpz, dgx, dgy, dgz]")
    for row in obs.raw_null_space:
        print("  unseen direction of [dpx, dpz, dgx, dgy, dgz]: "
              + "[" + ", ".join(f"{x:+.3f}" for x in row) + "]")
    print("Cramer-Rao sigma from image noise (gyro biases and aim point estimated too) "
          "[arcmin]:")
    for name, sigma in zip(names, obs.sigma, strict=True):
        print(f"  {name:9s} {sigma / ARCMIN:10.4f}" if np.isfinite(sigma)
              else f"  {name:9s} not observable")
    return 0


def _add_stabilization_profile(p: argparse.ArgumentParser) -> None:
    p.add_argument("--duration-s", type=positive, default=60.0, help="run length [s] (60)")
    p.add_argument("--rate-hz", type=positive, default=100.0,
                   help="gyro, gimbal-loop and camera frame rate [Hz] (100)")
    p.add_argument("--rock-amp-deg", type=finite, nargs=3, default=[5.0, 5.0, 5.0],
                   metavar=("YAW", "PITCH", "ROLL"), help="rocking amplitudes [deg] (5 5 5)")
    p.add_argument("--rock-freq-hz", type=finite, nargs=3, default=[0.25, 0.4, 0.32],
                   metavar=("YAW", "PITCH", "ROLL"),
                   help="rocking frequencies [Hz] (0.25 0.4 0.32)")
    p.add_argument("--rock-phase-deg", type=finite, nargs=3, default=[0.0, 60.0, 120.0],
                   metavar=("YAW", "PITCH", "ROLL"), help="rocking phases [deg] (0 60 120)")
    p.add_argument("--aim-deg", type=finite, nargs=2, default=[20.0, 10.0],
                   metavar=("AZIMUTH", "PITCH"), help="gimbal angles at the start [deg] (20 10)")
    p.add_argument("--image-noise-px", type=positive, default=0.1,
                   help="image noise per axis [px] (0.1)")
    p.add_argument("--gyro-arw-deg-per-rt-h", type=finite, default=0.01,
                   help="gyro angle random walk [deg/sqrt(h)] (0.01)")
    _add_mount(p)


def _add_mount(p: argparse.ArgumentParser) -> None:
    p.add_argument("--mount", choices=("patent", "inner-gimbal"), default="patent",
                   help="camera mount: 'patent' (eq. (2): the installation angles add to the "
                   "gimbal angles) or 'inner-gimbal' (camera on the pitch gimbal, its "
                   "installation rotation after the gimbal's) (patent)")


def _add_gyro_sampling(p: argparse.ArgumentParser) -> None:
    p.add_argument("--gyro-sampling", choices=("point", "interval-mean"), default="point",
                   help="what a gyro row holds: the rate at its time ('point') or the mean "
                   "rate over the interval ending there ('interval-mean') (point)")


def _add_stabilization_camera(p: argparse.ArgumentParser) -> None:
    p.add_argument("--fov-deg", type=field_of_view, default=5.0,
                   help="square field of view [deg] (5)")
    p.add_argument("--pixels", type=positive_int, default=1024,
                   help="pixels across the image (1024)")


def add_commands(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("stabilization", help="seed 001: installation angles of a gyro "
                       "indirect-stabilisation gimbal from the image drift of a target")
    ssub = p.add_subparsers(dest="stabilization_command", required=True, parser_class=Parser)

    sim = ssub.add_parser("simulate", help="simulate a rocking run and write it as CSV")
    sim.add_argument("out", help="CSV file to write (t_s, gyro_x, gyro_y, gyro_z, eta_rad, "
                     "eps_rad, los_x_px, los_z_px)")
    _add_stabilization_profile(sim)
    _add_stabilization_camera(sim)
    sim.add_argument("--delta-g-arcmin", type=finite, nargs=3, default=[30.0, -18.0, 42.0],
                     metavar=("GX", "GY", "GZ"), help="IMU installation angles [arcmin]")
    sim.add_argument("--delta-p-arcmin", type=finite, nargs=3, default=[24.0, 0.0, -36.0],
                     metavar=("PX", "PY", "PZ"), help="camera installation angles [arcmin]")
    sim.add_argument("--gyro-bias-deg-per-h", type=finite, nargs=3, default=[0.0, 0.0, 0.0],
                     metavar=("X", "Y", "Z"), help="gyro biases [deg/h] (0 0 0)")
    sim.add_argument("--target-px", type=finite, nargs=2, default=[0.0, 0.0],
                     metavar=("X", "Z"), help="image position of the target at the start "
                     "[px], x right, z up (0 0: where the LOS aims)")
    _add_gyro_sampling(sim)
    sim.add_argument("--seed", type=nonnegative_int, default=0, help="random seed (0)")
    sim.set_defaults(func=_cmd_stabilization_simulate)

    est = ssub.add_parser("estimate", help="estimate installation angles from a CSV run")
    est.add_argument("csv", help="CSV file with the columns written by 'simulate'")
    _add_stabilization_camera(est)
    est.add_argument("--image-noise-px", type=positive, default=0.1,
                     help="image noise per axis [px] (0.1)")
    est.add_argument("--gyro-arw-deg-per-rt-h", type=finite, default=0.01,
                     help="gyro angle random walk [deg/sqrt(h)] (0.01; 0: no LOS walk)")
    _add_mount(est)
    _add_gyro_sampling(est)
    est.add_argument("--forgetting", type=forgetting, default=1.0,
                     help="RLS forgetting factor in (0, 1] (1: none)")
    est.add_argument("--passes", type=positive_int, default=10,
                     help="most RLS passes (1: the patent's single linear pass) (10)")
    add_json_option(est, "the estimates")
    est.set_defaults(func=_cmd_stabilization_estimate)

    obs = ssub.add_parser("observability", help="rank and Cramer-Rao bounds of a rocking "
                          "profile")
    _add_stabilization_profile(obs)
    _add_stabilization_camera(obs)
    obs.set_defaults(func=_cmd_stabilization_observability)


START_IMAGE_NOISE = 0.1
"""Image noise [px] the estimator's start and the first pass use under ``auto``."""


def diagnose_stabilization(args: argparse.Namespace) -> int:
    steps = Steps()
    with steps.loading():
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

def add_diagnose_parser(dsub: argparse._SubParsersAction,
                        basic: Callable[[argparse.ArgumentParser], None]) -> None:
    """``diagnose stabilization``: the estimator's model of a recording against its
    candidates."""
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
    p.set_defaults(func=diagnose_stabilization)
