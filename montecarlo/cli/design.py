"""Calibration design: ``plan``, ``size`` and ``budget``."""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from pathlib import Path

from montecarlo.cli.common import (
    add_force_option,
    add_json_option,
    add_n_jobs_option,
    check_json_option,
    emit_json,
    float_of,
    knob_assignment,
    nonnegative_int,
    positive,
    positive_int,
    probability,
    quiet,
    write_provenance,
)
from montecarlo.errors import InputError
from montecarlo.io.files import OutputDir, writable_file

RELATIONS = ("common", "independent")


def _design_base(args: argparse.Namespace) -> tuple[dict, dict | None]:
    """The base ground design (--study or the built-in one) and its [spec] table, if any."""
    from montecarlo.design import sizing_problem
    from montecarlo.engine.study import read_study_file
    from montecarlo.systems import study_from_dict, study_with_errors

    errors = getattr(args, "errors", None)
    if args.study is None:
        if errors is None:
            return sizing_problem.DEFAULT_DESIGN, None
        raw, _ = study_with_errors(sizing_problem.DEFAULT_DESIGN, "the built-in design", errors)
        return raw, None  # a bad value named in the errors file, before any work
    raw = read_study_file(args.study)
    if errors is not None:  # every mistake named in its file, before any work
        raw, study = study_with_errors(raw, args.study, errors)
    else:
        study = study_from_dict(raw, args.study)
    if study.header.system != "ground":
        raise InputError(f"{args.study}: study.system: sizing and budgets need a ground study "
                         f"(got {study.header.system!r})")
    return raw, raw.get("spec")


def _requirement(args: argparse.Namespace, spec: dict | None):
    from montecarlo.design.sizing_problem import Requirement

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
    from montecarlo.design import sizing, sizing_problem, sizing_report

    base, spec = _design_base(args)
    weights = {n: float_of("--weight", n, v) for n, v in args.weight}
    if args.vary:
        bounds = {}
        for name, text in args.vary:
            lo, sep, hi = text.partition(":")
            bounds[name] = (float_of("--vary", name, lo),
                            float_of("--vary", name, hi if sep else lo))
    else:
        bounds = dict(sizing_problem.DEFAULT_BOUNDS)
        if args.errors:  # the pixel error is known: no longer a knob
            bounds.pop("pixel_px")
    unknown = set(weights) - set(bounds)
    if unknown:
        raise InputError(f"--weight: {', '.join(sorted(unknown))} is not a varied knob")
    knobs = tuple(sizing_problem.Knob(n, lo, hi, weights.get(n, 1.0))
                  for n, (lo, hi) in bounds.items())
    problem = sizing_problem.SizingProblem(base, _requirement(args, spec), knobs)
    order = tuple(k.strip() for k in args.order.split(",")) if args.order else None
    options = sizing_problem.SizingOptions(
        levels=args.levels, trials=args.trials, seed=args.seed, tolerance=args.tolerance,
        replication_margin=not args.no_margin, order=order, n_jobs=args.n_jobs)
    confirm_seed = None if args.no_confirm else (
        args.confirm_seed if args.confirm_seed is not None else args.seed + 1)
    out = Path(args.out)
    with OutputDir(out, "size") as staging:
        result = sizing.size(problem, options, relations=args.relations,
                             confirm_seed=confirm_seed)
        sizing_report.write_outputs(result, staging)
        write_provenance(staging, "size", seed=args.seed, confirm_seed=confirm_seed,
                         base_study=args.study, requirement=vars(problem.requirement),
                         knobs=[vars(k) for k in knobs], relations=list(args.relations),
                         trials=args.trials)
        sizing_report.write_html_report(result, staging)
    print(sizing_report.format_result(result))
    print(f"\nwritten to {out}/ (report.md, report.html, frontier.png, answers.csv, grid-*.csv, "
          "corners-*.csv)")
    return 0


