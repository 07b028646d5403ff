"""The study runner: reproducibility across jobs, chunks and backends; resume; Table 1 path."""

import math
import os
import signal
import subprocess
import sys
import textwrap
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from montecarlo.engine import runner
from montecarlo.engine.runner import RunOptions, run_study
from montecarlo.seed000 import table1
from montecarlo.systems import load_study
from tests.forked_cli import montecarlo_cli

ROOT = Path(__file__).parent.parent

SMALL = """
[study]
name = "small"
system = "ground"
trials = 3000
seed = 7
block_size = 500

[sensor]
fov_deg = [60.0, 45.0]
pixels = [1024, 768]

[mounting]
psi_deg = { dist = "uniform", bound = 10.0 }
theta_deg = 5.0
gamma_deg = -3.0

[geometry]
L_m = 100.0
H_m = 2.0

[errors]
dx_m = { dist = "uniform", bound = 0.1 }
dy_m = { dist = "normal", sigma = 0.05 }
dh1_m = { dist = "uniform", bound = 0.1 }
dh_m = { dist = "uniform", bound = 0.002 }
pixel_px = { dist = "normal", sigma = 0.4 }
pixel_relation = 0.5

[[sweep]]
"geometry.L_m" = [50.0, 200.0]
"""


@pytest.fixture(scope="module")
def small_study(tmp_path_factory):
    p = tmp_path_factory.mktemp("study") / "small.toml"
    p.write_text(textwrap.dedent(SMALL))
    return load_study(p)


