"""``montecarlo compare``: paired reruns are the same, a changed model is seen with its sign,
independent samples are judged on their intervals, different studies are refused."""

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.stats import norm

from montecarlo.errors import InputError
from montecarlo.io.files import record_sha256
from montecarlo.output.compare import (
    STATISTICS,
    Run,
    compare_runs,
    load_run,
    simultaneous_z,
    verdict_counts,
)
from tests.forked_cli import montecarlo_cli

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
    done = montecarlo_cli("-q", "run", study, "--out", out, "--n-jobs", "1")
    assert done.returncode == 0, done.stderr
    return out


def _cli(*args: str) -> subprocess.CompletedProcess:
    return montecarlo_cli("compare", *args)


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
    assert ("independent samples: differences judged on simultaneous 95% intervals over the "
            "independent rows (Bonferroni)") in done.stdout


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


def test_the_nightly_change_check_of_independent_samples_does_not_count_a_max_as_changed(runs):
    """Another seed (as after a study file changed): the nightly's check passes, names the
    undecided maxima, and states the interval criterion it applied, not the paired one."""
    from montecarlo.tools.nightly import change_check

    check = change_check(runs["a"].name, runs["a"].parent, runs["other_seed"], accept=False)
    assert check.passed and "independent" in check.name
    assert check.value.startswith("0 of ") and "undecided (a sampled max has no interval)" \
        in check.value
    assert check.expected == "no difference outside its simultaneous interval"


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


# --- every documented statistic, and the statistics of the intervals ---------------------------


@pytest.mark.parametrize("statistic", STATISTICS)
def test_every_statistic_of_compare_runs_through_the_command_line(runs, statistic):
    """`compare --statistic std` crashed (duplicate column, exit 1 'worse'); every statistic
    the command documents now gives a verdict on every row, and two samples of one model are
    never 'worse'."""
    done = _cli(str(runs["a"]), str(runs["other_seed"]), "--statistic", statistic, "--json")
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    data = json.loads(done.stdout)
    assert data["statistic"] == statistic and data["counts"]["worse"] == 0
    rows = data["rows"]
    assert rows and all(r["comparison"] == "independent" for r in rows)
    expected = {"undecided"} if statistic == "max" else {"same"}
    assert {r["verdict"] for r in rows} == expected
    paired = compare_runs(load_run(runs["a"]), load_run(runs["again"]), statistic)
    assert set(paired["verdict"]) == {"same"} and (paired["diff"] == 0.0).all()


def test_a_study_whose_spec_statistic_is_std_compares_by_default(runs, tmp_path):
    """Plain `compare A B` takes the spec's statistic; a spec on `std` made it crash."""
    copies = []
    for name in ("a", "again"):
        copy = tmp_path / name
        shutil.copytree(runs[name], copy)
        prov = json.loads((copy / "provenance.json").read_text())
        prov["resolved_study"]["spec"]["statistic"] = "std"
        prov["record_sha256"] = record_sha256(prov)  # as a run of such a study writes it
        (copy / "provenance.json").write_text(json.dumps(prov))
        copies.append(copy)
    done = _cli(*map(str, copies), "--json")
    assert done.returncode == 0, done.stderr
    data = json.loads(done.stdout)
    assert data["statistic"] == "std" and data["counts"]["same"] == len(data["rows"]) > 0


def _synthetic(tag: str, m: int, count: int, std: float, mean: float) -> Run:
    """A result of m grid points with the given count, std and mean on every row."""
    summary = pd.DataFrame({"point": range(m), "geometry.L_m": [10.0 * (i + 1) for i in range(m)],
                            "variant": "raw", "metric": "rotation_angle", "unit": "mrad",
                            "sampling": "random", "count": count, "mean": mean, "std": std})
    prov = {"kind": "run", "study": "synthetic", "study_hash": tag,
            "resolved_study": {"study": {"confidence": 0.95}}}
    return Run(Path(tag), summary, prov)


@pytest.mark.parametrize("m", [1, 2, 7, 40])
def test_independent_intervals_are_simultaneous_over_the_rows_bonferroni(m):
    """Half-width = Phi^-1(1 - (1 - c)/(2 m)) se for m rows compared, se of a mean = s/sqrt(n)
    per run, combined as independent errors: sqrt(2) s / sqrt(n) for two equal runs (scipy's
    normal quantile as the reference; 1.95996 at m = 1)."""
    n, s = 400, 3.0
    table = compare_runs(_synthetic("a", m, n, s, 1.0), _synthetic("b", m, n, s, 1.5), "mean")
    z = norm.ppf(1.0 - 0.05 / (2 * m))
    se = np.sqrt(2.0) * s / np.sqrt(n)
    np.testing.assert_allclose(table["diff_hi"] - table["diff"], z * se, rtol=1e-12)
    np.testing.assert_allclose(table["diff"] - table["diff_lo"], z * se, rtol=1e-12)
    assert simultaneous_z(0.95, m) == pytest.approx(norm.ppf(1 - 0.025 / m), rel=1e-12)
    if m == 1:
        assert simultaneous_z(0.95, 1) == pytest.approx(1.959964, abs=1e-6)


def test_the_standard_error_of_std_matches_a_monte_carlo_of_normal_samples():
    """se(s) = sigma / sqrt(2 (n - 1)) for normal data (var(s^2) = 2 sigma^4 / (n - 1), so the
    variance's se is sigma^2 sqrt(2 / (n - 1))). Reference: the spread of s over R = 4000
    seeded samples of n = 200 draws of N(0, 2^2); that spread is itself known to relative
    1/sqrt(2 (R - 1)) = 1.1 %, so 4 % is 3.5 of its standard errors."""
    n, sigma, reps = 200, 2.0, 4000
    rng = np.random.default_rng(7)
    s = rng.normal(0.0, sigma, size=(reps, n)).std(axis=1, ddof=1)
    table = compare_runs(_synthetic("a", 1, n, sigma, 0.0), _synthetic("b", 1, n, sigma, 0.0),
                         "std")
    se_each = (table["diff_hi"] - table["diff"]).iloc[0] / (simultaneous_z(0.95, 1)
                                                             * np.sqrt(2.0))
    assert se_each == pytest.approx(sigma / np.sqrt(2 * (n - 1)), rel=1e-12)
    assert se_each == pytest.approx(s.std(ddof=1), rel=0.04)
    variance_se = np.sqrt(2.0 / (n - 1)) * sigma ** 2
    assert (s ** 2).std(ddof=1) == pytest.approx(variance_se, rel=0.06)
