"""Command-line interface: ``montecarlo SUBCOMMAND ...``, one module per command group.

Every subcommand reports bad input as one line on stderr and exits with code 2.
``from montecarlo.cli import main; main(argv)`` runs a command in-process.
"""

from __future__ import annotations

import argparse
import gc
import logging
import os
import sys
from collections.abc import Sequence

from montecarlo import __version__
from montecarlo.cli import (
    authoring,
    camera,
    collimation,
    design,
    diagnose,
    seed000,
    stabilization,
    study,
    synth,
)
from montecarlo.cli.common import EXIT_BAD_INPUT, Parser, verbosity
from montecarlo.errors import InputError, RunInterrupted

GROUPS = (study, authoring, seed000, collimation, stabilization, diagnose, synth, camera,
          design)
"""Command modules, in the order their commands are listed by ``--help``."""


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="montecarlo",
        description="Monte Carlo error budgets for boresight calibration of strapdown "
        "electro-optical sensors.",
    )
    parser.add_argument("--version", action="version", version=f"montecarlo {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    for group in GROUPS:
        group.add_commands(sub)
    return parser


EXIT_INTERRUPTED = 130
"""Exit code after Ctrl-C (128 + SIGINT), as shells report it."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; returns its exit code (2 on bad input, reported as one line)."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s"))
    log = logging.getLogger("montecarlo")
    log.addHandler(handler)
    log.setLevel(logging.INFO)
    try:
        args = build_parser().parse_args(argv)
        log.setLevel(verbosity(args))
        return args.func(args)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except RunInterrupted as exc:
        print(f"stopped: {exc}", file=sys.stderr)
        return exc.code
    except KeyboardInterrupt:
        print("stopped: interrupted; nothing was written", file=sys.stderr)
        return EXIT_INTERRUPTED
    finally:
        log.removeHandler(handler)
        gc.unfreeze()  # a diagnosis froze what it loaded (Steps.loading); in-process callers go on


def entry_point() -> None:
    """Console-script entry point."""
    try:
        code = main()
        sys.stdout.flush()
    except BrokenPipeError:  # e.g. `montecarlo table1 | head`
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        code = 0
    sys.exit(code)
