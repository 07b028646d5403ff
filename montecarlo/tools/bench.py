"""Benchmark of the ground-calibration trial paths: ``montecarlo bench [--json] [--quick]``.

Workload: one sampled Table 1 configuration (seed 000, section 1.4: 90 x 90 deg, 512 x 512 px,
true angles 30/20/10 deg, L = 100 m, H = 1 m, placement errors uniform +-0.1 m, height-scale
error +-1 mm, pixel error uniform +-0.5 px common to both targets), both solver variants and
all six metrics per trial. A trial is one full draw -> placement -> pixels -> two solves ->
metrics; the runner paths include the streaming statistics.

(a) a Python loop of single trials through the literal reference, (b) the vectorised literal
reference (one block at a time, with streaming statistics), (c) the fused kernel on one core,
(d) the fused kernel through the study runner on two cores (loky; at 10^7 trials or more,
since below about that the runner keeps a ground study in the calling process; each row says
how it ran). Each figure is the median of ``repeats`` timed runs in this invocation, after one
untimed warm-up.

Seed 001 stabilisation beside them: trials of the base point of ``studies/stabilization.toml``
(simulate a 60 s run at 100 Hz, estimate by RLS, rerun compensated) through the runner on one
core, (e) with the literal numpy functions (``reference=True``), (f) with the compiled
kernels of :mod:`montecarlo.seed001.simulate_kernels` and
:mod:`montecarlo.seed001.estimate_kernels`; timed in alternation, median of ``min(repeats, 3)``
runs each.

``diagnose camera`` on Zhang's real calibration set, the whole command once per stated pixel
sigma (:mod:`montecarlo.tools.bench_diagnosis`).
"""

from __future__ import annotations

import contextlib
import functools
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import psutil

from montecarlo.engine.aggregate import N_BINS, PointStats, bin_index
from montecarlo.engine.distributions import Streams
from montecarlo.engine.runner import RunOptions, run_study, workers_text
from montecarlo.seed000 import ground
from montecarlo.systems import study_from_dict
from montecarlo.tools.bench_diagnosis import camera_diagnoses, format_diagnoses

WORKLOAD = {
    "study": {"name": "bench", "system": "ground", "trials": 1, "seed": 1},
    "sensor": {"fov_deg": [90.0, 90.0], "pixels": [512, 512]},
    "mounting": {"psi_deg": 30.0, "theta_deg": 20.0, "gamma_deg": 10.0},
    "geometry": {"L_m": 100.0, "H_m": 1.0},
    "errors": {"dx_m": {"dist": "uniform", "bound": 0.1},
               "dy_m": {"dist": "uniform", "bound": 0.1},
               "dh1_m": {"dist": "uniform", "bound": 0.1},
               "dh_m": {"dist": "uniform", "bound": 0.001},
               "pixel_px": {"dist": "uniform", "bound": 0.5},
               "pixel_relation": "common"},
}


def _study(trials: int):
    raw = {**WORKLOAD, "study": {**WORKLOAD["study"], "trials": trials}}
    return study_from_dict(raw, "<bench>")


def _median_rate(fn, trials: int, repeats: int) -> float:
    fn()  # warm-up: compilation, caches, worker pool
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return trials / statistics.median(times)