def _problem_spec_paths(target: str | None, relations: list[str]) -> dict[str, Path]:
    """The file of ``--problem-spec`` for each relation: the name given for one relation,
    NAME-<relation>.json for several."""
    if not target:
        return {}
    t = Path(target)
    return {r: t if len(relations) == 1 else t.with_name(f"{t.stem}-{r}{t.suffix}")
            for r in relations}


def _cmd_budget(args: argparse.Namespace) -> int:
    from montecarlo.design import budget, budget_report, problem_spec
    from montecarlo.design.sizing_problem import DESIGN_LABEL, KNOBS

    base, spec = _design_base(args)
    metric_from = "--metric"
    if args.from_problem_spec:
        given = problem_spec.read_problem_spec(args.from_problem_spec)
        base, relation = problem_spec.apply_problem_spec(base, given, args.from_problem_spec)
        if relation is not None and args.relations != [relation]:
            if args.relations != list(RELATIONS):  # asked for another one
                raise InputError(f"--relations: {args.from_problem_spec} has the pixel factors "
                                 f"of the {relation!r} relation (got {', '.join(args.relations)})")
            args.relations = [relation]
        if given.get("outputs") and args.metric is None:
            args.metric = str(given["outputs"][0])
            metric_from = f"{args.from_problem_spec}: outputs[0]"
    spec_paths = _problem_spec_paths(args.problem_spec, args.relations)
    for path in spec_paths.values():
        writable_file(path, args.force)
    point = {n: float_of("--point", n, v) for n, v in args.point}
    for n in point:
        if n not in KNOBS:
            raise InputError(f"--point {n}: unknown knob; choose from {', '.join(KNOBS)}")
    if args.from_sizing and point:
        raise InputError("--from-sizing: give either --point or --from-sizing, not both")
    points = _sizing_answers(args.from_sizing, args.relations) if args.from_sizing \
        else dict.fromkeys(args.relations, point)
    req = _requirement(args, spec)
    out = Path(args.out)
    with OutputDir(out, "budget") as staging:
        try:
            results = [budget.budget(base, req, rel, pt, samples=args.samples, seed=args.seed,
                                     trials=args.trials, resamples=args.resamples,
                                     n_jobs=args.n_jobs)
                       for rel, pt in points.items()]
        except InputError as exc:  # an unknown metric: named where it was given
            prefix = f"{DESIGN_LABEL}: spec.metric:"
            if str(exc).startswith(prefix):
                raise InputError(f"{metric_from}:{str(exc)[len(prefix):]}") from None
            raise
        budget_report.write_budget(results, staging)
        write_provenance(staging, "budget", seed=args.seed, base_study=args.study,
                         requirement=vars(req), points=points, samples=args.samples,
                         trials=args.trials, resamples=args.resamples)
        budget_report.write_html_report(results, staging)
    for r in results:
        if r.relation in spec_paths:
            assert r.problem is not None
            problem_spec.write_problem_spec(spec_paths[r.relation], problem_spec.problem_spec(
                r.problem, r.requirement.metric))
            print(f"SALib problem ({r.relation}) written to {spec_paths[r.relation]}")
    for r in results:
        print(budget_report.format_budget(r))
        print()
    print(f"written to {out}/ (report.md, report.html, budget.png, budget-*.csv)")
    return 0


def _sizing_answers(path: str, relations: Sequence[str]) -> dict[str, dict[str, float]]:
    """Each relation's answer (knob -> value) from a sizing run's answers.csv."""
    from montecarlo.design.sizing_problem import KNOBS, RELATIONS
    from montecarlo.io.table import read_table

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
        points[rel] = {k: float_of(f"{path}: row {row}: column", k, r[k]) for k in knobs}
    missing = [rel for rel in relations if rel not in points]
    if missing:
        raise InputError(f"{path}: no row for pixel relation {missing[0]!r} (choose the "
                         "relations it has with --relations)")
    return points