@pytest.fixture(scope="module", params=["fast", "reference"])
def kernel(request):
    """Both paths, each through workers: this study is small enough that the runner would
    otherwise keep it in process on the reference path."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(runner, "REFERENCE_BELOW", 0.0 if request.param == "fast" else math.inf)
        mp.setattr(runner, "IN_PROCESS", 0.0)
        yield request.param


def _workers(n_jobs):
    """Loky workers a run asked for ``n_jobs`` gets (capped at the cores; one runs in process)."""
    n = min(n_jobs, runner.available_cores())
    return 0 if n == 1 else n


def _summary(study, tmp_path, kernel=None, workers=None, **kw):
    ck = tmp_path / f"ck-{len(list(tmp_path.iterdir()))}"
    opts = RunOptions(progress=False, checkpoint_dir=ck, **kw)
    result = run_study(study, opts)
    assert kernel is None or result.kernel == kernel
    assert workers is None or result.workers == workers
    return result.to_frame()


@pytest.fixture(scope="module")
def reference(small_study, kernel, tmp_path_factory):
    return _summary(small_study, tmp_path_factory.mktemp("ref"), kernel, n_jobs=1)


def test_small_studies_run_the_reference_path_large_ones_the_kernel(small_study):
    assert runner.uses_reference(small_study, RunOptions())
    big = load_study(small_study.path, trials=10**6)
    assert not runner.uses_reference(big, RunOptions())
    assert runner.uses_reference(big, RunOptions(reference=True))


@pytest.mark.parametrize("kw", [
    {"n_jobs": 2},
    {"n_jobs": 2, "chunk_size": 500},
    {"n_jobs": 2, "chunk_size": 1500},
    {"n_jobs": 1, "chunk_size": 3000},
])
def test_bit_identical_for_any_jobs_and_chunks(small_study, kernel, reference, tmp_path, kw):
    got = _summary(small_study, tmp_path, kernel, workers=_workers(kw["n_jobs"]), **kw)
    pd.testing.assert_frame_equal(got, reference, check_exact=True)


@pytest.mark.parametrize("kernel", ["fast", pytest.param("reference", marks=pytest.mark.slow)],
                         indirect=True)
def test_bit_identical_on_dask_local_cluster(small_study, kernel, reference, tmp_path):
    """The dask backend gives the result of one in-process job. Slow on the reference path (a
    second local cluster): by default, the dask backend is checked on the fast path here and the
    reference path through workers by ``test_bit_identical_for_any_jobs_and_chunks``."""
    got = _summary(small_study, tmp_path, kernel, workers=min(2, runner.available_cores()),
                   n_jobs=2, backend="dask", chunk_size=1000)
    pd.testing.assert_frame_equal(got, reference, check_exact=True)


def test_a_small_run_stays_in_the_calling_process_and_a_resumed_one_runs_nowhere(small_study,
                                                                                 tmp_path,
                                                                                 monkeypatch):
    """Under the runner's threshold of work the trials run in the calling process even when
    two workers are asked for, and the result records it; a rerun that finds every point in
    its checkpoints runs no trials at all."""
    monkeypatch.setattr(runner, "IN_PROCESS", math.inf)  # (the kernel fixture may lower it)
    ck = tmp_path / "ck"
    first = run_study(small_study, RunOptions(n_jobs=2, progress=False, checkpoint_dir=ck))
    again = run_study(small_study, RunOptions(n_jobs=2, progress=False, checkpoint_dir=ck))
    assert (first.workers, again.workers) == (0, 0)


def test_seed_changes_results(small_study, reference, tmp_path):
    other = load_study(small_study.path, seed=8)
    assert not _summary(other, tmp_path, n_jobs=2)["mean"].equals(reference["mean"])


def test_every_trial_counted(reference):
    rows = reference[reference["metric"] == "rotation_angle"]
    assert ((rows["count"] + rows["invalid"]) == 3000).all()


def test_common_random_numbers_make_trends_smooth(tmp_path):
    """With the same draws at every point, trial i sees the same standardised errors at every
    pixel sigma, so its error grows with sigma in almost every trial (99.5 % here; with
    independent draws per point only about 71 %)."""
    p = tmp_path / "crn.toml"
    p.write_text(textwrap.dedent(SMALL).replace("trials = 3000", "trials = 1000")
                 .replace('"geometry.L_m" = [50.0, 200.0]',
                          '"errors.pixel_px.sigma" = [0.1, 0.2, 0.4, 0.8]')
                 .replace('psi_deg = { dist = "uniform", bound = 10.0 }', "psi_deg = 0.0")
                 .replace("[study]", "[study]\nper_trial = true"))
    result = run_study(load_study(p), RunOptions(progress=False, checkpoint_dir=tmp_path / "ck"))
    v = np.stack([result.trials[i]["normalised/rotation_angle"].to_numpy() for i in range(4)])
    assert np.mean(np.diff(v, axis=0) > 0) > 0.95  # trial-by-trial growth with sigma


def test_table1_study_reproduces_table1_module(tmp_path):
    """The worst_case points of studies/table1.toml (fast kernel) give the maxima of the literal
    montecarlo.seed000.table1 to 1e-12 rad (1e-9 mrad)."""
    study = load_study(ROOT / "studies/table1.toml", trials=500)
    df = _summary(study, tmp_path, n_jobs=2)
    worst = df[(df["errors.evaluation"] == "worst_case") & (df["metric"] == "table1_angle")]
    ours = table1.reproduce_table1()
    for variant, col in (("raw", "delta_mrad"), ("normalised", "norm_delta_mrad")):
        got = worst[worst["variant"] == variant]["max"].to_numpy()
        np.testing.assert_allclose(got, ours[col].to_numpy(), rtol=0, atol=1e-9)


def test_kill_and_resume_gives_the_uninterrupted_result(tmp_path):
    """Kill a run midway (SIGKILL), rerun it: it resumes and ends with identical results.

    The killed run is a fresh process of its own; the uninterrupted run and the rerun are
    ``python -m montecarlo`` forked from a process with the libraries imported."""
    text = textwrap.dedent(SMALL).replace("trials = 3000", "trials = 4000") \
        .replace("block_size = 500", "block_size = 4000") \
        .replace('"geometry.L_m" = [50.0, 200.0]',
                 '"geometry.L_m" = [' + ", ".join(f"{x:.1f}" for x in range(30, 180, 10)) + "]")
    study = tmp_path / "resume.toml"
    study.write_text(text)
    args = ["run", str(study), "--n-jobs", "1", "--quiet"]
    a, b = tmp_path / "a" / "out", tmp_path / "b" / "out"
    first = montecarlo_cli(*args, "--out", a, timeout=600)
    assert first.returncode == 0, first.stderr

    proc = subprocess.Popen([sys.executable, "-m", "montecarlo", *args, "--out", str(b)],
                            start_new_session=True)
    ck_root = b.parent / ".checkpoints"
    deadline = time.time() + 300
    while time.time() < deadline and len(list(ck_root.glob("*/point-*.pkl"))) < 5:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    n_done = len(list(ck_root.glob("*/point-*.pkl")))
    assert 5 <= n_done < 15, n_done
    assert not b.exists()  # no half-written results
    assert list(b.parent.glob(".out.tmp-*"))  # the killed run's staging directory is left

    rerun = montecarlo_cli(*args, "--out", b, timeout=600)
    assert rerun.returncode == 0, rerun.stderr
    assert "resuming" in rerun.stderr
    pd.testing.assert_frame_equal(pd.read_parquet(b / "summary.parquet"),
                                  pd.read_parquet(a / "summary.parquet"), check_exact=True)
    assert not ck_root.exists()  # cleaned up after success
    assert not list(b.parent.glob(".out.*"))  # and the stale staging directory removed


# --- in-process runs (n_jobs=1): task plan, options, callbacks, interruption, trial tables -------


def _tiny(small_study, trials=1100):
    """The small study with ``trials`` per point: blocks of 500, the last one short."""
    return load_study(small_study.path, trials=trials)


def test_planned_workers_are_the_workers_given_a_task(small_study, monkeypatch):
    """One block of one point is one task: a second worker would stay idle, so one is
    planned; two points of three blocks each make enough tasks for both; a run in the calling
    process, or of no point, has none; a remote dask cluster's are not counted."""
    monkeypatch.setattr(runner, "IN_PROCESS", 0.0)
    one, six = _tiny(small_study, trials=500), _tiny(small_study)
    two = RunOptions(n_jobs=2)
    assert runner.planned_workers(one, [0], two, False) == 1
    assert runner.planned_workers(six, [0, 1], two, False) == 2
    assert runner.planned_workers(six, [0, 1], RunOptions(n_jobs=1), False) == 0
    assert runner.planned_workers(six, [], two, False) == 0
    remote = RunOptions(n_jobs=2, backend="dask", scheduler="tcp://h:8786")
    assert runner.planned_workers(six, [0, 1], remote, False) is None
    monkeypatch.setattr(runner, "IN_PROCESS", math.inf)
    assert runner.planned_workers(six, [0, 1], two, False) == 0
    assert runner.plan_text(10.0, 2) == "about 5 s on 2 cores"
    assert runner.plan_text(0.4, 0) == "under a second on 1 core"
    assert runner.plan_text(90.0, None) == \
        "about 90 s of single-core work, on the dask cluster's workers"