@functools.cache
def _ceiling_kernels():
    """Compiled loops for two ceilings of the roofline (numba: imported only here).

    ``roots_and_divisions(x, out)``: the 12 square roots and 10 divisions of one trial of the
    solve (``ground_kernel._trial``), on independent data, summed: the throughput of the
    operations that set the solve's pace. ``increments(bins, hist)``: the histogram increments
    of the accumulation alone, ``hist[r, bins[r, i]] += 1`` row after row, as it does them.
    """
    import numba as nb

    @nb.njit(nogil=True, error_model="numpy", parallel=True)
    def roots_and_divisions(x, out):  # pragma: no cover - compiled
        for i in nb.prange(x.shape[0]):
            a = x[i]
            s = (np.sqrt(a + 1.0) + np.sqrt(a + 2.0) + np.sqrt(a + 3.0) + np.sqrt(a + 4.0)
                 + np.sqrt(a + 5.0) + np.sqrt(a + 6.0) + np.sqrt(a + 7.0) + np.sqrt(a + 8.0)
                 + np.sqrt(a + 9.0) + np.sqrt(a + 10.0) + np.sqrt(a + 11.0)
                 + np.sqrt(a + 12.0))
            s += (1.0 / (a + 1.5) + 1.0 / (a + 2.5) + 1.0 / (a + 3.5) + 1.0 / (a + 4.5)
                  + 1.0 / (a + 5.5) + 1.0 / (a + 6.5) + 1.0 / (a + 7.5) + 1.0 / (a + 8.5)
                  + 1.0 / (a + 9.5) + 1.0 / (a + 10.5))
            out[i] = s

    @nb.njit(nogil=True)
    def increments(bins, hist):  # pragma: no cover - compiled
        for r in range(bins.shape[0]):
            h = hist[r]
            b = bins[r]
            for i in range(b.shape[0]):
                h[b[i]] += 1

    return roots_and_divisions, increments


def naive_rate(n: int, repeats: int) -> float:
    """(a) single trials in a Python loop through ground.simulate and solution_metrics."""
    study = _study(n)
    system, p = study.system, study.points[0].prepared
    true, e = system.draws(p, Streams(1, 0, 0), 0, n)

    def run() -> None:
        for i in range(n):
            sols = ground.simulate(p.camera, true, p.L, p.H, dx=e[0, i], dy=e[1, i],
                                   dh1=e[2, i], dh=e[3, i], pixel_error_a=e[4:6, i],
                                   pixel_error_b=e[6:8, i])
            for sol in sols.values():
                ground.solution_metrics(sol, true)

    return _median_rate(run, n, repeats)


def _block_rate(n: int, repeats: int, fast: bool) -> float:
    study = _study(n)
    system, p = study.system, study.points[0].prepared
    bs = study.block_size

    def run() -> None:
        stats = PointStats()
        for b, first in enumerate(range(0, n, bs)):
            m = min(bs, n - first)
            streams = Streams(1, 0, b)
            if fast:
                system.accumulate_block(p, streams, first, m, b, stats)
            else:
                stats.add_block(b, *system.simulate_block(p, streams, first, m), m)

    return _median_rate(run, n, repeats)


