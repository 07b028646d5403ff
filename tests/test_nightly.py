"""Nightly regression check: passes on the shipped studies, fails on a regression.

Slow (the acceptance suite ``nightly``): each test runs the whole nightly check, as a user's
nightly job does; Table 1 itself is checked by the default tests of ``tests/test_table1.py``."""

import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from montecarlo.tools import nightly

ROOT = Path(__file__).parent.parent


@pytest.fixture(scope="module")
def nightly_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("nightly") / "nightly"
    proc = subprocess.run([sys.executable, "-m", "montecarlo", "nightly", "--quiet",
                           "--studies", str(ROOT / "studies"), "--out", str(out)],
                          capture_output=True, text=True, timeout=900)
    return proc, out


@pytest.mark.slow
def test_nightly_passes_and_records_history(nightly_run):
    proc, out = nightly_run
    assert proc.returncode == 0, proc.stdout + proc.stderr
    history = pd.read_csv(out / "history.csv")
    assert history["check"].nunique() == 12 + 5 * 4 and history["passed"].all()
    assert len(history) == 12 + (4 + 3 + 4 + 4 + 4) * 4  # one row per point of each trend
    assert "all checks passed" in (out / "report.md").read_text()
    assert (out / "table1" / "summary.csv").exists() and (out / "trends" / "report.md").exists()


@pytest.mark.slow
def test_a_flipped_trend_or_a_drifted_table1_value_fails(nightly_run):
    _, out = nightly_run
    trends = pd.read_csv(out / "trends" / "summary.csv")
    sel = ((trends["geometry.L_m"] == 400.0) & (trends["errors.pixel_relation"] == "common")
           & (trends["metric"] == "rotation_angle"))
    trends.loc[sel, ["mean", "p95"]] *= 10.0  # L = 400 m suddenly much worse
    failed = [c.name for c in nightly.trend_checks(trends) if not c.passed]
    assert failed and all("falls with L" in name for name in failed)

    table = pd.read_csv(out / "table1" / "summary.csv")
    row = (table["errors.evaluation"] == "worst_case") & (table["metric"] == "table1_angle")
    table.loc[row.idxmax(), "max"] *= 1.02
    failed = [c.name for c in nightly.table1_checks(table) if not c.passed]
    assert len(failed) == 1


@pytest.mark.slow
def test_nightly_exits_nonzero_on_regression(tmp_path):
    """A model change that moves Table 1 by ~2 % (a 500-pixel detector) must exit 1."""
    studies = tmp_path / "studies"
    shutil.copytree(ROOT / "studies", studies)
    t1 = studies / "table1.toml"
    t1.write_text(t1.read_text().replace("pixels = [512, 512]", "pixels = [500, 500]"))
    proc = subprocess.run([sys.executable, "-m", "montecarlo", "nightly", "--quiet",
                           "--studies", str(studies), "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 1
    assert "FAIL" in proc.stdout


@pytest.mark.slow
def test_history_holds_numbers_with_units_intervals_and_expectations(nightly_run):
    _, out = nightly_run
    history = pd.read_csv(out / "history.csv")
    assert list(history.columns) == nightly.HISTORY_COLUMNS
    t1 = history[history["check"] == "table1 row 1 raw"].iloc[0]
    assert t1["unit"] == "mrad" and t1["expected_lo"] == pytest.approx(7.37 * 0.99)
    assert t1["expected_lo"] <= t1["value"] <= t1["expected_hi"]
    trend = history[history["quantity"].str.startswith("p95 of rotation_angle at range L = ")]
    assert len(trend) == 4 * 4 and (trend["ci_lo"] < trend["value"]).all() \
        and (trend["value"] < trend["ci_hi"]).all()
    assert (out / "plots" / "history.png").stat().st_size > 10_000


@pytest.mark.slow
def test_an_error_too_small_for_the_table1_tolerance_fails_the_next_nightly(nightly_run, tmp_path,
                                                                             monkeypatch):
    """A 1e-6 relative error in the equivalent angles of eqs. (15)-(16) keeps Table 1 within the
    paper's 1 % tolerance, but the paired comparison with the previous run sees it."""
    from montecarlo.seed000 import ground

    _, first = nightly_run
    out = tmp_path / "nightly"
    shutil.copytree(first, out)
    angles = ground.equivalent_angles_of_target

    def slightly_off(C_ba, r_b):
        psi_m, theta_m, front = angles(C_ba, r_b)
        return psi_m * (1 + 1e-6), theta_m * (1 + 1e-6), front

    monkeypatch.setattr(ground, "equivalent_angles_of_target", slightly_off)
    passed, checks = nightly.run_nightly(ROOT / "studies", out, n_jobs=1, progress=False)
    failed = [c for c in checks if not c.passed]
    assert not passed and len(failed) == 1
    assert failed[0].name.startswith("table1: unchanged since the previous nightly")
    assert all(c.passed for c in checks if c.name.startswith("table1 row"))
    history = pd.read_csv(out / "history.csv")
    assert history["timestamp_utc"].nunique() == 2
    passed, _ = nightly.run_nightly(ROOT / "studies", tmp_path / "again", n_jobs=1,
                                    progress=False)
    assert passed  # no previous run to compare with