def test_tasks_cover_every_block_once_in_order(small_study):
    study = _tiny(small_study)
    assert [runner._n_blocks(study, p) for p in (0, 1)] == [3, 3]
    assert [runner._block_trials(study, 0, b) for b in range(3)] == [500, 500, 100]
    tasks = list(runner._tasks(study, [1, 0], 2))
    assert tasks == [(1, range(0, 2)), (1, range(2, 3)), (0, range(0, 2)), (0, range(2, 3))]


@pytest.mark.parametrize(("options", "trials", "blocks"), [
    (RunOptions(chunk_size=1500), 1100, 3),
    (RunOptions(n_jobs=1), 1100, 2),  # 6 blocks / (4 tasks per worker): ceil(1.5)
    (RunOptions(), 1100, 2),          # no worker count: one
    (RunOptions(n_jobs=1), 5000, 5),  # 20 blocks / 4
    (RunOptions(n_jobs=4), 1100, 1),  # never below one block
])
def test_blocks_per_task(small_study, options, trials, blocks):
    got = runner._chunk_blocks(_tiny(small_study, trials), [0, 1], options)
    assert got == blocks and isinstance(got, int)


def test_blocks_per_task_are_capped(small_study):
    study = _tiny(small_study, trials=500 * 1000)  # 2000 blocks on one worker: 500 > 32
    assert runner._chunk_blocks(study, [0, 1], RunOptions(n_jobs=1)) == runner.MAX_CHUNK_BLOCKS


@pytest.mark.parametrize(("options", "needle"), [
    (RunOptions(n_jobs=0), "--n-jobs: must be at least 1 (got 0)"),
    (RunOptions(scheduler="tcp://h:1"), "--scheduler: only meaningful with --backend dask"),
    (RunOptions(backend="dask", scheduler="http://h:1"), "is not a dask scheduler address"),
    (RunOptions(chunk_size=700), "--chunk-size: 700 is not a positive multiple of the study's "
                                 "block size 500"),
    (RunOptions(chunk_size=0), "--chunk-size: 0"),
    (RunOptions(chunk_size=-500), "--chunk-size: -500"),
])
def test_options_refused_before_any_work(small_study, options, needle):
    from montecarlo.errors import InputError

    with pytest.raises(InputError) as err:
        runner.checked_options(small_study, options)
    assert needle in str(err.value)


def test_options_default_and_capped_workers(small_study, caplog):
    cores = runner.available_cores()
    assert cores == len(os.sched_getaffinity(0))
    assert runner.checked_options(small_study, RunOptions()).n_jobs == cores
    assert runner.checked_options(small_study, RunOptions(n_jobs=1)).n_jobs == 1
    with caplog.at_level("WARNING", logger="montecarlo"):
        assert runner.checked_options(small_study, RunOptions(n_jobs=cores)).n_jobs == cores
    assert "--n-jobs" not in caplog.text  # as many workers as cores: nothing to say
    assert runner.checked_options(small_study, RunOptions(chunk_size=1000)).chunk_size == 1000
    dask = RunOptions(backend="dask", scheduler="tcp://10.0.0.1:8786", n_jobs=cores + 5)
    assert runner.checked_options(small_study, dask) == dask  # a cluster's workers: not capped
    with caplog.at_level("WARNING", logger="montecarlo"):
        capped = runner.checked_options(small_study, RunOptions(n_jobs=cores + 5))
    assert capped.n_jobs == cores
    assert f"--n-jobs {cores + 5}: this machine has {cores} cores; using {cores}" in caplog.text


