"""Run a study: grid points x blocks of trials, in parallel with joblib (loky or dask).

Reproducibility contract: trials are grouped into fixed *blocks* (``block_size`` trials, part
of the study); every block draws from its own streams (``SeedSequence(seed)`` with spawn key
``(block, source)``, or ``(point, block, source)`` without common random numbers). A *task* is
a run of consecutive blocks of one grid point; tasks may be any multiple of the block size, run
in any order, on any worker or backend. Statistics are merged exactly (see
:mod:`montecarlo.engine.aggregate`), so results are bit-identical for any ``n_jobs``, chunk size and
backend, on machines of one CPU type (numpy's and numba's SIMD code paths depend on it).

Each finished grid point is checkpointed (pickle, written atomically) under
``<out>/../.checkpoints/<name>-<hash>/``; rerunning an interrupted study skips finished points
and ends with the same results as an uninterrupted run.
"""

from __future__ import annotations

import contextlib
import math
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import joblib
import numpy as np
import pandas as pd
from tqdm import tqdm

from montecarlo.engine.aggregate import VALUE_COLUMNS, PointResult, PointStats
from montecarlo.engine.checkpoints import Checkpoints
from montecarlo.engine.study import Study
from montecarlo.engine.tasks import PointTask, run_task
from montecarlo.errors import InputError

Backend = Literal["loky", "dask"]


@dataclass(frozen=True)
class RunOptions:
    """How to run a study (none of this changes the results)."""

    n_jobs: int = 2
    backend: Backend = "loky"
    scheduler: str | None = None
    chunk_size: int | None = None
    """Trials per task, a multiple of the block size (default: about 4 tasks per worker)."""
    progress: bool = True
    checkpoint_dir: Path | None = None
    reference: bool = False
    """Use the literal reference implementation instead of a system's fast kernel (slower;
    the statistics agree to about 1e-12, not bit for bit)."""


@dataclass
class StudyResult:
    """Statistics of every grid point of a study, and optional per-trial values."""

    study: Study
    points: list[PointResult]
    trials: dict[int, pd.DataFrame] = field(default_factory=dict)

    def _sweep_value(self, key: str, value: Any) -> Any:
        """Sweep values as they go in a column: text if the key mixes numbers and text."""
        kinds = {isinstance(p.values[key], str) for p in self.study.points}
        return str(value) if len(kinds) > 1 else value

    def to_frame(self) -> pd.DataFrame:
        """Summary: one row per (grid point, variant, metric), values in display units."""
        frames = []
        for gp, pr in zip(self.study.points, self.points, strict=True):
            df = pr.summary.copy()
            scale = df["metric"].map({m.name: m.scale for _, m in self.study.metrics})
            df[VALUE_COLUMNS] = df[VALUE_COLUMNS].mul(scale, axis=0)
            df.insert(0, "point", gp.index)
            for i, key in enumerate(self.study.sweep_keys):
                df.insert(1 + i, key, self._sweep_value(key, gp.values[key]))
            df.insert(len(self.study.sweep_keys) + 3, "unit",
                      df["metric"].map({m.name: m.unit for _, m in self.study.metrics}))
            frames.append(df)
        out = pd.concat(frames, ignore_index=True)
        invalid_cols = [c for c in out.columns if c.startswith("invalid_")]
        out[invalid_cols] = out[invalid_cols].fillna(0).astype(np.int64)
        return out


def _tasks(study: Study, points: list[int], chunk_blocks: int) -> list[tuple[int, range]]:
    tasks = []
    for p in points:
        n_blocks = _n_blocks(study, p)
        tasks += [(p, range(s, min(s + chunk_blocks, n_blocks)))
                  for s in range(0, n_blocks, chunk_blocks)]
    return tasks


def _n_blocks(study: Study, point: int) -> int:
    return math.ceil(study.points[point].trials / study.block_size)


def _block_trials(study: Study, point: int, block: int) -> int:
    return min(study.block_size, study.points[point].trials - block * study.block_size)


MAX_CHUNK_BLOCKS = 32
"""Default cap on blocks per task, so that progress and checkpoints stay frequent."""


def _chunk_blocks(study: Study, points: list[int], options: RunOptions) -> int:
    """Blocks per task: the requested chunk size, or about four tasks per worker."""
    bs = study.block_size
    if options.chunk_size is not None:
        if options.chunk_size <= 0 or options.chunk_size % bs:
            raise InputError(f"--chunk-size: {options.chunk_size} is not a positive multiple of "
                             f"the study's block size {bs}")
        return options.chunk_size // bs
    total_blocks = sum(_n_blocks(study, p) for p in points)
    return min(MAX_CHUNK_BLOCKS, max(1, math.ceil(total_blocks / (4 * options.n_jobs))))


