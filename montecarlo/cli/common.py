"""What every command shares: the one-line-error parser, argument validators, file output."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path

from montecarlo.errors import InputError
from montecarlo.io.files import atomic_write_bytes

EXIT_BAD_INPUT = 2
"""Exit code of every command on bad input (a study file, a CSV file, a flag)."""


class Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line (no usage block), exit code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise InputError(f"{self.prog}: {message}")


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