def test_per_trial_values_always_take_the_reference_path(tmp_path):
    """A study large enough for the compiled kernel still runs the reference path when it
    keeps per-trial values (the kernel keeps none)."""
    p = tmp_path / "pt.toml"
    p.write_text(textwrap.dedent(SMALL).replace("[study]", "[study]\nper_trial = true"))
    assert runner.uses_reference(load_study(p, trials=10**6), RunOptions())


def test_estimated_seconds_is_cost_per_trial_times_trials(small_study):
    study = _tiny(small_study, trials=1000)
    per_trial = study.system.seconds_per_trial
    assert runner.estimated_seconds(study, [0, 1], False) == pytest.approx(2000 * per_trial)
    assert runner.estimated_seconds(study, [1], True) == pytest.approx(20 * 1000 * per_trial)


@pytest.mark.parametrize("system", ["collimation", "stabilization"])
def test_estimated_seconds_of_the_literal_path_use_its_own_cost(system):
    """The trial-by-trial path of these systems costs tens of times their fast path; the plan
    of a ``--reference`` run says so (it said the fast path's time)."""
    from montecarlo.systems import study_from_dict

    study = study_from_dict({"study": {"name": "e", "system": system, "trials": 100,
                                       "seed": 1}}, "<test>")
    fast, literal = (runner.estimated_seconds(study, [0], r) for r in (False, True))
    assert fast == pytest.approx(100 * study.system.seconds_per_trial)
    assert literal == pytest.approx(100 * study.system.reference_seconds_per_trial)
    assert literal > 10 * fast


@pytest.mark.parametrize(("seconds", "text"), [
    (0.4, "under a second"), (1.0, "1 s"), (45.2, "45 s"), (119.0, "119 s"), (120.0, "2 min"),
    (720.0, "12 min"), (3.5 * 3600, "3.5 h"), (2.1 * 86400, "2.1 days"),
    (4000 * 365.25 * 86400, "4e+03 years"), (2e4 * 365.25 * 86400, "2.0e+04 years"),
])
def test_durations_for_people(seconds, text):
    assert runner.duration_text(seconds) == text
    assert runner.about(seconds) == (text if seconds < 1 else f"about {text}")


def test_in_process_run_plan_callbacks_and_trial_table(tmp_path, caplog):
    """Per-trial values in trial order, the plan announced, one callback per grid point."""
    p = tmp_path / "pt.toml"
    p.write_text(textwrap.dedent(SMALL).replace("trials = 3000", "trials = 1100")
                 .replace("[study]", "[study]\nper_trial = true"))
    study = load_study(p)
    seen: list[int] = []
    with caplog.at_level("INFO", logger="montecarlo"):
        result = run_study(study, RunOptions(n_jobs=1, progress=False), on_point=seen.append)
    assert sorted(seen) == [0, 1] and result.kernel == "reference" and result.resumed == {}
    assert "small: 2 of 2 grid points to run, 2,200 trials (under a second on 1 core)" \
        in caplog.text
    assert sorted(result.trials) == [0, 1]
    for point, frame in result.trials.items():
        assert frame["trial"].tolist() == list(range(1100))
        assert (frame["point"] == point).all()
    summary = result.to_frame()
    assert list(summary.columns[:5]) == ["point", "geometry.L_m", "variant", "metric", "unit"]
    for (point, variant, metric), row in summary.set_index(["point", "variant", "metric"]) \
            .iterrows():
        v = result.trials[point][f"{variant}/{metric}"].to_numpy()
        scale = study.metric(metric).scale
        assert row["count"] == np.isfinite(v).sum() and row["trials"] == 1100
        assert row["mean"] == pytest.approx(np.nanmean(v) * scale, rel=1e-12)
        assert row["unit"] == study.metric(metric).unit


def test_reused_points_are_not_run_again(small_study):
    study = _tiny(small_study, trials=500)
    options = RunOptions(n_jobs=1, progress=False)
    first = run_study(study, options)
    seen: list[int] = []
    again = run_study(study, options, on_point=seen.append, reuse={0: first.points[0]})
    assert seen == [1] and again.points[0] is first.points[0]
    pd.testing.assert_frame_equal(again.to_frame(), first.to_frame(), check_exact=True)