@contextlib.contextmanager
def _backend(options: RunOptions) -> Iterator[int]:
    """Context in which joblib uses the requested backend; yields n_jobs for Parallel."""
    if options.backend == "loky":
        if options.scheduler:
            raise InputError("--scheduler: only meaningful with --backend dask")
        with joblib.parallel_config(backend="loky", inner_max_num_threads=1):
            yield options.n_jobs
        return
    from distributed import Client, LocalCluster

    if options.scheduler:
        try:
            client = Client(options.scheduler, timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise InputError(f"--scheduler: cannot reach {options.scheduler!r} ({exc})") from None
        with client, joblib.parallel_config(backend="dask"):
            yield -1
        return
    with LocalCluster(n_workers=options.n_jobs, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster), \
            joblib.parallel_config(backend="dask"):
        yield -1


def _trials_frame(study: Study, point: int, kept: dict[int, dict]) -> pd.DataFrame:
    """Per-trial values of one grid point, in trial order, columns '<variant>/<metric>' [rad]."""
    blocks = sorted(kept)
    trial = np.concatenate([b * study.block_size + np.arange(_block_trials(study, point, b))
                            for b in blocks])
    cols = {"/".join(key): np.concatenate([kept[b][key] for b in blocks])
            for key in kept[blocks[0]]}
    return pd.DataFrame({"point": point, "trial": trial, **cols})


def run_study(study: Study, options: RunOptions = RunOptions(),
              on_point: Callable[[int], Any] | None = None) -> StudyResult:
    """Run every grid point of ``study`` (resuming from checkpoints) and return the statistics."""
    if options.n_jobs < 1:
        raise InputError(f"--n-jobs: must be at least 1 (got {options.n_jobs})")
    root = Path(options.checkpoint_dir or Path("results") / ".checkpoints")
    checkpoints = Checkpoints(root, study)
    keep = study.header.per_trial
    done: dict[int, tuple[PointResult, dict]] = {}
    for gp in study.points:
        loaded = checkpoints.load(gp.index)
        if loaded is not None:
            done[gp.index] = loaded
    todo = [gp.index for gp in study.points if gp.index not in done]
    if done:
        print(f"{study.header.name}: resuming, {len(done)} of {len(study.points)} grid points "
              f"already computed ({checkpoints.dir})", file=sys.stderr)
    chunk_blocks = _chunk_blocks(study, todo, options) if todo else 1
    tasks = _tasks(study, todo, chunk_blocks)
    remaining = {p: _n_blocks(study, p) for p in todo}
    partial: dict[int, tuple[PointStats, dict]] = {p: (PointStats(), {}) for p in todo}

    signed = {m.name: m.signed for _, m in study.metrics}
    h = study.header
    point_tasks = {p: PointTask(study.system, study.points[p].prepared, h.seed, p,
                                h.common_random_numbers, study.block_size, study.points[p].trials)
                   for p in todo}
    total = sum(study.points[p].trials for p in todo)
    bar = tqdm(total=total, unit="trial", unit_scale=True, file=sys.stderr, dynamic_ncols=True,
               disable=not options.progress or not tasks,
               desc=f"{study.header.name}: {len(todo)}/{len(study.points)} points")
    with bar:
        if tasks:
            with _backend(options) as n_jobs:
                parallel = joblib.Parallel(n_jobs=n_jobs, return_as="generator_unordered")
                for point, stats, kept in parallel(
                        joblib.delayed(run_task)(point_tasks[p], blocks, keep, options.reference)
                        for p, blocks in tasks):
                    acc, trials = partial[point]
                    acc.merge(stats)
                    trials.update(kept)
                    remaining[point] -= len(stats.blocks)
                    bar.update(sum(_block_trials(study, point, b) for b in stats.blocks))
                    if remaining[point] == 0:
                        del partial[point]
                        finished = acc.finalize(signed, study.header.confidence)
                        checkpoints.save(point, finished, trials)
                        done[point] = (finished, trials)
                        if on_point is not None:
                            on_point(point)
    points = [done[gp.index][0] for gp in study.points]
    trials = {p: _trials_frame(study, p, done[p][1]) for p in done if done[p][1]}
    return StudyResult(study, points, trials)
