"""What every command shares: the one-line-error parser, argument validators, file output."""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

from montecarlo.errors import InputError
from montecarlo.io.files import atomic_write_bytes

EXIT_BAD_INPUT = 2
"""Exit code of every command on bad input (a study file, a CSV file, a flag)."""


class Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line (no usage block), exit code 2.

    Every command (and the program itself) takes ``-q/--quiet`` (warnings and errors only, no
    progress bars) and ``-v/--verbose`` (debugging detail); see :func:`verbosity`.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                          help="only warnings and errors, no progress bars")
        self.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS,
                          help="more detail")

    def error(self, message: str) -> None:  # type: ignore[override]
        raise InputError(f"{self.prog}: {message}")


def verbosity(args: argparse.Namespace) -> int:
    """The logging level the -q/-v flags ask for."""
    if getattr(args, "verbose", False):
        return logging.DEBUG
    return logging.WARNING if getattr(args, "quiet", False) else logging.INFO


def quiet(args: argparse.Namespace) -> bool:
    return bool(getattr(args, "quiet", False))


def add_n_jobs_option(p: argparse.ArgumentParser) -> None:
    """``--n-jobs N``; by default the cores, and small work runs in the calling process."""
    p.add_argument("--n-jobs", type=positive_int, metavar="N",
                   help="workers (default: the cores; small work runs in this process)")


def add_max_points_option(p: argparse.ArgumentParser) -> None:
    """``--max-points N``: the most grid points a study's sweep may expand to."""
    from montecarlo.engine.study import BYTES_PER_POINT, MAX_POINTS

    p.add_argument("--max-points", type=positive_int, default=MAX_POINTS, metavar="N",
                   help=f"refuse a sweep of more than N grid points before expanding it "
                   f"(default {MAX_POINTS:,}; about {BYTES_PER_POINT // 1000} kB of memory "
                   "each)")


def add_json_option(p: argparse.ArgumentParser, what: str) -> None:
    """``--json [PATH]``: print ``what`` as JSON instead of text, or also write it to PATH."""
    p.add_argument("--json", nargs="?", const="-", metavar="PATH",
                   help=f"{what} as JSON: printed instead of the text, or written to PATH "
                   "(the text is printed too)")
    add_force_option(p)


def add_force_option(p: argparse.ArgumentParser) -> None:
    """``--force``: replace a file the command writes if one is already there (else refused)."""
    with contextlib.suppress(argparse.ArgumentError):  # already added for another file
        p.add_argument("--force", action="store_true",
                       help="replace the files this command writes if they exist")


def check_json_option(args: argparse.Namespace) -> None:
    """Refuse, before any work, a --json file that cannot be written."""
    from montecarlo.io.files import writable_file

    if getattr(args, "json", None) not in (None, "-"):
        writable_file(args.json, args.force)


def emit_json(args: argparse.Namespace, data: Any) -> bool:
    """Print or write ``data`` as --json asks; True if it was printed (skip the text)."""
    import json

    if args.json is None:
        return False
    text = json.dumps(data, indent=2, default=str) + "\n"
    if args.json == "-":
        print(text, end="")
        return True
    write_text(args.json, text)
    return False


def number(kind: type[int] | type[float], *, low: float | None = None,
           high: float | None = None, open_low: bool = False, open_high: bool = False
           ) -> Callable[[str], int | float]:
    """An argparse ``type=`` that accepts a finite number of ``kind`` within the given bounds.

    >>> number(int, low=1)("3")
    3
    >>> number(float, low=0.0, open_low=True)("0")
    Traceback (most recent call last):
    argparse.ArgumentTypeError: '0' is not a number > 0
    """
    words = "an integer" if kind is int else "a number"
    bounds = [f"{'>' if open_low else '>='} {low:g}"] if low is not None else []
    bounds += [f"{'<' if open_high else '<='} {high:g}"] if high is not None else []
    expected = f"{words} {' and '.join(bounds)}".strip()

    def parse(text: str) -> int | float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {words}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
        if (low is not None and (value < low or (open_low and value == low))) or \
                (high is not None and (value > high or (open_high and value == high))):
            raise argparse.ArgumentTypeError(f"{text!r} is not {expected}")
        return value

    parse.__name__ = expected  # argparse names the type in its messages
    return parse


positive_int = number(int, low=1)
nonnegative_int = number(int, low=0)
positive = number(float, low=0.0, open_low=True)
nonnegative = number(float, low=0.0)
probability = number(float, low=0.0, high=1.0, open_low=True, open_high=True)
finite = number(float)
field_of_view = number(float, low=0.0, high=180.0, open_low=True, open_high=True)
"""A full field of view [deg]."""


def knob_assignment(text: str) -> tuple[str, str]:
    """``NAME=VALUE`` as a pair of stripped strings."""
    name, sep, value = text.partition("=")
    if not sep or not name or not value:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE (got {text!r})")
    return name.strip(), value.strip()


def float_of(option: str, name: str, text: str) -> float:
    """A finite number given in ``option`` for ``name``, or one line naming both."""
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{option} {name}: not a number: {text!r}") from None
    if not math.isfinite(value):
        raise InputError(f"{option} {name}: not a finite number: {text!r}")
    return value


def write_text(path: str | Path, text: str) -> None:
    """Write a text file all or nothing; an unwritable path is one line of bad input."""
    path = Path(path)
    try:
        atomic_write_bytes(path, text.encode())
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({exc.strerror})") from None


def write_provenance(directory: Path, kind: str, **record: object) -> None:
    """``provenance.json`` of a command's result directory (marks it as ours, see OutputDir)."""
    import json

    from montecarlo.io.files import PROVENANCE
    from montecarlo.output.provenance import provenance

    atomic_write_bytes(Path(directory) / PROVENANCE,
                       (json.dumps(provenance(kind, **record), indent=2, default=str) + "\n")
                       .encode())


def refraction_option(p: argparse.ArgumentParser, text: str) -> None:
    p.add_argument("--refraction-k", type=number(float, low=-5.0, high=5.0), default=0.13,
                   metavar="K", help=f"{text} [1] (default 0.13, Gauss's standard value)")

