"""Run a study: grid points x blocks of trials, in parallel with joblib (loky or dask).

Reproducibility contract: trials are grouped into fixed *blocks* (``block_size`` trials, part
of the study); every block draws from its own streams (``SeedSequence(seed)`` with spawn key
``(block, source)``, or ``(point, block, source)`` without common random numbers). A *task* is
a run of consecutive blocks of one grid point; tasks may be any multiple of the block size, run
in any order, on any worker or backend. Statistics are combined in block order (see
:mod:`montecarlo.engine.aggregate`), so results are bit-identical for any ``n_jobs``, chunk size
and backend, on machines of one CPU type (numpy's and numba's SIMD code paths depend on it).

With a checkpoint directory, each finished grid point is saved (:mod:`.checkpoints`); rerunning
an interrupted study skips finished points and ends with the same results as an uninterrupted
run. Tasks are generated as they are needed, so memory does not grow with the trial count.
"""

from __future__ import annotations

import _thread
import contextlib
import json
import logging
import math
import os
import re
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd

from montecarlo.engine.aggregate import (
    SPEC_COLUMNS,
    VALUE_COLUMNS,
    PointResult,
    PointStats,
    SpecCheck,
)
from montecarlo.engine.checkpoints import Checkpoints
from montecarlo.engine.nominal import nominal_values
from montecarlo.engine.study import Study
from montecarlo.engine.superquantile import is_cvar_column
from montecarlo.engine.tasks import PointTask, exit_with_parent, run_task
from montecarlo.errors import InputError, RunInterrupted

Backend = Literal["loky", "dask"]
log = logging.getLogger("montecarlo")


@dataclass(frozen=True)
class RunOptions:
    """How to run a study (none of this changes the results)."""

    n_jobs: int | None = None
    """Local workers (or LocalCluster workers); None: the cores available."""
    backend: Backend = "loky"
    scheduler: str | None = None
    chunk_size: int | None = None
    """Trials per task, a multiple of the block size (default: about 4 tasks per worker)."""
    progress: bool = True
    checkpoint_dir: Path | None = None
    """Save each finished grid point here and resume from it; None: no checkpoints."""
    reference: bool = False
    """Use the literal reference implementation instead of a system's fast kernel (slower;
    the statistics agree to about 1e-12, not bit for bit)."""


@dataclass
class StudyResult:
    """Statistics of every grid point of a study, and optional per-trial values."""

    study: Study
    points: list[PointResult]
    trials: dict[int, pd.DataFrame] = field(default_factory=dict)
    resumed: dict[str, Any] = field(default_factory=dict)
    """Grid points taken from checkpoints (``points``) and where (``from``, ``key``)."""
    kernel: str = "reference"
    """``"fast"`` if the system's compiled kernel computed the trials, else ``"reference"``."""
    workers: int | None = 0
    """Worker processes the trials of this run ran on (:func:`planned_workers`): 0 in the
    calling process (a small run, or ``n_jobs`` 1) or if no trial ran (every point resumed or
    reused); None on a dask scheduler given by address (its workers are not counted). For
    :func:`run_until_decided`, the most of any of its rounds."""
    nominal: dict[int, dict[tuple[str, str], float]] | None = None
    """Per grid point, each (variant, metric) in the nominal case [SI units, radians]
    (:mod:`.nominal`); computed on first use."""

    def nominal_values(self) -> dict[int, dict[tuple[str, str], float]]:
        """The nominal case of every grid point (one trial each, every error at its centre)."""
        if self.nominal is None:
            self.nominal = {gp.index: nominal_values(self.study.system, gp.prepared)
                            for gp in self.study.points}
        return self.nominal

    def _sweep_value(self, key: str, value: Any) -> Any:
        """Sweep values as they go in a column: text if the key mixes numbers and text, JSON
        text if any value is a list or a table (a cell holds one value)."""
        values = [p.values[key] for p in self.study.points]
        if any(isinstance(v, (list, dict)) for v in values):
            return json.dumps(value, sort_keys=True)
        kinds = {isinstance(v, str) for v in values}
        return str(value) if len(kinds) > 1 else value

    def to_frame(self) -> pd.DataFrame:
        """Summary: one row per (grid point, variant, metric), values in display units."""
        frames = []
        nominal = self.nominal_values()
        for gp, pr in zip(self.study.points, self.points, strict=True):
            df = pr.summary.copy()
            df["nominal"] = [nominal[gp.index].get((v, m), math.nan)
                             for v, m in zip(df["variant"], df["metric"], strict=True)]
            scale = df["metric"].map({m.name: m.scale for _, m in self.study.metrics})
            values = [c for c in df.columns
                      if c in VALUE_COLUMNS or c in SPEC_COLUMNS or is_cvar_column(c)
                      or c == "nominal"]
            df[values] = df[values].mul(scale, axis=0)
            df.insert(0, "point", gp.index)
            for i, key in enumerate(self.study.sweep_keys):
                df.insert(1 + i, key, self._sweep_value(key, gp.values[key]))
            df.insert(len(self.study.sweep_keys) + 3, "unit",
                      df["metric"].map({m.name: m.unit for _, m in self.study.metrics}))
            frames.append(df)
        out = pd.concat(frames, ignore_index=True)
        invalid_cols = [c for c in out.columns
                        if c.startswith("invalid_") and c != "invalid_fraction"]
        out[invalid_cols] = out[invalid_cols].fillna(0).astype(np.int64)
        return out


