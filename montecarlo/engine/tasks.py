"""The unit of work of the study runner: consecutive blocks of trials of one grid point.

Kept apart from :mod:`montecarlo.engine.runner` so that worker processes import only what a task
needs (numpy, the system and, for fast systems, numba), not pandas, plotting or the scheduler.
"""

from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from montecarlo.engine.aggregate import PointStats
from montecarlo.engine.distributions import Streams


@dataclass(frozen=True)
class PointTask:
    """What a worker needs to simulate blocks of one grid point."""

    system: Any
    prepared: Any
    seed: int
    point: int
    common_random_numbers: bool
    block_size: int
    trials: int


def run_task(task: PointTask, blocks: range, keep_trials: bool, reference: bool = False
             ) -> tuple[int, PointStats, dict[int, dict[tuple[str, str], np.ndarray]]]:
    """Simulate consecutive blocks of one grid point; a pure function of its arguments.

    Uses the system's fused ``accumulate_block`` when it has one, unless per-trial values are
    kept or the reference implementation is asked for (``reference``, also passed to
    ``simulate_block``: a system with a batched path then takes its literal one).
    """
    stats = PointStats()
    kept = {}
    fast = None if keep_trials or reference else getattr(task.system, "accumulate_block", None)
    for b in blocks:
        first = b * task.block_size
        n = min(task.block_size, task.trials - first)
        streams = Streams(task.seed, task.point, b, task.common_random_numbers)
        if fast is not None:
            fast(task.prepared, streams, first, n, b, stats)
            continue
        values, invalid = task.system.simulate_block(task.prepared, streams, first, n,
                                                     reference=reference)
        stats.add_block(b, values, invalid, n)
        if keep_trials:
            kept[b] = values
    return task.point, stats, kept


def exit_with_parent(parent: int, poll: float = 1.0) -> None:
    """Loky worker initializer: exit within ``poll`` seconds once process ``parent`` is gone.

    A worker whose parent was killed (SIGKILL leaves no chance to shut the pool down) is adopted
    by another process: its parent id is no longer ``parent``, and it exits, so that no worker
    outlives a killed run. Dask workers manage their own lifetime.
    """

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(poll)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()
