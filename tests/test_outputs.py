"""Study outputs: files, provenance, report and plots; all or nothing."""

import json
import textwrap

import pandas as pd
import pytest

from montecarlo.cli import main
from montecarlo.output import outputs

STUDY = """
[study]
name = "out"
description = "output test"
system = "ground"
trials = 2000
seed = 3
block_size = 1000
per_trial = true

[sensor]
fov_deg = [90.0, 90.0]
pixels = [512, 512]

[geometry]
L_m = 100.0
H_m = 2.0

[errors]
dx_m = { dist = "uniform", bound = 0.1 }
pixel_px = { dist = "normal", sigma = 0.5 }
pixel_relation = "independent"

[spec]
metric = "rotation_angle"
variant = "normalised"
limit = 3.0

[[sweep]]
"geometry.L_m" = [50.0, 100.0]
"geometry.H_m" = [1.0, 2.0, 4.0]
"""


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("outputs")
    p = tmp / "out.toml"
    p.write_text(textwrap.dedent(STUDY))
    out = tmp / "results" / "out"
    assert main(["run", str(p), "--quiet", "--out", str(out)]) == 0
    return p, out


def test_files_written(run_dir):
    _, out = run_dir
    names = {p.name for p in out.iterdir()}
    assert {"summary.csv", "summary.parquet", "trials.parquet", "provenance.json",
            "report.md", "plots"} <= names
    plots = {p.name for p in (out / "plots").iterdir()}
    assert {"histograms.png", "map_L_H.png", "trend_geometry_L_m.png",
            "trend_geometry_H_m.png"} <= plots
    trials = pd.read_parquet(out / "trials.parquet")
    assert len(trials) == 6 * 2000 and "normalised/rotation_angle_mrad" in trials


def test_trials_parquet_holds_the_summarys_unit_named_in_its_columns(run_dir):
    """trials.parquet held rad under a bare name while summary.csv holds mrad: its columns now
    name their unit and hold the summary's values (the max of each point's per-trial values is
    the summary's max, the mean its mean)."""
    _, out = run_dir
    trials = pd.read_parquet(out / "trials.parquet")
    summary = pd.read_csv(out / "summary.csv")
    value_columns = [c for c in trials.columns if c not in ("point", "trial")]
    assert value_columns and all(c.endswith("_mrad") for c in value_columns)
    for (variant, metric), row in summary.set_index(["variant", "metric"]).groupby(level=[0, 1]):
        for point, r in row.reset_index().set_index("point").iterrows():
            values = trials.loc[trials["point"] == point, f"{variant}/{metric}_mrad"]
            magnitude = values.abs() if r["percentiles_of"] == "abs" else values
            assert r["max"] == pytest.approx(magnitude.max(), rel=1e-12)
            assert r["mean"] == pytest.approx(values.mean(), rel=1e-9)


def test_summary_columns_and_units(run_dir):
    _, out = run_dir
    df = pd.read_csv(out / "summary.csv")
    assert set(df["unit"]) == {"mrad"}
    for col in ("count", "invalid", "mean", "std", "p50", "p90", "p95", "p99", "max",
                "p95_lo", "p95_hi", "percentiles_of", "geometry.L_m", "geometry.H_m"):
        assert col in df.columns
    assert set(df["metric"]) == {"rotation_angle", "eq18_angle", "table1_angle",
                                 "delta_psi", "delta_theta", "delta_gamma"}
    assert (df.loc[df["metric"].str.startswith("delta"), "percentiles_of"] == "abs").all()


def test_provenance(run_dir):
    _, out = run_dir
    prov = json.loads((out / "provenance.json").read_text())
    for key in ("study_hash", "seed", "package_version", "git_commit", "libraries",
                "resolved_study", "run_options"):
        assert key in prov
    assert prov["seed"] == 3 and len(prov["study_hash"]) == 64
    assert prov["libraries"]["numpy"]
    assert len(prov["resolved_study"]["points"]) == 6


def test_report_states_assumptions_and_spec(run_dir):
    _, out = run_dir
    report = (out / "report.md").read_text()
    assert "independent between targets" in report
    assert "## Spec" in report and ("meets" in report or "fails" in report)
    assert "plots/map_L_H.png" in report


def test_failure_leaves_previous_results_untouched(run_dir, monkeypatch):
    p, out = run_dir
    before = (out / "summary.csv").read_bytes()

    def broken(*_):
        raise RuntimeError("plotting failed")

    monkeypatch.setattr(outputs, "all_figures", broken)
    with pytest.raises(RuntimeError):
        main(["run", str(p), "--quiet", "--out", str(out), "--seed", "4"])
    assert (out / "summary.csv").read_bytes() == before
    assert not [q for q in out.parent.iterdir() if q.name.startswith(".out.")]


def test_rebin_spreads_log_bins_evenly():
    """Counts are kept, and a uniform density over log bins stays flat on linear bins."""
    import numpy as np

    from montecarlo.output.plots import _rebin

    lower = np.array([0.0, 1.0, 2.0, 4.0])
    upper = np.array([1.0, 2.0, 4.0, 8.0])
    counts = np.array([10, 10, 20, 40])  # 10 per unit width
    h = _rebin(lower, upper, counts, 1.0, np.linspace(0.0, 8.0, 17))
    np.testing.assert_allclose(h, 5.0)
    assert h.sum() == counts.sum()


def test_a_successful_run_removes_its_studys_stale_checkpoints_only(tmp_path):
    """Checkpoints of older source versions were never removed. After a successful run, the
    study's checkpoints saved by another code fingerprint (or package version) go; another
    study's, the same name with another study hash, and a folder without a key stay."""
    from montecarlo.engine.checkpoints import KEY_FILE, Checkpoints
    from montecarlo.systems import load_study

    p = tmp_path / "out.toml"
    p.write_text(textwrap.dedent(STUDY).replace("per_trial = true", "per_trial = false"))
    root = tmp_path / ".checkpoints"
    key = Checkpoints(root, load_study(p)).key
    made = {}
    for name, folder, record in [
            ("old_code", "out-00000000000000a1", {**key, "code": "0" * 64}),
            ("old_version", "out-00000000000000a2", {**key, "version": "0.0.1"}),
            ("other_study", "other-00000000000000a3", {**key, "code": "0" * 64}),
            ("other_hash", "out-00000000000000a4", {**key, "study": "f" * 64, "code": "0"}),
            ("no_key", "out-00000000000000a5", None)]:
        d = root / folder
        d.mkdir(parents=True)
        (d / "point-000000.pkl").write_bytes(b"old")
        if record is not None:
            (d / KEY_FILE).write_text(json.dumps(record))
        made[name] = d
    assert main(["run", str(p), "--quiet", "--out", str(tmp_path / "out")]) == 0
    assert not made["old_code"].exists() and not made["old_version"].exists()
    assert made["other_study"].exists() and made["other_hash"].exists()
    assert made["no_key"].exists()
    assert sorted(d.name for d in root.iterdir()) == sorted(
        made[n].name for n in ("other_study", "other_hash", "no_key"))
