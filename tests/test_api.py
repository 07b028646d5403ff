"""The Python interface: ``montecarlo.run`` returns a Result and writes nothing unless asked."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import montecarlo
from montecarlo.engine.runner import RunOptions, run_study
from montecarlo.errors import InputError
from montecarlo.systems import study_from_dict

ROOT = Path(__file__).parent.parent
TABLE1 = ROOT / "studies" / "table1.toml"

SMALL = {
    "study": {"name": "api-small", "system": "ground", "trials": 4000, "seed": 5},
    "sensor": {"fov_deg": [90.0, 90.0], "pixels": [512, 512]},
    "mounting": {"psi_deg": 30.0, "theta_deg": 20.0, "gamma_deg": 10.0},
    "geometry": {"L_m": 50.0, "H_m": 1.0},
    "errors": {"dx_m": {"dist": "uniform", "bound": 0.1},
               "dy_m": {"dist": "uniform", "bound": 0.1},
               "dh1_m": {"dist": "uniform", "bound": 0.1},
               "dh_m": {"dist": "uniform", "bound": 0.005},
               "pixel_px": {"dist": "normal", "sigma": 0.5}, "pixel_relation": "common"},
    "solver": {"variants": ["normalised"]},
    "spec": {"metric": "rotation_angle", "statistic": "p95", "limit": 4.6},
    "sweep": [{"geometry.L_m": [50.0, 100.0]}],
}


def test_run_from_a_dict_equals_the_runner_and_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = montecarlo.run(SMALL)
    assert list(tmp_path.iterdir()) == []  # no checkpoints, no results
    direct = run_study(study_from_dict(SMALL), RunOptions(progress=False)).to_frame()
    pd.testing.assert_frame_equal(result.summary, direct, check_exact=True)
    assert set(result.summary["unit"]) == {"mrad"}
    assert list(result.verdicts["verdict"]) == ["fails", "meets"]  # p95 4.95, 4.29 mrad


def test_trials_and_seed_override_the_study():
    a = montecarlo.run(SMALL, trials=1000, seed=1)
    b = montecarlo.run(SMALL, trials=1000, seed=2)
    assert (a.summary["trials"] == 1000).all()
    assert not np.array_equal(a.summary["mean"], b.summary["mean"])
    study = montecarlo.load_study(TABLE1)
    again = montecarlo.run(study, trials=1000)
    assert set(again.summary["trials"]) == {64, 1000}  # corners stay enumerated


def test_plot_report_and_figures(tmp_path):
    result = montecarlo.run(SMALL, trials=1000)
    ax = result.plot()
    assert ax.get_ylabel() == "true rotation angle φ of D [mrad]"
    assert "spec: p95 ≤ 4.6 mrad" in ax.get_legend_handles_labels()[1]
    with pytest.raises(ValueError, match="metric 'nope' is not in this study"):
        result.plot("nope")
    assert "histograms.png" in result.figures()
    out = result.report(tmp_path / "report")
    assert (out / "summary.csv").is_file() and (out / "report.md").is_file()
    prov = json.loads((out / "provenance.json").read_text())
    assert prov["kind"] == "run" and prov["study"] == "api-small"
    # 1000 trials: the literal path, in this process, as recorded and as reported
    assert (prov["kernel"], prov["workers"]) == ("reference", 0)
    assert ("trials computed by the literal reference implementation, in the calling process"
            in (out / "report.md").read_text())
    pd.testing.assert_frame_equal(pd.read_parquet(out / "summary.parquet"), result.summary)


def test_a_mean_spec_on_a_signed_metric_is_reported_as_the_bias_it_judges(tmp_path):
    """The yaw error's mean is signed; the spec judges its magnitude and says so, in the
    report's requirement, its table, and the summary's spec value."""
    raw = {**SMALL, "spec": {"metric": "delta_psi", "statistic": "mean", "limit": 0.05},
           "sweep": []}
    result = montecarlo.run(raw, trials=1000)
    row = result.summary[result.summary["metric"] == "delta_psi"].iloc[0]
    assert row["spec_value"] == abs(row["mean"]) > 0
    report = (result.report(tmp_path / "r") / "report.md").read_text()
    assert "Requirement: abs(mean) of `delta_psi`" in report
    assert "| abs(mean) (valid trials) | abs(mean) (all trials) |" in report


@pytest.mark.parametrize(("trials", "open_above"), [(40, True), (200, False)])
def test_p95_bars_end_in_an_arrow_where_the_trials_cannot_bound_p95_above(trials, open_above):
    """Below about 60 trials there is no distribution-free upper bound of p95 at 95 %
    (``p95_hi`` NaN): the bar is open above (an up caret, matplotlib's CARETUPBASE), not
    closed at the estimate."""
    from matplotlib.container import ErrorbarContainer
    from matplotlib.lines import CARETUPBASE

    result = montecarlo.run({**SMALL, "sweep": []}, trials=trials)
    rows = result.summary[result.summary["metric"] == "rotation_angle"]
    assert rows["p95_hi"].isna().all() == open_above
    bars = [c for c in result.plot().containers if isinstance(c, ErrorbarContainer)]
    markers = {line.get_marker() for line in bars[0].lines[1]}
    assert (CARETUPBASE in markers) == open_above


def test_a_study_without_a_spec_or_a_rotation_angle_plots_its_first_metric():
    """The collimation system has no ``rotation_angle``: without a spec the plot shows its
    first metric (it raised asking for the rotation angle)."""
    import tomllib

    from montecarlo.systems.catalog import starter_study

    raw = tomllib.loads(starter_study("collimation"))
    assert "spec" not in raw
    result = montecarlo.run(raw, trials=4)
    first = result.summary["metric"].iloc[0]
    assert result.plot().get_ylabel().startswith(result._result.study.metric(first).label)


def test_histogram_titles_give_the_no_solution_share_of_each_variant_where_they_differ():
    """range_sizing at 200 trials: at point 37 the raw solver finds no solution in 15.0 % of
    the trials, the normalised one in 2.5 %; the panel says both (it gave the larger alone)."""
    from montecarlo.output.plots import histogram_figure

    result = montecarlo.run(ROOT / "studies" / "range_sizing.toml", trials=200)
    rows = result.summary[(result.summary["metric"] == "rotation_angle")
                          & (result.summary["point"] == 37)].set_index("variant")
    assert list(rows.loc[["raw", "normalised"], "invalid_fraction"]) == [0.15, 0.025]
    titles = [ax.get_title().replace("\n", " ")
              for ax in histogram_figure(result._result, result.summary).axes]
    assert any(t.startswith("37:") and t.endswith("no\u00a0solution: raw 15.0%, normalised 2.5%")
               for t in titles)


def test_a_sampled_max_spec_says_what_meets_means(tmp_path):
    """A max over sampled trials bounds a share of all trials, not every one: the report's
    requirement says so; a percentile's does not need to."""
    raw = {**SMALL, "spec": {"metric": "rotation_angle", "statistic": "max", "limit": 50.0},
           "sweep": []}
    note = "Over sampled trials, `meets` says that the largest trial drawn is within the limit"
    result = montecarlo.run(raw, trials=1000)
    assert set(result.summary["verdict"].dropna()) == {"meets"}
    assert note in (result.report(tmp_path / "max") / "report.md").read_text()
    p95 = montecarlo.run({**raw, "spec": {**raw["spec"], "statistic": "p95"}}, trials=1000)
    assert note not in (p95.report(tmp_path / "p95") / "report.md").read_text()


def test_a_mistake_is_an_input_error_naming_the_key():
    bad = {**SMALL, "sensor": {"fov_deg": [90.0, 90.0], "pixels": [0, 512]}}
    with pytest.raises(InputError, match=r"sensor\.pixels"):
        montecarlo.run(bad)


def test_import_montecarlo_is_quick_and_lazy():
    code = ("import sys, montecarlo; print(sorted(m for m in ('pandas', 'numba', 'matplotlib') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


def test_worst_case_corners_are_exact_and_a_sampled_max_states_its_coverage():
    result = montecarlo.run(TABLE1, trials=2000)
    s = result.summary
    corners = s[s["errors.evaluation"] == "worst_case"]
    sampled = s[s["errors.evaluation"] == "sampled"]
    assert set(corners["sampling"]) == {"enumerated"} and set(sampled["sampling"]) == {"random"}
    assert corners["p95_lo"].isna().all() and sampled["p95_lo"].notna().all()
    spec = sampled[sampled["verdict"].notna()]
    # Wilks: the max of n trials bounds a fraction (1 - confidence) ** (1 / n) of the population
    np.testing.assert_allclose(spec["spec_coverage"], 0.05 ** (1 / 2000))
    assert corners.loc[corners["verdict"].notna(), "spec_coverage"].isna().all()
