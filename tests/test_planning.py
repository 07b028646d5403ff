"""Trial planning: order-statistic counts against scipy's binomial, pilot-based estimates
against the runs they predict, and ``run --until-decided`` against direct runs."""

import json
import math
import subprocess
import sys
import textwrap

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import binom

from montecarlo.design import planning
from montecarlo.engine.aggregate import order_statistic_ranks
from montecarlo.engine.runner import RunOptions, run_study, run_until_decided, uses_reference
from montecarlo.errors import InputError
from montecarlo.systems import study_from_dict
from tests.forked_cli import montecarlo_cli

STUDY = {
    "study": {"name": "plan-small", "system": "ground", "trials": 1000, "seed": 1},
    "sensor": {"fov_deg": [90.0, 90.0], "pixels": [512, 512]},
    "mounting": {"psi_deg": 30.0, "theta_deg": 20.0, "gamma_deg": 10.0},
    "geometry": {"L_m": 50.0, "H_m": 1.0},
    "errors": {"dx_m": {"dist": "uniform", "bound": 0.1},
               "dy_m": {"dist": "uniform", "bound": 0.1},
               "dh1_m": {"dist": "uniform", "bound": 0.1},
               "dh_m": {"dist": "uniform", "bound": 0.005},
               "pixel_px": {"dist": "normal", "sigma": 0.5}, "pixel_relation": "common"},
    "solver": {"variants": ["normalised"]},
    "spec": {"metric": "rotation_angle", "statistic": "p95", "limit": 4.5},
    "sweep": [{"geometry.L_m": [25.0, 60.0, 70.0, 100.0]}],
}
QUIET = RunOptions(n_jobs=1, progress=False)


@pytest.mark.parametrize("k, p, c, n", [(1, 0.95, 0.95, 59), (1, 0.99, 0.95, 299),
                                        (2, 0.95, 0.95, 93), (1, 0.95, 0.99, 90)])
def test_wilks_counts_of_the_literature(k, p, c, n):
    assert planning.order_statistic_trials(k, p, c) == n


@given(k=st.integers(1, 20), p=st.floats(0.5, 0.999), c=st.floats(0.5, 0.999))
@settings(max_examples=60, deadline=None)
def test_order_statistic_trials_is_the_fewest_that_cover(k, p, c):
    n = planning.order_statistic_trials(k, p, c)
    assert binom.sf(k - 1, n, 1 - p) >= c * (1 - 1e-12)
    assert n == k or binom.sf(k - 1, n - 1, 1 - p) < c


@pytest.mark.parametrize("p, delta", [(0.95, 0.01), (0.99, 0.002), (0.5, 0.05)])
def test_quantile_level_trials_meet_the_width_near_the_normal_count(p, delta):
    n = planning.quantile_level_trials(p, delta, 0.95)
    _, r, s = order_statistic_ranks(n, p, 0.95)
    assert r >= 1 and s <= n and (s - r) / n <= 2 * delta
    normal = 1.959964 ** 2 * p * (1 - p) / delta ** 2
    assert 0.9 * normal < n < 1.2 * normal


def test_pilot_estimates_predict_the_interval_of_a_larger_run():
    study = study_from_dict(STUDY)
    pilot = run_study(study, QUIET)
    plan = planning.pilot_plan(pilot, pilot.to_frame(), width=0.1)
    n = int(plan["trials_for_width_0.1"].max())
    assert 2000 < n < 200_000
    big = run_study(study_from_dict(STUDY, trials=n), QUIET).to_frame()
    width = (big["p95_hi"] - big["p95_lo"])[big["metric"] == "rotation_angle"]
    assert width.max() < 0.1 * 1.3
    assert set(plan["verdict"]) <= {"meets", "fails", "undecided"}
    undecided = plan[plan["verdict"] == "undecided"]
    assert (undecided["trials_to_decide"] > 1000).all()


