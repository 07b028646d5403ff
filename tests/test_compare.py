"""``montecarlo compare``: paired reruns are the same, a changed model is seen with its sign,
independent samples are judged on their intervals, different studies are refused."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from montecarlo.errors import InputError
from montecarlo.output.compare import compare_runs, load_run, verdict_counts

STUDY = """
[study]
name = "{name}"
system = "ground"
trials = {trials}
seed = {seed}

[sensor]
fov_deg = [90.0, 90.0]
pixels = [512, 512]

[mounting]
psi_deg = 30.0
theta_deg = 20.0
gamma_deg = 10.0

[geometry]
L_m = 50.0
H_m = 1.0

[errors]
dx_m = {{dist = "uniform", bound = 0.1}}
dy_m = {{dist = "uniform", bound = 0.1}}
dh1_m = {{dist = "uniform", bound = 0.1}}
dh_m = {{dist = "uniform", bound = 0.005}}
pixel_px = {{dist = "normal", sigma = {sigma}}}
pixel_relation = "common"

[solver]
variants = ["normalised"]

[spec]
metric = "rotation_angle"
statistic = "p95"
limit = 4.6

[[sweep]]
"geometry.L_m" = [50.0, 100.0]
"""


def _run(tmp_path: Path, tag: str, trials: int = 2000, seed: int = 1, sigma: float = 0.5,
         name: str = "compare-small") -> Path:
    study = tmp_path / f"{tag}.toml"
    study.write_text(STUDY.format(trials=trials, seed=seed, sigma=sigma, name=name))
    out = tmp_path / tag
    subprocess.run([sys.executable, "-m", "montecarlo", "-q", "run", str(study), "--out",
                    str(out), "--n-jobs", "1"], check=True)
    return out


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "montecarlo", "compare", *args],
                          capture_output=True, text=True)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("compare")
    return {"a": _run(tmp, "a"), "again": _run(tmp, "again"),
            "noisier": _run(tmp, "noisier", sigma=1.0),
            "other_seed": _run(tmp, "other_seed", seed=2),
            "bigger": _run(tmp, "bigger", trials=4000, seed=3),
            "renamed": _run(tmp, "renamed", trials=500, name="another-study")}


def test_a_rerun_is_the_same_everywhere(runs):
    table = compare_runs(load_run(runs["a"]), load_run(runs["again"]), "mean")
    assert set(table["comparison"]) == {"paired"}
    assert set(table["verdict"]) == {"same"} and (table["diff"] == 0.0).all()
    done = _cli(str(runs["a"]), str(runs["again"]), "--json")
    assert done.returncode == 0
    assert json.loads(done.stdout)["counts"] == {"same": len(table), "better": 0, "worse": 0,
                                                 "undecided": 0}


def test_more_pixel_noise_is_worse_and_less_is_better(runs):
    a, b = load_run(runs["a"]), load_run(runs["noisier"])
    worse = compare_runs(a, b, "p95")
    assert set(worse["comparison"]) == {"independent"}  # the study file changed
    assert set(worse["verdict"]) == {"worse"}
    assert (worse["diff_lo"] > 0).all()
    assert set(compare_runs(b, a, "p95")["verdict"]) == {"better"}
    done = _cli(str(runs["a"]), str(runs["noisier"]))
    assert done.returncode == 1 and "worse" in done.stdout


def test_independent_samples_of_one_model_are_the_same_on_their_intervals(runs):
    a, b = load_run(runs["a"]), load_run(runs["other_seed"])
    for stat in ("mean", "p95"):
        table = compare_runs(a, b, stat)
        assert set(table["comparison"]) == {"independent"}
        assert set(table["verdict"]) == {"same"}
        assert (table["diff_lo"] < 0).all() and (table["diff_hi"] > 0).all()
    # a max has no interval: two samples of it cannot be judged
    maxima = compare_runs(a, b, "max")
    assert verdict_counts(maxima)["undecided"] == len(maxima) > 0


def test_the_interval_of_a_difference_narrows_with_trials(runs):
    a = load_run(runs["a"])
    small = compare_runs(a, load_run(runs["other_seed"]), "mean")
    large = compare_runs(a, load_run(runs["bigger"]), "mean")
    width = lambda t: (t["diff_hi"] - t["diff_lo"]).to_numpy()  # noqa: E731
    assert np.all(width(large) < width(small))


def test_different_studies_and_foreign_directories_are_refused(runs, tmp_path):
    with pytest.raises(InputError, match="different studies"):
        compare_runs(load_run(runs["a"]), load_run(runs["renamed"]), "p95")
    table = compare_runs(load_run(runs["a"]), load_run(runs["renamed"]), "p95",
                         allow_different=True)
    assert len(table) == len(compare_runs(load_run(runs["a"]), load_run(runs["again"])))
    done = _cli(str(runs["a"]), str(runs["renamed"]))
    assert done.returncode == 2 and done.stderr.count("\n") == 1
    assert "--allow-different" in done.stderr and "Traceback" not in done.stderr
    done = _cli(str(runs["a"]), str(tmp_path))
    assert done.returncode == 2 and "provenance.json" in done.stderr
    done = _cli(str(runs["a"]), str(runs["again"]), "--statistic", "p42")
    assert done.returncode == 2