def _add_spec_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--study", help="base ground study (TOML); default: seed 000's Table 1 set-up "
                   "with the distributions of studies/range_sizing.toml")
    p.add_argument("--metric", help="metric (default: the study's [spec] or rotation_angle)")
    p.add_argument("--variant", help="solver variant (default: [spec] or normalised)")
    p.add_argument("--statistic", choices=("p50", "p90", "p95", "p99"),
                   help="percentile of the spec (default: [spec] or p95)")
    p.add_argument("--limit", type=positive, help="spec limit in the metric's display unit "
                   "(mrad for angles; default: the study's [spec])")
    p.add_argument("--confidence", type=probability, default=0.9,
                   help="confidence of the percentile bounds (default 0.9)")
    p.add_argument("--relations", nargs="+", choices=RELATIONS, default=list(RELATIONS),
                   help="pixel-noise relations (both)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="random seed (default 0)")
    add_n_jobs_option(p)


def _cmd_plan(args: argparse.Namespace) -> int:
    from montecarlo.design import planning
    from montecarlo.engine.runner import RunOptions, run_study
    from montecarlo.systems import load_study

    check_json_option(args)
    study = load_study(args.study)
    h, spec = study.header, study.spec
    stat = spec.statistic if spec else "p95"
    # a superquantile's tail starts at its level's quantile: the counts below are for that
    p = planning.PERCENTILES.get(stat) or planning.cvar_level(stat) or args.coverage
    c = h.confidence
    if not 0.0 < args.level_width < min(p, 1.0 - p):
        raise InputError(f"--level-width: must be below {min(p, 1.0 - p):g} for the "
                         f"{p:g}-quantile (got {args.level_width:g})")
    free = planning.distribution_free_table(p, c)
    level_n = planning.quantile_level_trials(p, args.level_width, c)
    pilot_trials = args.trials or min(max(gp.trials for gp in study.points), 4000)
    pilot = load_study(args.study, trials=pilot_trials)
    result = run_study(pilot, RunOptions(n_jobs=args.n_jobs, progress=not quiet(args)))
    table = planning.pilot_plan(result, result.to_frame(), args.width)
    data = {"study": h.name, "statistic": stat, "quantile": p, "confidence": c,
            "order_statistic_trials": free.to_dict("records"),
            "quantile_level_trials": {"half_width": args.level_width, "trials": level_n},
            "pilot_trials": pilot_trials, "points": table.to_dict("records")}
    if emit_json(args, data):
        return 0
    what = f"{stat} of {spec.metric}" if spec else "p95"
    print(f"{h.name}: trials for the {what} at {c:.0%} confidence")
    print(f"distribution-free (any metric): {planning.wilks_text(p, c)};")
    print("  the k-th largest of n trials bounds it with: " + ", ".join(
        f"k={k}: n={n:,}" for k, n in free.itertuples(index=False)))
    print(f"  the {c:.0%} interval of the {p:g}-quantile spans at most ±{args.level_width:g} "
          f"in quantile level from {level_n:,} trials")
    if planning.cvar_level(stat):
        print(f"  {stat} (mean of the worst {1 - p:.0%}): its interval is asymptotically "
              f"normal, not distribution-free; within 2 points of its coverage from "
              f"{math.ceil(250 / (1 - p)):,} trials (250 in the tail)")
    over = " over all trials, as the verdict judges it (no value = above the limit)" \
        if spec is not None and "verdict" in table else ""
    print(f"from a pilot of {pilot_trials:,} trials per grid point, the statistic{over} "
          "(estimates: the interval half-width shrinks as 1/sqrt(n); `run --until-decided` "
          "checks):")
    print(table.to_string(index=False))
    return 0


def add_commands(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plan", help="how many trials: distribution-free order-statistic counts "
                       "and, from a pilot run, the trials to decide each spec verdict")
    p.add_argument("study", help="study definition (TOML)")
    p.add_argument("--trials", type=positive_int,
                   help="pilot trials per grid point (default: the study's, at most 4000)")
    p.add_argument("--width", type=positive,
                   help="wanted full width of the statistic's interval, in the metric's unit")
    p.add_argument("--level-width", type=positive, default=0.01,
                   help="half-width in quantile level of the distribution-free interval "
                   "(default 0.01: p95 within p94-p96)")
    p.add_argument("--coverage", type=probability, default=0.99,
                   help="quantile to bound when the spec is on the max (default 0.99)")
    add_n_jobs_option(p)
    add_json_option(p, "the plan")
    p.set_defaults(func=_cmd_plan)

    p = sub.add_parser("size", help="cheapest range, mast, centroid and survey that meet a spec "
                       "(Pareto corners, common and independent pixel noise)")
    _add_spec_arguments(p)
    p.add_argument("--vary", action="append", type=knob_assignment, default=[],
                   metavar="KNOB=LO:HI", help="a knob and its bounds (repeatable; LO alone fixes "
                   "it); knobs: L_m, H_m, pixel_px, survey_m, scale_m; default: all five with "
                   "L 25:400, H 0.5:10, pixel 0.05:1, survey 0.01:0.2, scale 0.0002:0.005")
    p.add_argument("--weight", action="append", type=knob_assignment, default=[],
                   metavar="KNOB=W", help="cost of one doubling of a knob (default 1)")
    p.add_argument("--order", help="lexicographic cost instead of weights: KNOB,KNOB,... "
                   "(minimise the first, then the second, ...)")
    p.add_argument("--levels", type=positive_int, default=3,
                   help="grid levels per knob (default 3)")
    p.add_argument("--trials", type=positive_int, default=10000,
                   help="trials per evaluated design (default 10000)")
    p.add_argument("--tolerance", type=positive, default=0.02,
                   help="bisection stops at this relative bracket (default 0.02)")
    p.add_argument("--no-margin", action="store_true",
                   help="no replication margin: return the boundary of 'meets' itself")
    p.add_argument("--confirm-seed", type=nonnegative_int,
                   help="seed of the independent confirmation run (default seed + 1)")
    p.add_argument("--no-confirm", action="store_true", help="skip the confirmation run")
    p.add_argument("--errors", metavar="FILE.toml", help="update the base design's [errors] "
                   "from this file (e.g. diagnose camera --emit-errors); pixel_px is then fixed "
                   "unless --vary names it")
    p.add_argument("--out", default="results/sizing", help="output directory")
    p.set_defaults(func=_cmd_size)

    p = sub.add_parser("budget", help="Sobol variance shares of each error source and a split "
                       "of the spec among them, at a design point")
    _add_spec_arguments(p)
    p.add_argument("--point", action="append", type=knob_assignment, default=[],
                   metavar="KNOB=VALUE", help="design point as sizing knobs (repeatable), e.g. "
                   "L_m=50 H_m=5 pixel_px=0.2; default: the base study's values")
    p.add_argument("--from-sizing", metavar="ANSWERS.csv",
                   help="take each relation's design point from a sizing run's answers.csv")
    p.add_argument("--samples", type=positive_int, default=8192,
                   help="Sobol base sample size, a power of 2 (default 8192)")
    p.add_argument("--resamples", type=positive_int, default=200,
                   help="bootstrap resamples for the Sobol intervals (default 200)")
    p.add_argument("--trials", type=positive_int, default=20000,
                   help="trials of the study runs (design total, sources alone; default 20000)")
    p.add_argument("--problem-spec", metavar="OUT.json",
                   help="also write the Sobol factors as a SALib problem (ProblemSpec JSON; "
                   "OUT-<relation>.json for each of several relations)")
    add_force_option(p)
    p.add_argument("--from-problem-spec", metavar="IN.json",
                   help="take the error sources from a SALib problem (ProblemSpec JSON); its "
                   "pixel factor names set the relation")
    p.add_argument("--out", default="results/budget", help="output directory")
    p.set_defaults(func=_cmd_budget)
