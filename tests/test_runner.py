"""The study runner: reproducibility across jobs, chunks and backends; resume; Table 1 path."""

import math
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from montecarlo.engine import runner
from montecarlo.engine.runner import RunOptions, run_study
from montecarlo.seed000 import table1
from montecarlo.systems import load_study

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


def _summary(study, tmp_path, kernel=None, **kw):
    ck = tmp_path / f"ck-{len(list(tmp_path.iterdir()))}"
    opts = RunOptions(progress=False, checkpoint_dir=ck, **kw)
    result = run_study(study, opts)
    assert kernel is None or result.kernel == kernel
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
    pd.testing.assert_frame_equal(_summary(small_study, tmp_path, kernel, **kw), reference,
                                  check_exact=True)


def test_bit_identical_on_dask_local_cluster(small_study, kernel, reference, tmp_path):
    got = _summary(small_study, tmp_path, kernel, n_jobs=2, backend="dask", chunk_size=1000)
    pd.testing.assert_frame_equal(got, reference, check_exact=True)


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
    """Kill a run midway (SIGKILL), rerun it: it resumes and ends with identical results."""
    text = textwrap.dedent(SMALL).replace("trials = 3000", "trials = 4000") \
        .replace("block_size = 500", "block_size = 4000") \
        .replace('"geometry.L_m" = [50.0, 200.0]',
                 '"geometry.L_m" = [' + ", ".join(f"{x:.1f}" for x in range(30, 330, 10)) + "]")
    study = tmp_path / "resume.toml"
    study.write_text(text)
    cmd = [sys.executable, "-m", "montecarlo", "run", str(study), "--n-jobs", "1", "--quiet"]
    a, b = tmp_path / "a" / "out", tmp_path / "b" / "out"
    subprocess.run([*cmd, "--out", str(a)], check=True, timeout=600)

    proc = subprocess.Popen([*cmd, "--out", str(b)], start_new_session=True)
    ck_root = b.parent / ".checkpoints"
    deadline = time.time() + 300
    while time.time() < deadline and len(list(ck_root.glob("*/point-*.pkl"))) < 5:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    n_done = len(list(ck_root.glob("*/point-*.pkl")))
    assert 5 <= n_done < 30, n_done
    assert not b.exists()  # no half-written results
    assert list(b.parent.glob(".out.tmp-*"))  # the killed run's staging directory is left

    rerun = subprocess.run([*cmd, "--out", str(b)], capture_output=True, text=True, timeout=600)
    assert rerun.returncode == 0, rerun.stderr
    assert "resuming" in rerun.stderr
    pd.testing.assert_frame_equal(pd.read_parquet(b / "summary.parquet"),
                                  pd.read_parquet(a / "summary.parquet"), check_exact=True)
    assert not ck_root.exists()  # cleaned up after success
    assert not list(b.parent.glob(".out.*"))  # and the stale staging directory removed
