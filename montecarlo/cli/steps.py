"""Wall time of the steps of a command, and a note on each slow one with why (``diagnose``)."""

from __future__ import annotations

import gc
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager

SLOW_STEP = 2.0
"""A step of a diagnosis taking at least this long [s] is named, with why, after the output."""


class Steps:
    """Wall time of the steps of one diagnosis, and the notes on the slow ones."""

    def __init__(self) -> None:
        self.spent: list[tuple[str, float, str]] = []

    @contextmanager
    def __call__(self, name: str, why: str = "") -> Iterator[None]:
        t0 = time.perf_counter()
        yield
        self.spent.append((name, time.perf_counter() - t0, why))

    @contextmanager
    def loading(self) -> Iterator[None]:
        """The step that imports the libraries. What it loaded lives as long as the command:
        it is frozen out of the garbage collector's full collections, which would otherwise
        walk its ~100,000 objects each time (0.65 s of a 0.15 px camera diagnosis), until the
        command ends (:func:`montecarlo.cli.main` unfreezes)."""
        with self("loading", LIBRARIES):
            yield
        gc.freeze()

    def notes(self) -> list[str]:
        """One line per step that took at least :data:`SLOW_STEP`: its time and why."""
        return [f"slow step: {name} took {spent:.1f} s" + (f" ({why})" if why else "")
                for name, spent, why in self.spent if spent >= SLOW_STEP]

    def report(self, to_stderr: bool) -> None:
        """Print the notes after the output: on stdout with the text, on stderr with --json."""
        for line in self.notes():
            print(line, file=sys.stderr if to_stderr else sys.stdout)


LIBRARIES = "importing scipy, pandas and the model's modules; a few seconds on a cold or " \
    "busy machine"
"""Why loading can be slow."""


def fit_why(n_obs: int, n_params: int) -> str:
    """Why a diagnosis's fits take time: the residuals and the model runs per Jacobian
    (``n_params``: the base parameters perturbed apart; a camera's views' poses count once)."""
    return (f"nonlinear fits of the base model, of every candidate and of the adapted model to "
            f"{n_obs} residuals; each Jacobian evaluates the model {2 * n_params}+ times "
            "(central differences)")