def _tasks(study: Study, points: list[int], chunk_blocks: int) -> Iterator[tuple[int, range]]:
    """The tasks, generated as the runner asks for them."""
    for p in points:
        n_blocks = _n_blocks(study, p)
        for s in range(0, n_blocks, chunk_blocks):
            yield p, range(s, min(s + chunk_blocks, n_blocks))


def _n_blocks(study: Study, point: int) -> int:
    return math.ceil(study.points[point].trials / study.block_size)


def _block_trials(study: Study, point: int, block: int) -> int:
    return min(study.block_size, study.points[point].trials - block * study.block_size)


MAX_CHUNK_BLOCKS = 32
"""Default cap on blocks per task, so that progress and checkpoints stay frequent."""


def _chunk_blocks(study: Study, points: list[int], options: RunOptions) -> int:
    """Blocks per task: the requested chunk size, or about four tasks per worker."""
    if options.chunk_size is not None:
        return options.chunk_size // study.block_size
    total_blocks = sum(_n_blocks(study, p) for p in points)
    return min(MAX_CHUNK_BLOCKS, max(1, math.ceil(total_blocks / (4 * (options.n_jobs or 1)))))


def available_cores() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


SCHEDULER_ADDRESS = re.compile(r"^((tcp|tls|ucx)://)?[\w.\-\[\]:]+:\d{1,5}$")
"""What a dask scheduler address looks like: ``[tcp://]host:port``."""

WORKER_WAIT = 30.0
"""Seconds a dask run waits with no worker before it gives up [s]."""


def _watch_workers(client: Any, stop: threading.Event, gone: list[str]) -> None:
    """Interrupt the main thread if the cluster has had no worker for :data:`WORKER_WAIT`."""
    since = None
    while not stop.wait(2.0):
        try:
            workers = client.scheduler_info().get("workers", {})
        except Exception:  # scheduler unreachable: no worker either
            workers = {}
        if workers:
            since = None
            continue
        since = since or time.monotonic()
        if time.monotonic() - since > WORKER_WAIT:
            gone.append(f"no dask worker for {WORKER_WAIT:.0f} s")
            _thread.interrupt_main()
            return


