"""Measured-like data with chosen effects: ``synth ground | collimation``."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

import numpy as np

from montecarlo.cli.common import (
    Parser,
    add_force_option,
    field_of_view,
    finite,
    nonnegative,
    nonnegative_int,
    positive,
    positive_int,
    refraction_option,
    write_text,
)
from montecarlo.errors import InputError
from montecarlo.io.files import writable_file
from montecarlo.units import ARCSEC


def _unit(unit: str) -> str:
    return "" if unit == "1" else f" {unit}"


def _injected(truth: dict[str, float], display_unit: Callable[[str], tuple[str, float]],
              mounting: tuple[str, ...]) -> str:
    """The injected effects' parameters in display units (the mounting left out), or
    "nothing"."""
    shown = {k: v / display_unit(k)[1] for k, v in truth.items()
             if k not in mounting and v != 0.0}
    return ", ".join(f"{k} = {v:.4g}{_unit(display_unit(k)[0])}"
                     for k, v in shown.items()) or "nothing"


def _check_files(args: argparse.Namespace) -> None:
    """Refuse, before any work, data and truth files that cannot be written."""
    writable_file(args.out, args.force)
    if args.truth:
        writable_file(args.truth, args.force)


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
    print(f"wrote {args.out}: {data.n} observations ({dropped} off the detector dropped), "
          f"seed {args.seed}; injected: "
          + _injected(truth, ge.display_unit, ("psi", "theta", "gamma")))
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
    print(f"wrote {args.out}: {len(data.mirror)} mirrors, seed {args.seed}; diagnose with "
          f"--angle-sigma-arcsec {sigma:.4g}; injected: "
          + _injected(truth, ce.display_unit, ("frame_heading",)))
    return 0


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
    print(f"wrote {args.out}: {len(data.mirror)} rows ("
          + ("absolute readings with the two reference rows" if rows
             else "readings relative to the reference") + f"), seed {args.seed}; diagnose with "
          f"--angle-sigma-arcsec {sigma:.4g}; injected: "
          + _injected(truth, pe.display_unit, ("frame_heading",)))
    return 0


def add_commands(sub: argparse._SubParsersAction) -> None:
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
