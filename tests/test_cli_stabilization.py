"""`montecarlo stabilization simulate|estimate|observability`, run as a subprocess."""

import json

import pytest

from tests.forked_cli import montecarlo_cli

SHORT = ["--duration-s", "20", "--rate-hz", "50"]
TRUTH_ARCMIN = {"delta_px": 24.0, "delta_gx": 30.0, "delta_gy": -18.0, "delta_z": -78.0,
                "delta_py": 0.0}  # simulate's defaults: dg = (30, -18, 42), dp = (24, 0, -36)


def run_cli(*args):
    return montecarlo_cli("stabilization", *args)


@pytest.fixture(scope="module")
def run_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("stab") / "run.csv"
    out = run_cli("simulate", str(path), *SHORT, "--seed", "3")
    assert out.returncode == 0, out.stderr
    assert "delta_z = -78.0000" in out.stdout
    return path


def test_simulate_writes_the_documented_columns(run_csv):
    lines = run_csv.read_text().splitlines()
    assert lines[0] == "t_s,gyro_x,gyro_y,gyro_z,eta_rad,eps_rad,los_x_px,los_z_px"
    assert len(lines) == 1 + 20 * 50 + 1
    assert [p.name for p in run_csv.parent.iterdir()] == ["run.csv"]


def test_estimate_json_recovers_the_simulated_angles(run_csv):
    out = run_cli("estimate", str(run_csv), "--json")
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    assert result["converged"] and result["units"]["delta_*"] == "arcmin"
    for name, truth in TRUTH_ARCMIN.items():
        p = result["parameters"][name]
        assert abs(p["value"] - truth) <= 4 * p["sigma"], (name, p)


def test_estimate_text_names_units(run_csv):
    out = run_cli("estimate", str(run_csv))
    assert out.returncode == 0, out.stderr
    assert "arc-minutes" in out.stdout and "deg/h" in out.stdout
    assert "delta_z" in out.stdout and "dpz - dgz" in out.stdout


@pytest.mark.parametrize(
    ("edit", "needle"),
    [
        (lambda rows: [*rows[:3], rows[3].replace(rows[3].split(",")[2], "abc", 1), *rows[4:]],
         "row 4, column 'gyro_y'"),
        (lambda rows: [*rows[:5], rows[2], *rows[6:]], "row 6, column 't_s'"),
        (lambda rows: [rows[0].replace("eps_rad", "pitch"), *rows[1:]], "missing column"),
        (lambda rows: rows[:4], "at least 10"),
    ],
)
def test_malformed_csv_exits_2_with_one_line(run_csv, tmp_path, edit, needle):
    rows = run_csv.read_text().splitlines()
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(edit(rows)) + "\n")
    out = run_cli("estimate", str(bad))
    assert out.returncode == 2
    assert out.stderr.count("\n") == 1 and "Traceback" not in out.stderr
    assert needle in out.stderr and str(bad) in out.stderr


def test_unwritable_output_exits_2_and_writes_nothing(tmp_path):
    target = tmp_path / "missing-dir" / "run.csv"
    out = run_cli("simulate", str(target), *SHORT)
    assert out.returncode == 2 and out.stderr.count("\n") == 1
    assert not target.parent.exists()


def test_bad_flag_value_exits_2():
    out = run_cli("estimate", "x.csv", "--forgetting", "1.5")
    assert out.returncode == 2 and out.stderr.count("\n") == 1


def test_observability_reports_rank_and_the_unseen_direction():
    out = run_cli("observability", *SHORT)
    assert out.returncode == 0, out.stderr
    assert "rank 4 of 4" in out.stdout and "rank 4 of 5" in out.stdout
    assert "[+0.000, +0.707, +0.000, +0.000, +0.707]" in out.stdout.replace("-0.000", "+0.000")
    level_roll = run_cli("observability", *SHORT, "--rock-amp-deg", "0", "0", "5",
                         "--aim-deg", "0", "0")
    assert "rank 2 of 4" in level_roll.stdout and "not observable" in level_roll.stdout


def test_inner_gimbal_interval_mean_off_centre_round_trip(tmp_path):
    path = tmp_path / "inner.csv"
    variant = ["--mount", "inner-gimbal", "--gyro-sampling", "interval-mean"]
    out = run_cli("simulate", str(path), *SHORT, *variant, "--target-px", "300", "0",
                  "--seed", "4")
    assert out.returncode == 0, out.stderr
    assert "inner-gimbal mount" in out.stdout and "delta_gz = 42.0000" in out.stdout
    out = run_cli("estimate", str(path), *variant, "--json")
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    assert result["mount"] == "inner-gimbal" and result["gyro_sampling"] == "interval-mean"
    truth = {**TRUTH_ARCMIN, "delta_gz": 42.0}
    for name, value in truth.items():
        p = result["parameters"][name]
        assert abs(p["value"] - value) <= 4 * p["sigma"], (name, p)
    assert abs(result["aim_px"][0] - 300.0) < 0.1 and abs(result["aim_px"][1]) < 0.1


def test_observability_of_the_inner_gimbal_mount_separates_dpz_and_dgz():
    out = run_cli("observability", *SHORT, "--mount", "inner-gimbal")
    assert out.returncode == 0, out.stderr
    assert "rank 5 of 5 for X" in out.stdout and "rank 5 of 5 for [dpx" in out.stdout
    assert "unseen direction" not in out.stdout


@pytest.mark.parametrize("flag", [["--mount", "outer"], ["--gyro-sampling", "mean"]])
def test_unknown_variant_exits_2(flag):
    out = run_cli("estimate", "x.csv", *flag)
    assert out.returncode == 2 and "Traceback" not in out.stderr and flag[0] in out.stderr
