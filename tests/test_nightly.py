"""Nightly regression check: passes on the shipped studies, fails on a regression."""

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


def test_nightly_passes_and_records_history(nightly_run):
    proc, out = nightly_run
    assert proc.returncode == 0, proc.stdout + proc.stderr
    history = pd.read_csv(out / "history.csv")
    assert len(history) == 12 + 5 * 4 and history["passed"].all()
    assert "all checks passed" in (out / "report.md").read_text()
    assert (out / "table1" / "summary.csv").exists() and (out / "trends" / "report.md").exists()


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