def test_an_interrupted_run_keeps_finished_points_and_says_how_to_resume(small_study, tmp_path,
                                                                        caplog):
    from montecarlo.errors import RunInterrupted

    study = _tiny(small_study, trials=500)
    options = RunOptions(n_jobs=1, progress=False, checkpoint_dir=tmp_path / "ck")

    def stop(point):
        raise KeyboardInterrupt

    with pytest.raises(RunInterrupted) as err:
        run_study(study, options, on_point=stop)
    assert err.value.code == 130
    assert str(err.value).startswith(
        "small: interrupted; 1 of 2 grid points finished (1 in this run); rerun the same "
        f"command to resume from {tmp_path / 'ck'}")
    with caplog.at_level("WARNING", logger="montecarlo"):
        resumed = run_study(study, options)
    assert resumed.resumed["points"] == [0] and resumed.resumed["key"]
    assert f"small: resuming, 1 of 2 grid points already computed ({tmp_path / 'ck'}" \
        in caplog.text
    whole = run_study(study, RunOptions(n_jobs=1, progress=False))
    pd.testing.assert_frame_equal(resumed.to_frame(), whole.to_frame(), check_exact=True)
    with pytest.raises(RunInterrupted) as err:  # without checkpoints: nothing to resume from
        run_study(study, RunOptions(n_jobs=1, progress=False), on_point=stop)
    assert str(err.value).endswith("1 of 2 grid points finished (1 in this run)")


def test_sweep_values_mixing_numbers_and_text_become_text(small_study):
    from dataclasses import replace as dc_replace

    study = _tiny(small_study, trials=500)
    result = run_study(study, RunOptions(n_jobs=1, progress=False))
    assert result.to_frame()["geometry.L_m"].tolist()[0] == 50.0
    mixed = dc_replace(study, points=(dc_replace(study.points[0], values={"geometry.L_m": "a"}),
                                      study.points[1]))
    assert dc_replace(result, study=mixed)._sweep_value("geometry.L_m", 200.0) == "200.0"
    assert result._sweep_value("geometry.L_m", 200.0) == 200.0


@pytest.mark.parametrize(("factor", "verdict"), [(2.0, "meets"), (0.5, "fails")])
def test_a_spec_is_judged_in_its_display_unit(tmp_path, factor, verdict):
    """The [spec] limit is in the metric's display unit: twice the largest p95 interval end of
    a run without the spec meets, half the smallest fails. Only the spec's rows get a verdict,
    and its value is the row's p95 when every trial has a value."""
    p = tmp_path / "spec.toml"
    text = textwrap.dedent(SMALL).replace("trials = 3000", "trials = 500")
    p.write_text(text)
    options = RunOptions(n_jobs=1, progress=False)
    plain = run_study(load_study(p), options).to_frame()
    rows = plain[(plain["metric"] == "rotation_angle") & (plain["variant"] == "raw")]
    limit = factor * (rows["p95_hi"].max() if factor > 1 else rows["p95_lo"].min())
    p.write_text(text + textwrap.dedent(f"""
        [spec]
        metric = "rotation_angle"
        variant = "raw"
        statistic = "p95"
        limit = {float(limit)!r}
        """))
    frame = run_study(load_study(p), options).to_frame()
    judged = frame[(frame["metric"] == "rotation_angle") & (frame["variant"] == "raw")]
    assert len(judged) == 2 and (judged["verdict"] == verdict).all()
    assert frame.drop(judged.index)["verdict"].isna().all()
    valid = judged[judged["invalid"] == 0]
    assert (valid["spec_value"] == valid["p95"]).all()


def _study(raw, **kw):
    from montecarlo.systems import study_from_dict

    return study_from_dict(raw, **kw)


QUIET = RunOptions(n_jobs=1, progress=False)

SHARP = {
    "study": {"name": "sharp", "system": "ground", "trials": 200, "seed": 3},
    "sensor": {"fov_deg": [90.0, 90.0], "pixels": [512, 512]},
    "mounting": {"psi_deg": 30.0, "theta_deg": 20.0, "gamma_deg": 10.0},
    "geometry": {"L_m": 50.0, "H_m": 1.0},
    "errors": {"dx_m": 0.0, "dy_m": 0.0, "dh1_m": 0.0, "dh_m": 0.0,
               "pixel_px": {"dist": "normal", "sigma": 0.3}, "pixel_relation": "common"},
    "solver": {"variants": ["normalised"]},
    "sweep": [{"errors.pixel_px.sigma": [0.3, 0.6]}],
}
"""Survey errors zero, so the pixel error alone sets the metrics (error ∝ pixel sigma)."""