def test_until_decided_grows_only_undecided_points_and_equals_direct_runs():
    study = study_from_dict(STUDY)
    first = run_study(study, QUIET).to_frame()
    assert "undecided" in set(first["verdict"].dropna())
    grown = run_until_decided(study, QUIET, max_trials=64_000)
    summary = grown.to_frame()
    spec_rows = summary.dropna(subset=["verdict"])
    assert "undecided" not in set(spec_rows["verdict"])
    same_path = RunOptions(n_jobs=1, progress=False, reference=grown.kernel == "reference")
    for gp in grown.study.points:
        direct = run_study(study_from_dict(STUDY, trials=gp.trials), same_path).to_frame()
        a = summary[summary["point"] == gp.index].reset_index(drop=True)
        b = direct[direct["point"] == gp.index].reset_index(drop=True)
        np.testing.assert_array_equal(a["p95"], b["p95"])
        assert list(a["verdict"].fillna("")) == list(b["verdict"].fillna(""))
    decided_first = first.dropna(subset=["verdict"]).groupby("point")["verdict"].apply(
        lambda v: "undecided" not in set(v))
    for p, was_decided in decided_first.items():
        assert (grown.study.points[p].trials == 1000) == was_decided


def test_until_decided_takes_the_direct_runs_path_in_every_round():
    """4 x 30000 trials are just too few to load the kernel for (estimated below 0.5 s on the
    literal path), 4 x 30000 plus a grown point are not: every round must still take the
    literal path, as a direct run of the study does, whatever --max-trials is. Each point then
    equals a direct `--reference` run of its final trials to the last bit, in every
    statistic; before, grown rounds switched to the kernel (up to ~1e-9 relative in mean,
    std and max) and which path was taken changed with --max-trials."""
    study = study_from_dict(STUDY, trials=30_000)
    assert uses_reference(study, QUIET)
    first = run_study(study, QUIET)
    assert first.kernel == "reference"
    assert list(first.to_frame().dropna(subset=["verdict"])["verdict"]).count("undecided") == 1
    for max_trials in (60_000, 240_000):
        grown = run_until_decided(study, QUIET, max_trials=max_trials)
        assert grown.kernel == "reference"
        assert sum(gp.trials for gp in grown.study.points) >= 150_000
        assert not uses_reference(grown.study, QUIET)  # a direct default run would not
        summary = grown.to_frame()
        reference = RunOptions(n_jobs=1, progress=False, reference=True)
        for gp in grown.study.points:
            if gp.trials == 30_000:
                direct = first.to_frame()
            else:
                direct = run_study(study.with_trials({gp.index: gp.trials}), reference).to_frame()
            a = summary[summary["point"] == gp.index].reset_index(drop=True)
            b = direct[direct["point"] == gp.index].reset_index(drop=True)
            pd.testing.assert_frame_equal(a, b, check_exact=True)


def test_until_decided_refuses_max_trials_below_the_studys_trials():
    with pytest.raises(InputError, match=r"--max-trials: 999 is below the study's 1,000"):
        run_until_decided(study_from_dict(STUDY), QUIET, max_trials=999)


def test_trials_to_decide_follow_the_inverse_square_root_law():
    """n = ceil(n0 (h0 / d)^2): halving the distance d to the limit quadruples the trials;
    the docstring's example, 1000 (0.2 / 0.1)^2 = 4000 and 16000 at d = 0.05, by hand."""
    n0, h0 = 1000, 0.2
    d = np.array([0.4, 0.2, 0.1, 0.05, 0.025])
    n = planning.trials_to_decide(n0, h0, d)
    np.testing.assert_array_equal(n, [250, 1000, 4000, 16000, 64000])
    np.testing.assert_array_equal(n[1:] / n[:-1], 4.0)
    assert planning.trials_to_decide(n0, h0, 0.0) == np.inf


def test_a_pilot_too_small_to_bound_the_statistic_says_what_pilot_is_needed():
    """A p99 interval has an upper end only from n >= ln(0.025)/ln(0.99) = 367.0 trials (368 at
    95 %): the plan of a 100-trial pilot printed trials_to_decide = -2**63 and a numpy warning;
    it is now one line naming 368, and a pilot of 368 is bounded."""
    assert planning.interval_trials(0.99, 0.95) == 368
    assert math.log(0.025) / math.log(0.99) == pytest.approx(367.04, abs=0.01)
    s = order_statistic_ranks(367, 0.99, 0.95)[2]
    assert s == 368  # one past the last trial: unbounded at 367
    raw = {k: v for k, v in STUDY.items() if k != "sweep"}
    raw["spec"] = {**STUDY["spec"], "statistic": "p99"}
    pilot = run_study(study_from_dict(raw, trials=100), QUIET)
    with pytest.raises(InputError, match=r"pilot of 100 trials .* p99 .* --trials 368"):
        planning.pilot_plan(pilot, pilot.to_frame())
    enough = run_study(study_from_dict(raw, trials=368), QUIET)
    plan = planning.pilot_plan(enough, enough.to_frame())
    assert plan["trials_to_decide"].notna().all() and (plan["trials_to_decide"] >= 368).all()