@contextlib.contextmanager
def _backend(options: RunOptions, gone: list[str]) -> Iterator[int]:
    """Context in which joblib uses the requested backend; yields n_jobs for Parallel."""
    import joblib

    if options.backend == "loky":
        with joblib.parallel_config(backend="loky", inner_max_num_threads=1,
                                    initializer=exit_with_parent, initargs=(os.getpid(),)):
            yield options.n_jobs or 1
        return
    from distributed import Client, LocalCluster

    if options.scheduler:
        address = options.scheduler
        try:
            client = Client(address, timeout="10s")
        except Exception as exc:  # refused, timed out, or not speaking dask at all
            reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise InputError(f"--scheduler: no dask scheduler answers at {address!r} "
                             f"({reason[:120]})") from None
        cluster: Any = contextlib.nullcontext()
    else:
        cluster = LocalCluster(n_workers=options.n_jobs, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
    stop = threading.Event()
    watcher = threading.Thread(target=_watch_workers, args=(client, stop, gone), daemon=True)
    with cluster, client, joblib.parallel_config(backend="dask"):
        watcher.start()
        try:
            yield -1
        finally:
            stop.set()


def _trials_frame(study: Study, point: int, kept: dict[int, dict]) -> pd.DataFrame:
    """Per-trial values of one grid point, in trial order, columns '<variant>/<metric>' [rad]."""
    blocks = sorted(kept)
    trial = np.concatenate([b * study.block_size + np.arange(_block_trials(study, point, b))
                            for b in blocks])
    cols = {"/".join(key): np.concatenate([kept[b][key] for b in blocks])
            for key in kept[blocks[0]]}
    return pd.DataFrame({"point": point, "trial": trial, **cols})


def checked_options(study: Study, options: RunOptions) -> RunOptions:
    """Options checked before any work; local workers capped at the cores (one line says so).

    Raises
    ------
    InputError
        ``n_jobs < 1``, a scheduler without the dask backend or not shaped like an address,
        or a chunk size that is not a multiple of the study's block size.
    """
    cores = available_cores()
    if options.n_jobs is None:
        options = replace(options, n_jobs=cores)
    assert options.n_jobs is not None
    if options.n_jobs < 1:
        raise InputError(f"--n-jobs: must be at least 1 (got {options.n_jobs})")
    if options.scheduler is not None:
        if options.backend != "dask":
            raise InputError("--scheduler: only meaningful with --backend dask")
        if not SCHEDULER_ADDRESS.match(options.scheduler):
            raise InputError(f"--scheduler: {options.scheduler!r} is not a dask scheduler "
                             "address (expected tcp://HOST:PORT)")
    bs = study.block_size
    if options.chunk_size is not None and (options.chunk_size <= 0 or options.chunk_size % bs):
        raise InputError(f"--chunk-size: {options.chunk_size} is not a positive multiple of "
                         f"the study's block size {bs}")
    if options.scheduler is None and options.n_jobs > cores:
        log.warning("--n-jobs %d: this machine has %d cores; using %d workers",
                 options.n_jobs, cores, cores)
        return replace(options, n_jobs=cores)
    return options


ESTIMATE_AFTER = 5.0
"""Seconds of running after which the remaining time of a long run is announced [s]."""

IN_PROCESS = 2.0
"""Work estimated below this [s] runs in the calling process: starting workers would cost more."""


REFERENCE_BELOW = 0.5
"""A study whose literal reference path is estimated below this [s] runs it rather than the
compiled kernel, whose loading costs more (the two agree to about 1e-12)."""


def estimated_seconds(study: Study, points: list[int], reference: bool) -> float:
    """Rough single-core time of the trials of ``points`` (the system's cost per trial)."""
    per_trial = getattr(study.system, "seconds_per_trial", 1e-3)
    if reference:
        per_trial = getattr(study.system, "reference_seconds_per_trial", None) or per_trial
    return per_trial * sum(study.points[p].trials for p in points)


def planned_workers(study: Study, points: list[int], options: RunOptions,
                    reference: bool) -> int | None:
    """Worker processes the trials of ``points`` will run on (``options`` checked): 0 for no
    points or in the calling process (one worker asked for on loky, or too little work to pay
    for starting workers), else the workers given a task (at most ``n_jobs``; a study of fewer
    tasks leaves the others idle); None on a dask scheduler given by address, whose workers
    are not counted."""
    work = estimated_seconds(study, points, reference)
    if not points or (options.backend == "loky" and (options.n_jobs == 1 or work < IN_PROCESS)):
        return 0
    if options.scheduler:
        return None
    chunk = _chunk_blocks(study, points, options)
    tasks = sum(math.ceil(_n_blocks(study, p) / chunk) for p in points)
    return min(options.n_jobs or 1, tasks)


def workers_text(workers: int) -> str:
    """Where trials ran (:func:`planned_workers`): 'in the calling process', '2 worker
    processes'."""
    return "in the calling process" if workers == 0 else \
        f"on {workers} worker process{'es' if workers != 1 else ''}"


def plan_text(seconds: float, workers: int | None) -> str:
    """How long and on how many cores (:func:`planned_workers`): 'about 18 s on 2 cores'."""
    if workers is None:
        return f"{about(seconds)} of single-core work, on the dask cluster's workers"
    n = max(workers, 1)
    return f"{about(seconds / n)} on {n} {'core' if n == 1 else 'cores'}"


def uses_reference(study: Study, options: RunOptions) -> bool:
    """Whether the trials go through the literal reference path: asked for, or, for a system
    with a fused kernel, per-trial values kept or a study so small that loading the kernel
    would cost more; a system with a faster path beside its literal one
    (``has_reference_path``) takes the faster one unless asked; one with neither has only its
    literal path. Decided on the whole study, so that resuming never
    changes it."""
    if options.reference:
        return True
    if not hasattr(study.system, "accumulate_block"):
        return not getattr(study.system, "has_reference_path", False)
    if study.header.per_trial:
        return True
    return estimated_seconds(study, list(range(len(study.points))), True) < REFERENCE_BELOW


def _results(study: Study, tasks: Iterator[tuple[int, range]], point_tasks: dict,
             reference: bool, n_jobs: int | None) -> Iterator[Any]:
    """(point, stats, kept) of each task: in this process (``n_jobs`` None), or from the
    workers of the backend entered by the caller."""
    keep = study.header.per_trial
    if n_jobs is None:
        for p, blocks in tasks:
            yield run_task(point_tasks[p], blocks, keep, reference)
        return
    import joblib

    parallel = joblib.Parallel(n_jobs=n_jobs, return_as="generator_unordered")
    yield from parallel(joblib.delayed(run_task)(point_tasks[p], blocks, keep, reference)
                        for p, blocks in tasks)


def run_study(study: Study, options: RunOptions = RunOptions(),
              on_point: Callable[[int], Any] | None = None,
              reuse: dict[int, PointResult] | None = None) -> StudyResult:
    """Run every grid point of ``study`` (resuming from checkpoints) and return the statistics.

    ``reuse`` maps grid points to results already computed for them (not run again).

    Raises
    ------
    RunInterrupted
        Ctrl-C, or a dask cluster without workers; finished points stay checkpointed.
    """
    options = checked_options(study, options)
    checkpoints = None if options.checkpoint_dir is None else \
        Checkpoints(Path(options.checkpoint_dir), study, options.reference)
    done: dict[int, tuple[PointResult, dict]] = {}
    if checkpoints is not None:
        for gp in study.points:
            loaded = checkpoints.load(gp.index)
            if loaded is not None:
                done[gp.index] = loaded
    resumed = sorted(done)
    done.update({p: (pr, {}) for p, pr in (reuse or {}).items()})
    todo = [gp.index for gp in study.points if gp.index not in done]
    if checkpoints is not None and done:
        log.warning("%s: resuming, %d of %d grid points already computed (%s)",
                 study.header.name, len(done), len(study.points), checkpoints.dir)
    chunk_blocks = _chunk_blocks(study, todo, options) if todo else 1
    remaining = {p: _n_blocks(study, p) for p in todo}
    partial: dict[int, tuple[PointStats, dict]] = {p: (PointStats(), {}) for p in todo}

    signed = {m.name: m.signed for _, m in study.metrics}
    spec = study.spec
    check = None if spec is None else SpecCheck(spec.metric, spec.variant, spec.statistic,
                                                spec.limit / study.metric(spec.metric).scale)
    h = study.header
    point_tasks = {p: PointTask(study.system, study.points[p].prepared, h.seed, p,
                                h.common_random_numbers, study.block_size, study.points[p].trials)
                   for p in todo}
    total = sum(study.points[p].trials for p in todo)
    reference = uses_reference(study, options)
    work = estimated_seconds(study, todo, reference)
    workers = planned_workers(study, todo, options, reference)
    note = getattr(study.system, "first_use_note", None)
    if todo and note is not None and not reference:
        message = note([study.points[p].prepared for p in todo])
        if message:
            log.info("%s: %s", h.name, message)
    gone: list[str] = []
    announced, ran = False, 0
    try:
        from tqdm import tqdm

        with contextlib.ExitStack() as stack:
            # workers (and a dask scheduler) first: a scheduler that does not answer is
            # reported before any plan or progress bar is shown
            n_jobs = None if workers == 0 else stack.enter_context(_backend(options, gone))
            if todo:
                log.info("%s: %d of %d grid points to run, %s trials (%s)", h.name, len(todo),
                         len(study.points), f"{total:,}", plan_text(work, workers))
            bar = stack.enter_context(tqdm(
                total=total, unit="trial", unit_scale=True, dynamic_ncols=True,
                disable=not options.progress or not todo,
                desc=f"{h.name}: {len(todo)}/{len(study.points)} points"))
            start = time.monotonic()
            for point, stats, kept in _results(study, _tasks(study, todo, chunk_blocks),
                                               point_tasks, reference, n_jobs):
                acc, trials = partial[point]
                acc.merge(stats)
                trials.update(kept)
                remaining[point] -= stats.blocks
                bar.update(stats.trials)
                ran += stats.trials
                elapsed = time.monotonic() - start
                if not announced and elapsed > ESTIMATE_AFTER and ran < total:
                    announced = True
                    log.info("%s: %s left at %s trials/s", h.name,
                             about((total - ran) * elapsed / ran), f"{ran / elapsed:,.0f}")
                if remaining[point] == 0:
                    del partial[point]
                    finished = acc.finalize(signed, h.confidence, check,
                                            study.points[point].sampled)
                    if checkpoints is not None:
                        checkpoints.save(point, finished, trials)
                    done[point] = (finished, trials)
                    if on_point is not None:
                        on_point(point)
    except KeyboardInterrupt:
        saved = len(done) - len(resumed)
        where = f"; rerun the same command to resume from {checkpoints.dir}" \
            if checkpoints is not None and done else ""
        why = gone[0] if gone else "interrupted"
        raise RunInterrupted(f"{h.name}: {why}; {len(done)} of {len(study.points)} grid points "
                             f"finished ({saved} in this run){where}",
                             1 if gone else 130) from None
    points = [done[gp.index][0] for gp in study.points]
    trials = {p: _trials_frame(study, p, done[p][1]) for p in done if done[p][1]}
    origin = {"points": resumed, "from": str(checkpoints.dir), "key": checkpoints.key} \
        if resumed and checkpoints is not None else {}
    return StudyResult(study, points, trials, origin, "reference" if reference else "fast",
                       workers=workers)


DEFAULT_MAX_TRIALS = 1_048_576
"""Default cap on the trials per grid point of :func:`run_until_decided`."""


def run_until_decided(study: Study, options: RunOptions,
                      max_trials: int = DEFAULT_MAX_TRIALS) -> StudyResult:
    """Run, then double the trials of every sampled grid point whose spec verdict is
    ``undecided`` and run it again, until every verdict is decided or ``max_trials`` is reached.

    Each round draws the same nested streams (seed, point, block), so a grown point's first
    trials are those of the round before; its blocks are computed again (the total work is
    at most twice that of the last round). Decided points keep their result. Checkpoints are
    not used.

    Every round takes the path a direct run of ``study`` takes (:func:`uses_reference`,
    decided once, before the first round), whatever ``max_trials`` is: each point's result is
    bit for bit that of a direct run of its final trials on that path
    (``run --trials N [--reference]``; the result's ``kernel`` says which).

    Raises
    ------
    InputError
        The study has no ``[spec]`` to decide, or ``max_trials`` is below its trials.
    """
    if study.spec is None:
        raise InputError(f"{study.path}: spec: --until-decided needs a [spec] table to decide")
    most = max(gp.trials for gp in study.points)
    if max_trials < most:
        raise InputError(f"--max-trials: {max_trials:,} is below the study's {most:,} trials "
                         "per grid point; give at least that many (or fewer --trials)")
    options = replace(options, checkpoint_dir=None,
                      reference=uses_reference(study, checked_options(study, options)))
    result = run_study(study, options)
    trials = dict(result.trials)
    workers = [result.workers]
    while True:
        grow = {}
        for gp, pr in zip(study.points, result.points, strict=True):
            undecided = "verdict" in pr.summary and (pr.summary["verdict"] == "undecided").any()
            if undecided and gp.sampled and gp.trials < max_trials:
                grow[gp.index] = min(2 * gp.trials, max_trials)
        if not grow:
            break
        log.info("%s: %d grid point(s) undecided; running them again with %s trials",
                 study.header.name, len(grow),
                 ", ".join(sorted({f"{t:,}" for t in grow.values()})))
        study = study.with_trials(grow)
        reuse = {p: pr for p, pr in enumerate(result.points) if p not in grow}
        result = run_study(study, options, reuse=reuse)
        workers.append(result.workers)
        trials = {**{p: t for p, t in trials.items() if p not in grow}, **result.trials}
    left = [gp.index for gp, pr in zip(study.points, result.points, strict=True)
            if (pr.summary.get("verdict", pd.Series(dtype=str)) == "undecided").any()]
    if left:
        log.warning("%s: still undecided at %s trials: grid point(s) %s", study.header.name,
                    f"{max_trials:,}", ", ".join(map(str, left)))
    widest = None if None in workers else max(n for n in workers if n is not None)
    return replace(result, trials=dict(sorted(trials.items())), workers=widest)


def about(seconds: float) -> str:
    """An estimated duration: 'about 45 s', 'under a second'."""
    text = duration_text(seconds)
    return text if text.startswith("under") else f"about {text}"


def duration_text(seconds: float) -> str:
    """A duration for people: 45 s, 12 min, 3.5 h, 2.1 days, 4.0e+03 years."""
    for unit, size in (("years", 365.25 * 86400), ("days", 86400), ("h", 3600), ("min", 60)):
        if seconds >= 2 * size:
            value = seconds / size
            return f"{value:.2g} {unit}" if value < 1e4 else f"{value:.1e} {unit}"
    return f"{seconds:.0f} s" if seconds >= 1 else "under a second"
