"""Command-line interface: ``montecarlo SUBCOMMAND ...``.

Every subcommand reports bad input as one line on stderr and exits with code 2.
"""

from __future__ import annotations

import argparse
import json
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
    sys.exit(main())


if __name__ == "__main__":
    entry_point()