def test_until_decided_stops_at_max_trials_and_needs_a_spec(tmp_path):
    study = study_from_dict(STUDY)
    capped = run_until_decided(study, QUIET, max_trials=2000)
    assert max(gp.trials for gp in capped.study.points) == 2000
    path = tmp_path / "nospec.toml"
    assert montecarlo_cli("init", "ground", path).returncode == 0
    text = path.read_text()
    path.write_text(text[:text.index("[spec]")] + text[text.index("[[sweep]]"):])
    done = montecarlo_cli("run", path, "--until-decided", "--out", tmp_path / "out")
    assert done.returncode == 2 and "--until-decided needs a [spec]" in done.stderr
    assert not (tmp_path / "out").exists()


def test_plan_command_prints_and_writes_json(tmp_path):
    path = tmp_path / "plan.toml"
    done = montecarlo_cli("init", "ground", path)
    assert done.returncode == 0, done.stderr
    done = montecarlo_cli("-q", "plan", path, "--trials", "1000", "--width", "0.1", "--json")
    assert done.returncode == 0, done.stderr
    data = json.loads(done.stdout)
    assert data["order_statistic_trials"][0] == {"k (k-th largest)": 1, "trials": 59}
    assert data["pilot_trials"] == 1000 and data["points"]
    # a fresh process of its own: a refused flag is exit 2, one line, no traceback
    done = subprocess.run([sys.executable, "-m", "montecarlo", "plan", str(path),
                           "--level-width", "0.2"], capture_output=True, text=True)
    assert done.returncode == 2 and "--level-width" in done.stderr
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr, done.stderr


@pytest.mark.parametrize("spec", [None, {"statistic": "max"}, {"statistic": "std"},
                                  {"statistic": "p99"}], ids=["no-spec", "max", "std", "p99"])
def test_every_plan_branch_runs_through_the_command_line(tmp_path, spec):
    """Without a spec (the p95 is planned), on a max or a std (--coverage picks the quantile
    of the distribution-free counts; no percentile verdict to decide, the p95's interval is
    planned) and on a p99 (trials_to_decide from a pilot large enough to bound it): exit 0,
    one JSON answer, no warning."""
    text = """
        [study]
        name = "plan-branch"
        system = "ground"
        trials = 1000
        seed = 1
        [sensor]
        fov_deg = [90.0, 90.0]
        pixels = [512, 512]
        [geometry]
        L_m = 70.0
        H_m = 1.0
        [errors]
        pixel_px = { dist = "normal", sigma = 0.5 }
        pixel_relation = "common"
        """
    if spec is not None:
        text += f"""
        [spec]
        metric = "rotation_angle"
        statistic = "{spec['statistic']}"
        limit = 4.5
        """
    path = tmp_path / "plan.toml"
    path.write_text(textwrap.dedent(text))
    done = montecarlo_cli("-q", "plan", path, "--trials", "400", "--coverage", "0.9", "--json")
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr and "Warning" not in done.stderr
    data = json.loads(done.stdout)
    expected = {None: ("p95", 0.95), "max": ("max", 0.9), "std": ("std", 0.9),
                "p99": ("p99", 0.99)}[spec and spec["statistic"]]
    assert (data["statistic"], data["quantile"]) == expected
    assert data["pilot_trials"] == 400
    assert sorted(p["variant"] for p in data["points"]) == ["normalised", "raw"]
    for point in data["points"]:
        if spec is not None and spec["statistic"] == "p99":
            assert point["trials_to_decide"] >= 400
        else:
            assert "trials_to_decide" not in point
