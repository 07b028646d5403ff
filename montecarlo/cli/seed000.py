"""Seed 000 reproductions: ``table1``, ``air``, ``transfer-alignment``."""

from __future__ import annotations

import argparse
import math

from montecarlo.cli.common import (
    add_json_option,
    check_json_option,
    emit_json,
    finite,
    nonnegative_int,
    positive,
    positive_int,
)
from montecarlo.errors import InputError
from montecarlo.units import MRAD


def _cmd_table1(args: argparse.Namespace) -> int:
    from montecarlo.seed000 import table1

    check_json_option(args)
    table = table1.reproduce_table1()
    if not emit_json(args, table[list(table1.JSON_KEYS)].to_dict(orient="records")):
        print(table1.format_table1(table))
    return 0


def _cmd_air(args: argparse.Namespace) -> int:
    from montecarlo.seed000 import air

    check_json_option(args)
    table = air.reproduce_paper(n=args.trials, rng=args.seed)
    if args.json is not None:
        out = {
            "paper_mrad": {"one_sigma": air.PAPER_1SIGMA / MRAD,
                           "three_sigma": air.PAPER_3SIGMA / MRAD},
            "rss_of_inputs_mrad": air.rss_of_inputs() / MRAD,
            "one_d_from_1sigma_inputs_mrad": {
                k: v / MRAD for k, v in air.one_sigma_rotation(1).items()},
            "consistent_readings": air.consistent_readings(table).to_dict(orient="records"),
            "seed": args.seed,
            "rows": table.to_dict(orient="records"),
        }
        if emit_json(args, out):
            return 0
    print(air.format_reproduction(table))
    return 0


def add_commands(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("table1", help="reproduce seed 000, Table 1 and compare with the paper")
    add_json_option(p, "the six rows")
    p.set_defaults(func=_cmd_table1)

    p = sub.add_parser("air", help="seed 000, section 2: reproduce 1.70 / 5.10 mrad of the air "
                       "dynamic calibration with every rotation metric")
    add_json_option(p, "every statistic of every reading")
    p.add_argument("--trials", type=positive_int, default=200_000,
                   help="Monte Carlo trials per reading (default 200000)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="random seed (default 0)")
    p.set_defaults(func=_cmd_air)
    _add_transfer_alignment_commands(sub)


def _cmd_transfer_alignment(args: argparse.Namespace) -> int:
    from montecarlo.seed000 import table2
    from montecarlo.seed000 import transfer_alignment as ta

    check_json_option(args)
    if args.table2:
        return _table2_explained(args)
    try:
        cfg = ta.AlignmentConfig(manoeuvre=args.manoeuvre, duration=args.duration_s,
                                 bank=math.radians(args.bank_deg), period=args.period_s,
                                 attitude_matching=args.attitude_matching)
    except ValueError as exc:
        raise InputError(f"montecarlo transfer-alignment: {exc}") from None
    table = table2.table2_grid(cfg, rng=args.seed, runs=args.trials)
    if not emit_json(args, {"config": table2.describe(cfg), "seed": args.seed,
                            "rows": table.to_dict(orient="records")}):
        print(table2.format_table2(table, cfg))
    return 0


def _table2_explained(args: argparse.Namespace) -> int:
    from montecarlo.seed000 import table2_search as ts

    ex = ts.explain_table2(runs=args.response_runs, confirm_runs=args.trials, seed=args.seed,
                           n_jobs=args.jobs)
    best = ex["best"]
    if not emit_json(args, {
            "variant": best.variant, "params_si": best.params,  # type: ignore[attr-defined]
            "lever_arm_m": list(ts.LEVER_ARM), "seed": args.seed,
            "worst_gap_arcmin_superposition": best.worst_gap_arcmin,  # type: ignore[attr-defined]
            "rows": ex["check"].to_dict(orient="records"),  # type: ignore[attr-defined]
            "ratios": ex["ratios"].to_dict(orient="records")}):  # type: ignore[attr-defined]
        print(ts.format_explanation(ex))
    return 0


def _add_transfer_alignment_commands(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("transfer-alignment", help="seed 000, Table 2: Kalman-filter transfer "
                       "alignment for the five IMU grades, paper vs ours")
    add_json_option(p, "the five rows")
    p.add_argument("--trials", type=positive_int, default=100,
                   help="Monte Carlo runs of the filter per IMU grade (default 100)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="random seed (default 0)")
    p.add_argument("--manoeuvre", default="s_turn",
                   help="flight profile: s_turn (default), wing_rock, surge or level")
    p.add_argument("--duration-s", type=positive, default=120.0,
                   help="alignment time [s] (default 120)")
    p.add_argument("--bank-deg", type=finite, default=30.0,
                   help="peak bank of the S-turn, roll amplitude of the wing rock [deg] "
                   "(default 30)")
    p.add_argument("--period-s", type=positive, default=60.0,
                   help="period of the S-turn or the wing rock [s] (default 60)")
    p.add_argument("--attitude-matching", action="store_true",
                   help="add attitude matching to velocity matching")
    p.add_argument("--table2", action="store_true",
                   help="search the unmodelled effects (time tag, lever arm, flexure, master "
                   "errors, scale factors) that come closest to Table 2, one configuration for "
                   "all five rows; the manoeuvre flags are then ignored and --trials is the "
                   "confirming Monte Carlo's runs per row")
    p.add_argument("--response-runs", type=positive_int, default=100,
                   help="with --table2: sampled paths per random effect (default 100)")
    p.add_argument("--jobs", type=positive_int, default=2,
                   help="with --table2: parallel workers (default 2; same numbers for any)")
    p.set_defaults(func=_cmd_transfer_alignment)
