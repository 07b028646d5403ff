"""Commands that run studies and compare results: ``run``, ``report``, ``compare``,
``nightly``, ``bench``."""

from __future__ import annotations

import argparse
from pathlib import Path

from montecarlo.cli.common import (
    add_json_option,
    add_max_points_option,
    add_n_jobs_option,
    check_json_option,
    emit_json,
    nonnegative,
    nonnegative_int,
    positive_int,
    quiet,
)
from montecarlo.errors import InputError

FORMATS = ("png", "svg", "pdf")
ONLY_SHOWN = 10
"""Rows of one run only that ``compare`` lists without --all."""


def _cmd_run(args: argparse.Namespace) -> int:
    from montecarlo.engine.checkpoints import Checkpoints
    from montecarlo.engine.runner import (
        DEFAULT_MAX_TRIALS,
        RunOptions,
        checked_options,
        run_study,
        run_until_decided,
    )
    from montecarlo.io.files import RESULTS_ROOT, OutputDir
    from montecarlo.systems import load_study

    if args.errors:
        from montecarlo.engine.study import read_study_file
        from montecarlo.systems import study_with_errors

        _, study = study_with_errors(read_study_file(args.study), args.study, args.errors,
                                     trials=args.trials, seed=args.seed,
                                     max_points=args.max_points)
    else:
        study = load_study(args.study, trials=args.trials, seed=args.seed,
                           max_points=args.max_points)
    out = Path(args.out) if args.out else RESULTS_ROOT / study.header.name
    options = RunOptions(n_jobs=args.n_jobs, backend=args.backend, scheduler=args.scheduler,
                         chunk_size=args.chunk_size, progress=not quiet(args),
                         checkpoint_dir=out.parent / ".checkpoints", reference=args.reference)
    checked_options(study, options)  # before any directory is made
    most = max(gp.trials for gp in study.points)
    if args.max_trials is not None and not args.until_decided:
        raise InputError("--max-trials: only with --until-decided")
    max_trials = DEFAULT_MAX_TRIALS if args.max_trials is None else args.max_trials
    if args.until_decided and study.spec is None:
        raise InputError(f"{args.study}: spec: --until-decided needs a [spec] table to decide")
    if args.until_decided and max_trials < most:
        raise InputError(f"--max-trials: {max_trials:,} is below the study's {most:,} trials "
                         "per grid point; give at least that many (or fewer --trials)")
    target = OutputDir(out, "run", {"study": study.header.name}, inputs=(Path(args.study),))
    with target as staging:
        result = run_until_decided(study, options, max_trials) if args.until_decided \
            else run_study(study, options)
        from montecarlo.output.outputs import write_outputs  # matplotlib: only for results

        write_outputs(result, staging, options, args.format)
    Checkpoints(out.parent / ".checkpoints", study, args.reference).remove()
    from montecarlo.output.report import spec_verdicts

    verdicts = spec_verdicts(result, result.to_frame())
    print(f"{study.header.name}: {len(study.points)} grid points written to {out}/ "
          f"(report.md, summary.csv, plots/)")
    if verdicts is not None:
        print(verdicts.to_string(index=False))
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from montecarlo.output.outputs import rerender

    names, prov = rerender(args.result, args.format)
    print(f"{prov['study']}: report.md and {len(names)} plots ({args.format}) drawn again in "
          f"{args.result}/ from its saved results")
    return 0


def _cmd_nightly(args: argparse.Namespace) -> int:
    from montecarlo.tools.nightly import run_nightly

    passed, checks = run_nightly(Path(args.studies), Path(args.out), args.n_jobs,
                                 progress=not quiet(args), accept_changes=args.accept_changes)
    for c in checks:
        print(f"{'pass' if c.passed else 'FAIL'}  {c.name}: {c.value} (expected {c.expected})")
    print(f"nightly: {sum(c.passed for c in checks)}/{len(checks)} checks pass; "
          f"report {args.out}/report.md")
    return 0 if passed else 1


def _cmd_compare(args: argparse.Namespace) -> int:
    from montecarlo.output.compare import (
        compare_runs,
        confidence_of,
        load_run,
        match_rows,
        verdict_counts,
    )

    check_json_option(args)
    a, b = load_run(args.run_a), load_run(args.run_b)
    spec = a.provenance.get("resolved_study", {}).get("spec") or {}
    statistic = args.statistic or spec.get("statistic", "p95")
    table = compare_runs(a, b, statistic, args.rtol, args.allow_different)
    _, only_a, only_b, keys = match_rows(a, b)
    counts = verdict_counts(table)
    mode = table["comparison"].iloc[0] if table["comparison"].nunique() == 1 else "mixed"
    if not emit_json(args, {"a": str(a.path), "b": str(b.path), "study": a.name,
                            "statistic": statistic, "comparison": mode, "counts": counts,
                            "rows": table.to_dict("records"),
                            "only_a": only_a.to_dict("records"),
                            "only_b": only_b.to_dict("records")}):
        level = f"{confidence_of(a):.0%}"
        how = ("paired: same seed and trials, so every difference is the code's"
               if mode == "paired" else "independent samples: differences judged on "
               f"simultaneous {level} intervals over the independent rows (Bonferroni)"
               if mode == "independent" else "paired and independent rows; the independent "
               f"ones on simultaneous {level} intervals (Bonferroni)")
        names = a.name if a.name == b.name else f"{a.name} and {b.name}"
        print(f"{names}: {b.path} against {a.path}, {statistic} ({how}); rows matched on "
              f"{', '.join([*keys, 'variant', 'metric'])}")
        shown = table if args.all else table[table["verdict"] != "same"]
        if len(shown):
            view = shown.drop(columns=["statistic", "comparison"]).copy()
            for col in ("a", "b", "diff", "diff_lo", "diff_hi"):
                view[col] = view[col].map(lambda v: f"{v:.6g}")
            view["rel_diff"] = view["rel_diff"].map(lambda v: f"{v:+.3%}")
            print(view.to_string(index=False))
        for run, only in ((a, only_a), (b, only_b)):
            if len(only):
                shown = only if args.all else only.head(ONLY_SHOWN)
                more = f", the first {len(shown)} (--all: every one)" if len(shown) < len(only) \
                    else ""
                print(f"{len(only)} rows only in {run.path}, not compared{more}:")
                print(shown.to_string(index=False))
        print(", ".join(f"{n} {v}" for v, n in counts.items() if n) + f" of {len(table)} rows"
              + "".join(f"; {len(o)} only in {r.path}" for r, o in ((a, only_a), (b, only_b))
                        if len(o)))
    return 1 if counts["worse"] else 0


