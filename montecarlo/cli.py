"""Command-line interface: ``montecarlo SUBCOMMAND ...``.

Every subcommand reports bad input as one line on stderr and exits with code 2.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence

from montecarlo import __version__
from montecarlo.exceptions import InputError

EXIT_BAD_INPUT = 2


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line (no usage block), exit code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise InputError(f"{self.prog}: {message}")


def _cmd_table1(args: argparse.Namespace) -> int:
    from montecarlo import table1

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

    from montecarlo.outputs import write_outputs
    from montecarlo.report import spec_verdicts
    from montecarlo.runner import Checkpoints, RunOptions, run_study
    from montecarlo.study import load_study

    study = load_study(args.study, trials=args.trials, seed=args.seed)
    out = Path(args.out) if args.out else Path("results") / study.header.name
    options = RunOptions(n_jobs=args.n_jobs, backend=args.backend, scheduler=args.scheduler,
                         chunk_size=args.chunk_size, progress=not args.quiet,
                         checkpoint_dir=out.parent / ".checkpoints")
    result = run_study(study, options)
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

    from montecarlo.nightly import run_nightly

    passed, checks = run_nightly(Path(args.studies), Path(args.out), args.n_jobs,
                                 progress=not args.quiet)
    for c in checks:
        print(f"{'pass' if c.passed else 'FAIL'}  {c.name}: {c.value} (expected {c.expected})")
    print(f"nightly: {sum(c.passed for c in checks)}/{len(checks)} checks pass; "
          f"report {args.out}/report.md")
    return 0 if passed else 1


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
    p.set_defaults(func=_cmd_run)

    p = sub.add_parser("nightly", help="rerun Table 1 and the trend checks; exit 1 on regression")
    p.add_argument("--studies", default="studies", help="directory with table1.toml, trends.toml")
    p.add_argument("--out", default="results/nightly", help="output directory")
    p.add_argument("--n-jobs", type=_positive_int, default=2)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_nightly)
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
