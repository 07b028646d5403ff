"""What the study runner needs from a simulated system: its metrics and a block of trials.

A system turns one validated grid-point configuration into per-trial metrics. The runner needs
from it only what :class:`System` declares, so ground calibration, air calibration, collimation
and stabilisation studies share one runner, one aggregation and one set of outputs. The systems
themselves live in :mod:`montecarlo.systems`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from pydantic import BaseModel

from montecarlo.engine.distributions import Streams


@dataclass(frozen=True)
class Metric:
    """A per-trial output: name, label for plots, display unit and its scale from SI/radians.

    ``signed`` metrics (per-axis errors) report percentiles and max of their magnitude.
    """

    name: str
    label: str
    unit: str
    scale: float
    signed: bool = False


BlockValues = dict[tuple[str, str], np.ndarray]
"""(variant, metric) -> per-trial values in SI/radians, NaN for an invalid trial."""
BlockInvalid = dict[str, dict[str, int]]
"""variant -> reason name -> count of invalid trials, plus "total"."""


class System(Protocol):
    """What the runner needs from a simulated system."""

    name: str
    config_model: type[BaseModel]
    """Pydantic model of the system's sections of a study file."""
    default_block_size: int

    def prepare(self, config: Any) -> Any:
        """Internal, picklable form of a validated config (SI units, radians)."""

    def metrics(self, prepared: Any) -> list[tuple[str, Metric]]:
        """(variant, metric) pairs the system produces for this config."""

    def trials_per_point(self, prepared: Any, requested: int) -> int:
        """Trials actually run at a grid point (e.g. 2**k for a pure corner enumeration)."""

    def is_sampled(self, prepared: Any) -> bool:
        """True if trials sample random errors; False if they enumerate every case."""

    def simulate_block(self, prepared: Any, streams: Streams, first_trial: int, n: int,
                       reference: bool = False) -> tuple[BlockValues, BlockInvalid]:
        """Simulate trials ``first_trial .. first_trial + n - 1`` from the given streams
        (``reference``: by the literal path, where the system also has a batched one)."""

    def describe(self, prepared: Any) -> list[str]:
        """Lines stating the assumptions of this config, for reports."""

    seconds_per_trial: float
    """A rough cost of one trial on one core [s], for planning (in-process or in workers,
    estimated times), on the path a run takes by default. A system whose literal path costs
    more may say so in ``reference_seconds_per_trial`` [s] (used for ``--reference``). Systems
    with a fused kernel may also have ``accumulate_block`` and
    ``first_use_note(prepared_list) -> str | None`` (a compile about to happen)."""