def test_a_small_in_process_run_takes_the_reference_path_and_says_which_path_ran(monkeypatch):
    """A small study runs the reference path in process: bit for bit the run that keeps per-trial
    values (which always takes it). Forced onto the compiled kernel it says "fast" and differs in
    the last digits only."""
    study = _study(SHARP)
    small = run_study(study, QUIET)
    per_trial = run_study(_study({**SHARP, "study": {**SHARP["study"], "per_trial": True}}),
                          QUIET)
    assert small.kernel == "reference" and small.trials == {}
    pd.testing.assert_frame_equal(small.to_frame(), per_trial.to_frame(), check_exact=True)
    monkeypatch.setattr(runner, "REFERENCE_BELOW", 0.0)
    fast = run_study(study, QUIET)
    assert fast.kernel == "fast"
    a, b = small.to_frame(), fast.to_frame()
    values = ["mean", "std", "p95", "max"]
    assert (a[values] != b[values]).to_numpy().any()
    np.testing.assert_allclose(b[values], a[values], rtol=1e-9, atol=0)


def test_two_sweep_keys_and_a_failure_reason_at_some_points_only():
    """ψ 44.9° in a 90° field with 2 px pixel errors puts targets outside the field; ψ 30° never.
    The summary has the two sweep keys after the point, one row per (point, variant, metric)
    numbered from 0, and the reason's count as an integer column, 0 where no trial failed."""
    raw = {**SHARP, "errors": {**SHARP["errors"], "pixel_px": {"dist": "normal", "sigma": 2.0}},
           "sweep": [{"mounting.psi_deg": [30.0, 44.9]}, {"geometry.H_m": [1.0, 2.0]}]}
    study = _study(raw)
    frame = run_study(study, QUIET).to_frame()
    assert list(frame.columns[:6]) == ["point", "mounting.psi_deg", "geometry.H_m", "variant",
                                       "metric", "unit"]
    assert frame.index.equals(pd.RangeIndex(4 * 6))
    for point, rows in frame.groupby("point"):
        values = study.points[point].values
        assert (rows["mounting.psi_deg"] == values["mounting.psi_deg"]).all()
        assert (rows["geometry.H_m"] == values["geometry.H_m"]).all()
    assert frame["invalid_OUTSIDE_FOV"].dtype == np.int64
    assert frame["invalid_fraction"].dtype == np.float64
    assert (frame["invalid_fraction"] == frame["invalid"] / frame["trials"]).all()
    assert (frame["invalid_OUTSIDE_FOV"] == frame["invalid"]).all()  # the only reason
    at_30 = frame["mounting.psi_deg"] == 30.0
    assert (frame.loc[at_30, "invalid"] == 0).all() and (frame.loc[~at_30, "invalid"] > 0).all()
    assert (frame["count"] + frame["invalid"] == 200).all()


def test_a_reference_run_does_not_resume_from_checkpoints_of_the_compiled_kernel(monkeypatch,
                                                                                 tmp_path):
    monkeypatch.setattr(runner, "REFERENCE_BELOW", 0.0)
    study = _study(SHARP)
    options = RunOptions(n_jobs=1, progress=False, checkpoint_dir=tmp_path / "ck")

    def stop(point):
        raise KeyboardInterrupt

    from montecarlo.errors import RunInterrupted

    with pytest.raises(RunInterrupted):
        run_study(study, options, on_point=stop)  # point 0 saved by the compiled kernel
    reference = run_study(study, replace(options, reference=True))
    assert reference.resumed == {} and reference.kernel == "reference"
    fast = run_study(study, options)
    assert fast.resumed["points"] == [0] and fast.kernel == "fast"


def test_per_trial_values_and_counts_through_two_interruptions(tmp_path):
    """Interrupted after one point, then again after one more: the second says 2 finished, 1 in
    that run; the third run resumes both and its per-trial values equal an uninterrupted run's."""
    from montecarlo.errors import RunInterrupted

    raw = {**SHARP, "study": {**SHARP["study"], "per_trial": True, "trials": 50},
           "sweep": [{"errors.pixel_px.sigma": [0.3, 0.6, 0.9]}]}
    study = _study(raw)
    options = RunOptions(n_jobs=1, progress=False, checkpoint_dir=tmp_path / "ck")

    def stop(point):
        raise KeyboardInterrupt

    for finished in (1, 2):
        with pytest.raises(RunInterrupted) as err:
            run_study(study, options, on_point=stop)
        assert f"{finished} of 3 grid points finished (1 in this run)" in str(err.value)
    resumed = run_study(study, options)
    assert resumed.resumed["points"] == [0, 1]
    whole = run_study(study, QUIET)
    assert sorted(resumed.trials) == [0, 1, 2]
    for p in range(3):
        pd.testing.assert_frame_equal(resumed.trials[p], whole.trials[p], check_exact=True)
    pd.testing.assert_frame_equal(resumed.to_frame(), whole.to_frame(), check_exact=True)