def ground_roofline(n: int, repeats: int) -> dict[str, Any]:
    """Where the fast ground path's time goes on one core, stage by stage, against ceilings.

    The stages of ``GroundSystem.accumulate_block`` (draws, solve, metrics, accumulation) are
    timed over ``n`` trials of the workload; each against its own ceiling, measured in the
    same run on the same chunks (``ground_kernel.SOLVE_CHUNK`` trials): the draws against
    the generator alone filling as many U[0, 1) numbers into a reused buffer, the metrics
    against the same ufuncs alone on contiguous copies of the same arguments, the solve and
    the accumulation against a memory copy of as many bytes as they read and write. Times
    are CPU times of this thread (so that other processes' load does not enter; the kernels
    run in this thread), medians of ``repeats`` runs [ns per trial]; ``fraction`` is
    ceiling / stage.

    A memory copy is not what bounds the solve or the accumulation, so each also gets the
    ceiling of the work that does (``bound``): the solve's 12 square roots and 10 divisions
    per trial alone, and the accumulation's histogram increments alone (the bins of the same
    metric values, into histogram rows of the same size, in the same order). ``bound`` is
    the larger of a stage's ceilings (the one that binds; the ceiling itself for the draws
    and the metrics), ``bound_fraction`` = bound / stage. ``floor_ns_per_trial`` is the sum of
    the stages' bounds: the time of a trial with every stage at its binding ceiling, and
    ``floor_speedup`` = total / floor the most that rearranging these operations can gain
    (beyond it takes other operations: another generator, other metric functions).
    """
    from montecarlo.seed000 import ground_kernel as gk
    from montecarlo.systems.ground import STAGES, _scratch

    study = _study(n)
    system, p = study.system, study.points[0].prepared
    bs = study.block_size
    m = min(gk.SOLVE_CHUNK, n)
    chunks = -(-n // m)

    def stages() -> dict[str, float]:
        clock: dict[str, float] = {}
        stats = PointStats()
        for b, first in enumerate(range(0, n, bs)):
            system.accumulate_block(p, Streams(1, 0, b), first, min(bs, n - first), b, stats,
                                    clock)
        return clock

    _, rows, affine = system.unit_draws(p, Streams(1, 0, 0), 0, m)
    n_random = len({id(r) for r in rows})  # distinct rows drawn (common pixel rows shared)
    flags, fields, _, out_rows = _scratch(m)
    C = np.ascontiguousarray(np.eye(3).reshape(9))
    cam = p.camera
    gk.solve_chunk(C, p.L, p.H, float(cam.k_x), float(cam.k_z), cam.n_x / 2.0, cam.n_z / 2.0,
                   rows, affine, flags, fields, out_rows)
    args = [fields[a:b].copy() for a, b in ((0, 6), (6, 12), (12, 14), (14, 16))]
    gk.metrics_in_place(fields)
    values = fields[gk.METRIC_ROWS]
    bins = np.where(np.isfinite(values), bin_index(np.nan_to_num(values)), 0).astype(np.int32)
    hist = np.zeros((len(gk.METRIC_ROWS), N_BINS), np.int64)
    roots_and_divisions, increments = _ceiling_kernels()
    x, y = np.linspace(0.0, 1.0, m), np.empty(m)
    work = [a.copy() for a in args]
    gen = np.random.Generator(np.random.PCG64(1))
    draw_buf = np.empty((n_random, m))
    solve_bytes = n_random * 8 + 16 * 8 + 2 * 2  # rows in; 16 field rows, 2 flags out
    acc_bytes = len(gk.METRIC_ROWS) * 8 + 2 * 2 + 4  # metric rows, flags in; bins out
    copies = {k: (np.ones(v * m // 8), np.empty(v * m // 8))
              for k, v in (("solve", solve_bytes), ("accumulation", acc_bytes))}

    def generator() -> None:
        for _ in range(chunks):
            for row in draw_buf:
                gen.random(out=row)

    def ufuncs() -> None:
        for _ in range(chunks):
            for a, w in zip(args, work, strict=True):
                np.copyto(w, a)  # fresh arguments each time (not timed apart; see below)
            np.arctan2(work[0], work[1], out=work[0])
            np.arccos(work[2], out=work[2])
            np.arcsin(work[3], out=work[3])

    def refresh() -> None:
        for _ in range(chunks):
            for a, w in zip(args, work, strict=True):
                np.copyto(w, a)

    def memcpy(key: str) -> None:
        src, dst = copies[key]
        for _ in range(chunks):
            np.copyto(dst, src)

    def compute() -> None:
        for _ in range(chunks):
            roots_and_divisions(x, y)

    def scatter() -> None:
        for _ in range(chunks):
            increments(bins, hist)

    def timed(fn) -> float:
        t0 = time.thread_time()
        fn()
        return time.thread_time() - t0

    stages()  # warm-up: compilation, caches
    compute()
    scatter()
    spent: dict[str, list[float]] = {k: [] for k in (*STAGES, "total")}
    ceiling: dict[str, list[float]] = {k: [] for k in (*STAGES, "compute", "increments")}
    for _ in range(repeats):  # stages and ceilings alternate
        clock = stages()
        for k in STAGES:
            spent[k].append(clock[k])
        spent["total"].append(sum(clock.values()))
        ceiling["draws"].append(timed(generator))
        ceiling["metrics"].append(max(timed(ufuncs) - timed(refresh), 0.0))
        ceiling["solve"].append(timed(functools.partial(memcpy, "solve")))
        ceiling["accumulation"].append(timed(functools.partial(memcpy, "accumulation")))
        ceiling["compute"].append(timed(compute))
        ceiling["increments"].append(timed(scatter))
    scale = 1e9 / n
    what = {"draws": f"the generator alone, {n_random} U[0, 1) per trial",
            "solve": f"memory copy of {solve_bytes} B per trial (draws in, fields out)",
            "metrics": "the same ufuncs alone (arctan2 x6, arccos x2, arcsin x2)",
            "accumulation": f"memory copy of {acc_bytes} B per trial (metrics in, bins out)"}
    second = {"solve": ("compute", "its 12 square roots and 10 divisions alone"),
              "accumulation": ("increments", f"its {len(gk.METRIC_ROWS)} histogram "
                                             "increments alone")}
    out: dict[str, Any] = {"trials": n, "sub_chunk": m, "stages": []}
    for k in STAGES:
        stage = statistics.median(spent[k]) * scale
        ceil = statistics.median(ceiling[k]) * scale
        bound, bound_what = ceil, what[k]
        if k in second:
            other = statistics.median(ceiling[second[k][0]]) * scale
            if other > ceil:
                bound, bound_what = other, second[k][1]
        out["stages"].append({"stage": k, "ns_per_trial": stage, "ceiling": what[k],
                              "ceiling_ns_per_trial": ceil,
                              "fraction": ceil / stage if stage > 0 else float("nan"),
                              "bound": bound_what, "bound_ns_per_trial": bound,
                              "bound_fraction": bound / stage if stage > 0 else float("nan")})
    out["total_ns_per_trial"] = statistics.median(spent["total"]) * scale
    out["floor_ns_per_trial"] = sum(s["bound_ns_per_trial"] for s in out["stages"])
    out["floor_speedup"] = out["total_ns_per_trial"] / out["floor_ns_per_trial"]
    return out


def format_roofline(r: dict[str, Any]) -> list[str]:
    """The roofline table of :func:`ground_roofline`."""
    total = r["total_ns_per_trial"]
    lines = [f"roofline of the fused ground path, one core, CPU time ({r['trials']:,} trials "
             f"in chunks of {r['sub_chunk']:,}); "
             "fraction = ceiling / stage:",
             f"  {'stage':<13}{'ns/trial':>9}{'share':>7}  {'ceiling ns/trial':>16}"
             f"{'fraction':>9}  ceiling"]
    for s in r["stages"]:
        lines.append(f"  {s['stage']:<13}{s['ns_per_trial']:>9.1f}"
                     f"{100 * s['ns_per_trial'] / total:>6.0f}%  "
                     f"{s['ceiling_ns_per_trial']:>16.1f}{100 * s['fraction']:>8.0f}%  "
                     f"{s['ceiling']}")
    lines.append(f"  {'total':<13}{total:>9.1f}   100%  ({1e3 / total:.1f} M trials/s)")
    binding = [s for s in r["stages"] if "bound" in s and s["bound"] != s["ceiling"]]
    if binding:
        lines.append("  the work that binds where a memory copy does not:")
        for s in binding:
            lines.append(f"  {s['stage']:<13}{s['ns_per_trial']:>9.1f}{'':>7}  "
                         f"{s['bound_ns_per_trial']:>16.1f}{100 * s['bound_fraction']:>8.0f}%  "
                         f"{s['bound']}")
    lines.append(f"  every stage at its binding ceiling: {r['floor_ns_per_trial']:.1f} ns/trial, "
                 f"at most {r['floor_speedup']:.2f}x faster with these operations")
    return lines


def runner_rate(n: int, repeats: int, n_jobs: int | None = None) -> dict[str, Any]:
    """(d) trials per second through run_study (``n_jobs`` as the CLI's ``--n-jobs``), and how
    the runner ran them: ``kernel`` (``"fast"`` or ``"reference"``) and ``workers`` (0 in the
    calling process). The runner decides both from the study's size, so a small study runs
    the literal path or stays in the calling process however many cores there are."""
    study = _study(n)
    options = RunOptions(n_jobs=n_jobs, progress=False)  # no checkpoints: each run afresh
    ran: list[Any] = []
    rate = _median_rate(lambda: ran.append(run_study(study, options)), n, repeats)
    return {"trials": n, "trials_per_s": rate, "kernel": ran[-1].kernel,
            "workers": ran[-1].workers}


def runner_path(s: dict[str, Any]) -> str:
    """How the runner ran one row of the scaling series, in words."""
    path = "fused kernel" if s["kernel"] == "fast" else "literal reference"
    return f"{path}, {workers_text(s['workers'])}"


STABILIZATION_WORKLOAD = {
    "study": {"name": "bench-stabilization", "system": "stabilization", "trials": 1, "seed": 1},
    "params": {"rock_amplitude_deg": 5.0, "duration_s": 60.0, "image_noise_px": 0.1,
               "gyro_noise_deg_per_root_h": 0.01},
}
def stabilization_rates(n_reference: int, n_fast: int, repeats: int, duration: float = 60.0
                        ) -> tuple[float, float]:
    """(e), (f): stabilisation trials per second through run_study on one core, in the calling
    process, on the literal path (``reference=True``) and on the compiled kernels.

    The two paths alternate (one warm-up each, then ``repeats`` timed pairs) so that a change
    of the host's load between them does not enter their ratio.
    """
    runs = []
    for n, reference in ((n_reference, True), (n_fast, False)):
        raw = {**STABILIZATION_WORKLOAD,
               "study": {**STABILIZATION_WORKLOAD["study"], "trials": n},
               "params": {**STABILIZATION_WORKLOAD["params"], "duration_s": duration}}
        options = RunOptions(n_jobs=1, progress=False, reference=reference)
        runs.append(functools.partial(run_study, study_from_dict(raw, "<bench>"), options))
    for run in runs:
        run()  # warm-up: compilation, caches
    times: list[list[float]] = [[], []]
    for _ in range(repeats):
        for run, spent in zip(runs, times, strict=True):
            t0 = time.perf_counter()
            run()
            spent.append(time.perf_counter() - t0)
    return n_reference / statistics.median(times[0]), n_fast / statistics.median(times[1])


def study_memory(trials: int) -> dict[str, float]:
    """Peak memory of ``montecarlo run`` on the workload with ``trials`` trials [MB].

    Runs the CLI in a fresh process (as a user would) and polls its process tree every 0.1 s:
    the largest RSS of any one process, the largest sum of RSS (which counts shared libraries
    once per process) and the largest sum of PSS (shared pages split between their users).
    """
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.toml"
        lines = []
        for section, table in {**WORKLOAD, "study": {**WORKLOAD["study"], "trials": trials}
                               }.items():
            lines.append(f"[{section}]")
            lines += [f"{k} = {_toml(v)}" for k, v in table.items()]
        path.write_text("\n".join(lines) + "\n")
        proc = psutil.Popen([sys.executable, "-m", "montecarlo", "run", str(path),
                             "--quiet", "--out", str(Path(tmp) / "out")],
                            stdout=subprocess.DEVNULL)
        peak = {"max_process_rss_mb": 0.0, "tree_rss_mb": 0.0, "tree_pss_mb": 0.0}
        while proc.poll() is None:
            rss = pss = biggest = 0.0
            for p in [proc, *proc.children(recursive=True)]:
                with contextlib.suppress(psutil.Error):
                    info = p.memory_full_info()
                    rss += info.rss
                    pss += info.pss
                    biggest = max(biggest, info.rss)
            for key, value in zip(peak, (biggest, rss, pss), strict=True):
                peak[key] = max(peak[key], value / 2**20)
            time.sleep(0.1)
        if proc.returncode != 0:
            raise RuntimeError(f"montecarlo run exited with {proc.returncode}")
    return peak


def _toml(value: Any) -> str:
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + " }"
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return f'"{value}"' if isinstance(value, str) else repr(value)


def compile_seconds() -> float:
    """First-run compile time of the kernel with an empty numba cache (in a fresh process)."""
    code = ("import time; t = time.perf_counter(); from montecarlo.tools import bench; "
            "bench._block_rate(8192, 1, True); print(time.perf_counter() - t)")
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                             text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def host_probe() -> float:
    """Speed of the host right now: numpy arctan2 evaluations per second on one core, in
    cache. On a shared (virtual) machine it moves with the neighbours' load; trial rates move
    with it, so compare runs through it."""
    x = np.linspace(-1.0, 1.0, 4096)
    y = x + 2.0
    out = np.empty_like(x)
    return _median_rate(lambda: [np.arctan2(x, y, out=out) for _ in range(200)], 200 * 4096, 5)


def run_bench(quick: bool = False, repeats: int = 5) -> dict[str, Any]:
    """All figures of the benchmark.

    ``quick`` (what ``make bench`` runs, under 30 s on two quiet cores): the roofline and every
    row at small sizes, the runner scaling at 10^6 and 10^7 trials (below about 10^7 the runner
    keeps a ground study in the calling process: row (d) is the 10^7 run, on the workers), the
    memory of one 10^6-trial study, no cold-cache compile, the camera diagnosis at 0.25 px.
    Otherwise (``--full``) the sizes of the full benchmark: scaling up to 10^8 trials, memory
    at 10^4 and 10^8, the compile time with an empty cache, the camera diagnosis at every
    sigma from 0.15 to 0.3 px and ``auto``.
    """
    started, load_before = time.perf_counter(), list(os.getloadavg())
    probe_before = host_probe()
    big = 10**6 if quick else 10**8
    sizes = [10**6, 10**7] if quick else [10**k for k in range(4, 9)]
    roofline = ground_roofline(2**20 if quick else 2**23, repeats)
    naive = naive_rate(200 if quick else 2000, repeats)
    reference = _block_rate(2**16 if quick else 2**18, repeats, fast=False)
    fast1 = _block_rate(2**20 if quick else 2**22, repeats, fast=True)
    scaling = [runner_rate(n, repeats) for n in sizes]
    fast2 = scaling[-1]["trials_per_s"]
    memory = {n: study_memory(n) for n in ((big,) if quick else (sizes[0], big))}
    duration = 5.0 if quick else 60.0
    stab_reference, stab_fast = stabilization_rates(8 if quick else 64, 64 if quick else 256,
                                                    min(repeats, 3), duration)
    diagnoses = camera_diagnoses(quick)
    return {
        "quick": quick,
        "load_average": load_before,
        "roofline": roofline,
        "naive_trials_per_s": naive,
        "reference_trials_per_s": reference,
        "fast_trials_per_s_1core": fast1,
        "fast_trials_per_s_2core": fast2,
        "peak_rss_mb": memory[big]["max_process_rss_mb"],
        "peak_tree_rss_mb": memory[big]["tree_rss_mb"],
        "peak_tree_pss_mb": memory[big]["tree_pss_mb"],
        "memory_by_trials": {str(n): m for n, m in memory.items()},
        "peak_memory_trials": big,
        "ratio_2core_to_naive": fast2 / naive,
        "ratio_1core_to_reference": fast1 / reference,
        "ratio_2core_to_1core": fast2 / fast1,
        "stabilization_reference_trials_per_s": stab_reference,
        "stabilization_fast_trials_per_s": stab_fast,
        "stabilization_ratio": stab_fast / stab_reference,
        "stabilization_duration_s": duration,
        "camera_diagnoses": diagnoses,
        "compile_seconds_cold_cache": None if quick else compile_seconds(),
        "host_probe_atan2_per_s": [probe_before, host_probe()],
        "load_average_after": list(os.getloadavg()),
        "bench_seconds": time.perf_counter() - started,
        "scaling": scaling,
        "repeats": repeats,
        "cpu_count": os.cpu_count(),
        "numpy": np.__version__,
        "workload": "seed 000 Table 1, sampled: L=100 m, H=1 m, df=0.5 px common, both "
                    "solvers, 6 metrics, streaming statistics",
    }


def format_bench(r: dict[str, Any]) -> str:
    rows = [("(a) naive per-trial loop, literal reference", "naive_trials_per_s"),
            ("(b) vectorised literal reference, 1 core", "reference_trials_per_s"),
            ("(c) fused kernel, 1 core", "fast_trials_per_s_1core"),
            ("(d) through the runner: " + runner_path(r["scaling"][-1]),
             "fast_trials_per_s_2core")]
    compiled = r["compile_seconds_cold_cache"]
    width = max(46, *(len(label) + 1 for label, _ in rows))
    lines = [
        f"workload: {r['workload']}",
        f"median of {r['repeats']} runs each, {r['cpu_count']} CPUs, "
        f"{'quick' if r['quick'] else 'full'} sizes, {r['bench_seconds']:.0f} s in all; "
        "load average "
        + " ".join(f"{x:.2f}" for x in r["load_average"]) + " at the start, "
        + " ".join(f"{x:.2f}" for x in r["load_average_after"]) + " at the end",
        "",
        *format_roofline(r["roofline"]),
        "",
        *(f"{label:<{width}}{r[key]:>14,.0f} trials/s" for label, key in rows),
        "",
        f"(d)/(a) = {r['ratio_2core_to_naive']:,.0f}x   (c)/(b) = "
        f"{r['ratio_1core_to_reference']:.1f}x   (d)/(c) = {r['ratio_2core_to_1core']:.2f}x",
        f"memory of `montecarlo run` on a {r['peak_memory_trials']:.0e}-trial study: largest "
        f"process RSS {r['peak_rss_mb']:.0f} MB; whole tree RSS {r['peak_tree_rss_mb']:.0f} MB,"
        f" PSS {r['peak_tree_pss_mb']:.0f} MB",
        "first-run compile time (empty numba cache): "
        + (f"{compiled:.1f} s" if compiled is not None else "not measured (--full measures it)"),
        "host speed probe (numpy arctan2 per second, one core, before/after): "
        + " / ".join(f"{p / 1e6:.0f} M" for p in r["host_probe_atan2_per_s"])
        + " (a shared host's speed moves with its load; so do the rates above)",
        "",
        f"seed 001 stabilisation ({r['stabilization_duration_s']:.0f} s run at 100 Hz: "
        "simulate, RLS estimate, compensated rerun), through the runner, 1 core:",
        f"{'(e) literal numpy reference':<46}{r['stabilization_reference_trials_per_s']:>14,.2f}"
        " trials/s",
        f"{'(f) compiled kernels':<46}{r['stabilization_fast_trials_per_s']:>14,.2f} trials/s",
        f"(f)/(e) = {r['stabilization_ratio']:.1f}x",
        "",
        *format_diagnoses(r.get("camera_diagnoses", [])),
        "",
        "scaling through the runner (it picks the path and the workers by the study's size):",
    ]
    for s in r["scaling"]:
        lines.append(f"  {s['trials']:>12,} trials  {s['trials_per_s']:>14,.0f} trials/s  "
                     f"({runner_path(s)})")
    for n, m in r["memory_by_trials"].items():
        lines.append(f"memory at {int(n):,} trials: largest process {m['max_process_rss_mb']:.0f}"
                     f" MB, tree RSS {m['tree_rss_mb']:.0f} MB, tree PSS {m['tree_pss_mb']:.0f} MB")
    return "\n".join(lines)
