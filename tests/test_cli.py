"""The command line, run as a subprocess (as users and CI run it)."""

import json

import pytest

from tests.forked_cli import montecarlo_cli


def run_cli(*args, **kwargs):
    return montecarlo_cli(*args, **kwargs)


def test_table1_json():
    out = run_cli("table1", "--json")
    assert out.returncode == 0, out.stderr
    rows = json.loads(out.stdout)
    assert len(rows) == 6
    for row in rows:
        assert list(row) == ["df_px", "L_m", "H_m", "db_mm", "paper_delta_mrad",
                             "paper_norm_delta_mrad", "delta_mrad", "norm_delta_mrad"]
        assert abs(row["delta_mrad"] / row["paper_delta_mrad"] - 1) < 0.01


def test_table1_text_names_the_metric():
    out = run_cli("table1")
    assert out.returncode == 0, out.stderr
    assert "arccos((1 + tr D)/4)" in out.stdout
    assert out.stdout.count("\n") > 10


@pytest.mark.parametrize("args", [["table1", "--bogus"], ["nosuchcommand"], []])
def test_bad_flags_exit_2_with_one_line(args):
    out = run_cli(*args)
    assert out.returncode == 2
    assert out.stderr.count("\n") == 1, out.stderr
    assert "Traceback" not in out.stderr