def test_enumerated_corners_in_process_give_the_exact_statistic():
    """Every bounded source at both ends (dx, dh and four independent pixel coordinates: 2^6
    corners): the spec's p95 is exact, its interval a single value, and the verdict follows
    from it alone."""
    raw = {**SHARP, "errors": {"dx_m": {"dist": "uniform", "bound": 0.1}, "dy_m": 0.0,
                               "dh1_m": 0.0, "dh_m": {"dist": "uniform", "bound": 0.001},
                               "pixel_px": {"dist": "uniform", "bound": 0.5},
                               "pixel_relation": "independent", "evaluation": "worst_case"},
           "spec": {"metric": "rotation_angle", "statistic": "p95", "limit": 1e3},
           "sweep": [{"geometry.L_m": [50.0, 100.0]}]}
    study = _study(raw)
    assert not any(gp.sampled for gp in study.points)
    assert [gp.trials for gp in study.points] == [64, 64]
    frame = run_study(study, QUIET).to_frame()
    judged = frame[frame["metric"] == "rotation_angle"]
    assert len(judged) == 2 and (judged["verdict"] == "meets").all()
    assert (judged["spec_lo"] == judged["spec_value"]).all()
    assert (judged["spec_hi"] == judged["spec_value"]).all()
    assert (judged["spec_value"] == judged["p95"]).all()


def test_a_chunk_of_one_trial_with_blocks_of_one():
    study = _study({**SHARP, "study": {**SHARP["study"], "block_size": 1}})
    assert runner.checked_options(study, RunOptions(chunk_size=1)).chunk_size == 1


@pytest.mark.parametrize(("seconds", "text"), [
    (2 * 60.0, "2 min"), (2 * 3600.0, "2 h"), (2 * 86400.0, "2 days"),
    (2 * 365.25 * 86400, "2 years"), (2 * 365.25 * 86400 - 1, "7.3e+02 days"),
])
def test_durations_at_twice_each_unit(seconds, text):
    assert runner.duration_text(seconds) == text


# --- the dask watch: a fake client and clock, no waiting -----------------------------------------


class _FakeCluster:
    """``scheduler_info`` answers from a script of (clock, workers); None: the scheduler does not
    answer. Each poll sets the clock the watcher reads."""

    def __init__(self, script):
        self.script, self.polls, self.now = list(script), 0, 0.0

    def scheduler_info(self):
        self.now, workers = self.script[self.polls]
        self.polls += 1
        if workers is None:
            raise OSError("scheduler gone")
        return {"workers": workers}

    def monotonic(self):
        return self.now


class _Stop:
    """A stop event set after ``polls`` waits; records each wait's timeout."""

    def __init__(self, polls=math.inf):
        self.polls, self.waits = polls, []

    def wait(self, timeout):
        self.waits.append(timeout)
        return len(self.waits) > self.polls


def test_the_dask_watch_interrupts_once_no_worker_was_seen_for_the_wait(monkeypatch):
    """Workers come and go: the watch counts from the first poll without one (an unreachable
    scheduler counts as none), starts again when a worker is back, and interrupts the run once
    more than WORKER_WAIT [s] passed without one."""
    wait = runner.WORKER_WAIT
    w = {"tcp://w:1": {}}
    fake = _FakeCluster([(100.0, w), (110.0, {}), (110.0 + wait - 1, None), (150.0, w),
                         (160.0, {}), (160.0 + wait, {}), (161.0 + wait, {})])
    interrupts: list[int] = []
    monkeypatch.setattr(runner, "time", fake)
    monkeypatch.setattr(runner._thread, "interrupt_main", lambda: interrupts.append(1))
    gone: list[str] = []
    stop = _Stop()
    runner._watch_workers(fake, stop, gone)
    assert fake.polls == 7 and interrupts == [1]
    assert gone == [f"no dask worker for {wait:.0f} s"]
    assert stop.waits == [2.0] * 7


def test_the_dask_watch_ends_quietly_when_the_run_ends(monkeypatch):
    fake = _FakeCluster([(100.0, {}), (100.0 + 10 * runner.WORKER_WAIT, {"w": {}})])
    monkeypatch.setattr(runner, "time", fake)
    monkeypatch.setattr(runner._thread, "interrupt_main", lambda: pytest.fail("interrupted"))
    gone: list[str] = []
    runner._watch_workers(fake, _Stop(polls=2), gone)
    assert fake.polls == 2 and gone == []