def _cmd_bench(args: argparse.Namespace) -> int:
    from montecarlo.tools.bench import format_bench, run_bench

    check_json_option(args)
    result = run_bench(quick=not args.full, repeats=args.repeats)
    if not emit_json(args, result):
        print(format_bench(result))
    return 0


def add_commands(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run a study file and write results/<study>/")
    p.add_argument("study", help="study definition (TOML), e.g. studies/table1.toml")
    p.add_argument("--errors", metavar="FILE.toml", help="update the study's [errors] table "
                   "from this file (e.g. written by diagnose camera --emit-errors)")
    add_n_jobs_option(p)
    p.add_argument("--backend", choices=("loky", "dask"), default="loky",
                   help="loky: local processes; dask: a dask.distributed cluster")
    p.add_argument("--scheduler", help="dask scheduler address (default: start a LocalCluster)")
    p.add_argument("--trials", type=positive_int, help="override the trials per grid point")
    p.add_argument("--seed", type=nonnegative_int, help="override the study seed")
    p.add_argument("--out", help="output directory (default results/<study name>)")
    p.add_argument("--chunk-size", type=positive_int,
                   help="trials per task, a multiple of the block size (results do not change)")
    p.add_argument("--reference", action="store_true",
                   help="use the literal reference implementation instead of the fast kernel")
    p.add_argument("--until-decided", action="store_true",
                   help="double the trials of grid points whose spec verdict is undecided "
                   "until it is decided or --max-trials is reached")
    p.add_argument("--max-trials", type=positive_int,
                   help="most trials per grid point with --until-decided (default 1,048,576; "
                   "not below the study's trials)")
    add_max_points_option(p)
    p.add_argument("--format", choices=FORMATS, default="png", help="plot file format")
    p.set_defaults(func=_cmd_run)

    p = sub.add_parser("report", help="draw the plots and report.md of a result directory "
                       "again from its saved results (no trial is run)")
    p.add_argument("result", help="result directory of `montecarlo run`")
    p.add_argument("--format", choices=FORMATS, default="png", help="plot file format")
    p.set_defaults(func=_cmd_report)

    p = sub.add_parser("compare", help="compare two results of a study: difference, interval "
                       "and verdict per grid point (exit 1 if anything got worse)")
    p.add_argument("run_a", help="result directory of `montecarlo run` (the reference)")
    p.add_argument("run_b", help="result directory to compare with it")
    p.add_argument("--statistic", choices=("mean", "std", "p50", "p90", "p95", "p99", "cvar95",
                                           "max"),
                   help="statistic to compare (default: the spec's, else p95)")
    p.add_argument("--rtol", type=nonnegative, default=1e-9,
                   help="relative tolerance of paired runs (same seed and trials; 1e-9)")
    p.add_argument("--allow-different", action="store_true",
                   help="compare results of different studies on their common grid points")
    p.add_argument("--all", action="store_true", help="show every row, not only the changes")
    add_json_option(p, "the comparison")
    p.set_defaults(func=_cmd_compare)

    p = sub.add_parser("nightly", help="rerun Table 1 and the trend checks; exit 1 on regression")
    p.add_argument("--studies", default="studies", help="directory with table1.toml, trends.toml")
    p.add_argument("--out", default="results/nightly", help="output directory")
    p.add_argument("--accept-changes", action="store_true",
                   help="results that changed since the previous nightly do not fail the run "
                   "(after an intended change of the model)")
    add_n_jobs_option(p)
    p.set_defaults(func=_cmd_nightly)

    p = sub.add_parser("bench", help="trials per second of the reference and fast ground paths")
    add_json_option(p, "every figure")
    size = p.add_mutually_exclusive_group()
    size.add_argument("--quick", action="store_true", help="small sizes, under 30 s on two "
                      "quiet cores (the default; what `make bench` runs)")
    size.add_argument("--full", action="store_true", help="the full sizes: runner scaling up "
                      "to 10^8 trials, memory at 10^8, cold-cache compile time (minutes)")
    p.add_argument("--repeats", type=positive_int, default=5, help="timed runs per figure (5)")
    p.set_defaults(func=_cmd_bench)
