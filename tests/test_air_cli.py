"""`montecarlo air` and `montecarlo transfer-alignment`, run as subprocesses."""

import json

import pytest

from tests.forked_cli import montecarlo_cli


def run_cli(*args):
    return montecarlo_cli(*args)


def test_air_json_reproduces_the_paper_within_2_percent():
    out = run_cli("air", "--json", "--trials", "20000", "--seed", "1")
    assert out.returncode == 0, out.stderr
    res = json.loads(out.stdout)
    assert res["paper_mrad"] == {"one_sigma": 1.70, "three_sigma": 5.10}
    best = [r for r in res["consistent_readings"]
            if r["scenario"] == "rss" and r["metric"] == "rotation_angle"]
    assert len(best) == 1
    assert abs(best[0]["one_sigma_mrad"] / 1.70 - 1) < 0.02
    assert abs(best[0]["three_sigma_mrad"] / 5.10 - 1) < 0.02
    metrics = {r["metric"] for r in res["rows"]}
    assert {"rotation_angle", "eq18_angle", "table1_angle", "delta_psi"} <= metrics


def test_air_text_names_every_metric():
    out = run_cli("air", "--trials", "2000")
    assert out.returncode == 0, out.stderr
    for name in ("rotation_angle", "eq18_angle", "table1_angle", "1.70", "5.10"):
        assert name in out.stdout


def test_transfer_alignment_json_has_the_five_grades():
    out = run_cli("transfer-alignment", "--json", "--trials", "5", "--duration-s", "20")
    assert out.returncode == 0, out.stderr
    rows = json.loads(out.stdout)["rows"]
    assert [(r["gyro_deg_h"], r["accel_g"]) for r in rows] == [
        (0.05, 5e-4), (0.05, 1e-4), (0.05, 5e-5), (0.5, 5e-5), (1.0, 5e-5)]
    assert [r["paper_level_arcmin"] for r in rows] == [20, 12, 5, 5, 5]
    assert all(r["level_cov_arcmin"] > 0 for r in rows)


@pytest.mark.parametrize("args", [["air", "--trials", "0"], ["air", "--bogus"],
                                  ["transfer-alignment", "--duration-s", "0.01"],
                                  ["transfer-alignment", "--manoeuvre", "loop"]])
def test_bad_flags_exit_2_with_one_line(args):
    out = run_cli(*args)
    assert out.returncode == 2
    assert out.stderr.count("\n") == 1, out.stderr
    assert "Traceback" not in out.stderr


@pytest.mark.slow
def test_transfer_alignment_table2_json_gives_the_search_and_its_check():
    """--table2: the configuration comes from the search (SI values of the effects it chose),
    five confirmed rows and the source ratios of every variant."""
    out = run_cli("transfer-alignment", "--table2", "--json", "--trials", "20",
                  "--response-runs", "5", "--jobs", "1")
    assert out.returncode == 0, out.stderr
    res = json.loads(out.stdout)
    assert len(res["rows"]) == 5 and res["worst_gap_arcmin_superposition"] >= 0
    assert set(res["params_si"]) <= {"time_offset", "time_jitter", "lever_arm_error",
                                     "flexure_sigma", "vibration_amplitude", "master_heading",
                                     "master_level", "master_velocity", "gyro_scale",
                                     "accel_scale"}
    assert {r["variant"] for r in res["ratios"]} >= {"velocity, S-turn"}


def test_transfer_alignment_table2_bad_jobs_exit_2():
    out = run_cli("transfer-alignment", "--table2", "--jobs", "0")
    assert out.returncode == 2 and "--jobs" in out.stderr and "Traceback" not in out.stderr