# --- adaptive trials (run --until-decided), in process -------------------------------------------

DECIDE = {
    **SHARP,
    "study": {"name": "decide", "system": "ground", "trials": 10, "seed": 3, "per_trial": True},
    "spec": {"metric": "rotation_angle", "statistic": "p95", "limit": 0.1},
    "sweep": [{"errors.pixel_px.sigma": [1e-3, 2e-3, 10.0]}],
}
"""Three points whose every trial is far from the 0.1 mrad limit: about 0.001 and 0.002 mrad
(below it) and 1 to 30 mrad (above it)."""


def _first_bounded_count(p=0.95, confidence=0.95):
    """Fewest trials whose p-quantile interval has an upper end (its rank ``s <= n``)."""
    from scipy.stats import binom

    n = 1
    while binom.ppf(1 - (1 - confidence) / 2, n, p) + 1 > n:
        n += 1
    return n


def _verdicts(result):
    return result.to_frame().dropna(subset=["verdict"]).sort_values("point")["verdict"].tolist()


def test_until_decided_doubles_undecided_points_until_their_verdict_is_decided(tmp_path, caplog):
    """Below the limit a point meets only once its p95 interval has an upper end (72 trials, from
    the binomial), so it grows 10, 20, 40, 80; above it, every order statistic exceeds the limit
    and it fails at once, keeping its 10 trials and its result. The grown points equal direct
    runs of 80 trials; no checkpoint is written."""
    from montecarlo.engine.runner import run_until_decided

    assert _first_bounded_count() == 72
    study = _study(DECIDE)
    first = run_study(study, QUIET)
    assert _verdicts(first) == ["undecided", "undecided", "fails"]
    options = RunOptions(n_jobs=1, progress=False, checkpoint_dir=tmp_path / "ck")
    with caplog.at_level("INFO", logger="montecarlo"):
        grown = run_until_decided(study, options, max_trials=1000)
    assert [gp.trials for gp in grown.study.points] == [80, 80, 10]
    assert _verdicts(grown) == ["meets", "meets", "fails"]
    for t in (20, 40, 80):
        assert f"decide: 2 grid point(s) undecided; running them again with {t} trials" \
            in caplog.text
    assert "still undecided" not in caplog.text and not (tmp_path / "ck").exists()
    direct = run_study(_study(DECIDE, trials=80), QUIET)
    summary, expected = grown.to_frame(), direct.to_frame()
    for p in (0, 1):
        pd.testing.assert_frame_equal(summary[summary["point"] == p],
                                      expected[expected["point"] == p], check_exact=True)
        pd.testing.assert_frame_equal(grown.trials[p], direct.trials[p], check_exact=True)
    pd.testing.assert_frame_equal(grown.points[2].summary, first.points[2].summary,
                                  check_exact=True)
    assert list(grown.trials) == [0, 1, 2]
    pd.testing.assert_frame_equal(grown.trials[2], first.trials[2], check_exact=True)


@pytest.mark.parametrize(("max_trials", "trials", "verdict"), [
    (10, 10, "undecided"), (60, 60, "undecided"), (71, 71, "undecided"), (72, 72, "meets")])
def test_until_decided_stops_at_max_trials_and_names_the_points_left(caplog, max_trials, trials,
                                                                      verdict):
    """The last round is cut to ``max_trials`` (40 -> 60, not 80); a point still undecided
    there is named in a warning."""
    from montecarlo.engine.runner import run_until_decided

    with caplog.at_level("INFO", logger="montecarlo"):
        result = run_until_decided(_study(DECIDE), QUIET, max_trials=max_trials)
    assert [gp.trials for gp in result.study.points] == [trials, trials, 10]
    assert _verdicts(result) == [verdict, verdict, "fails"]
    assert [len(result.trials[p]) for p in range(3)] == [trials, trials, 10]
    still = f"decide: still undecided at {max_trials:,} trials: grid point(s) 0, 1"
    assert (still in caplog.text) == (verdict == "undecided")
    assert ("running them again" in caplog.text) == (max_trials > 10)


def test_until_decided_needs_a_spec():
    from montecarlo.engine.runner import run_until_decided
    from montecarlo.errors import InputError

    raw = {k: v for k, v in DECIDE.items() if k != "spec"}
    with pytest.raises(InputError, match=r"<study>: spec: --until-decided needs a \[spec\]"):
        run_until_decided(_study(raw), QUIET, max_trials=100)
