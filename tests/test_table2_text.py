"""Seed 000, Table 2 beside our transfer-alignment filter: the grid's columns against the
filter's covariance and the actual errors of its runs, and the printed text against the
paper's rows (copied here from the seed's text, 表2) and values derived by hand."""

import math
import re
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from montecarlo.seed000 import table2 as t2
from montecarlo.seed000 import transfer_alignment as ta

SEED_TABLE2 = (
    # 陀螺精度 [°/h], 加表精度 [g], IMU 航向精度 [′], IMU 水平精度 [′] -- seed 000, Table 2
    (0.05, 5e-4, 13, 20),
    (0.05, 1e-4, 8, 12),
    (0.05, 5e-5, 3, 5),
    (0.50, 5e-5, 3, 5),
    (1.00, 5e-5, 3, 5),
)
ARCMIN = math.pi / 10800.0
SHORT = ta.AlignmentConfig(duration=2.0)  # ten Kalman updates: fast, far from converged


def test_grade_config_replaces_the_imu_grade_only():
    """0.5 °/h = 0.5 pi / 180 / 3600 rad/s = 2.424e-6 rad/s; 1e-4 g = 9.80665e-4 m/s²."""
    cfg = t2.grade_config(np.float32(2.5e-6), 1)
    assert type(cfg.gyro_drift) is float and type(cfg.accel_bias) is float
    assert cfg == replace(ta.AlignmentConfig(), gyro_drift=float(np.float32(2.5e-6)),
                          accel_bias=1.0)
    assert t2.grade_config(1e-6, 2e-3, SHORT) == replace(SHORT, gyro_drift=1e-6, accel_bias=2e-3)
    row = t2.TABLE2_ROWS[3]
    assert row.gyro_drift == pytest.approx(0.5 * math.pi / 180 / 3600, rel=1e-12)
    assert t2.TABLE2_ROWS[1].accel_bias == pytest.approx(9.80665e-4, rel=1e-12)


def test_table2_grid_is_the_paper_beside_the_filter_sigma_and_the_rms_of_its_runs():
    """Per grade (built here from the paper's units, not by the module): the filter's final
    1σ (sqrt of the covariance diagonal; level = RSS of east and north, and their larger),
    and the rms over the runs of the actual final error, from the runs of ``simulate`` with
    the grade's stream (one stream per row spawned from the seed), all in arc-minutes."""
    runs = 3
    table = t2.table2_grid(SHORT, rng=5, runs=runs)
    assert len(table) == 5 and (table["runs"] == runs).all()
    seeds = np.random.SeedSequence(5).spawn(5)
    for (_, r), printed, seed in zip(table.iterrows(), SEED_TABLE2, seeds, strict=True):
        assert (r.gyro_deg_h, r.accel_g, r.paper_heading_arcmin, r.paper_level_arcmin) == printed
        cfg = replace(SHORT, gyro_drift=printed[0] * math.pi / 180 / 3600,
                      accel_bias=printed[1] * 9.80665)
        P = ta.covariance_analysis(cfg).P[-1]
        assert r.heading_cov_arcmin == pytest.approx(math.sqrt(P[2, 2]) / ARCMIN, rel=1e-9)
        assert r.level_cov_arcmin == pytest.approx(math.sqrt(P[0, 0] + P[1, 1]) / ARCMIN,
                                                   rel=1e-9)
        assert r.level_axis_max_cov_arcmin == pytest.approx(
            math.sqrt(max(P[0, 0], P[1, 1])) / ARCMIN, rel=1e-9)
        phi = ta.simulate(cfg, np.random.default_rng(seed), runs).phi[-1]  # (runs, 3)
        rms = [math.sqrt(sum(phi[j, i] ** 2 for j in range(runs)) / runs) for i in range(3)]
        assert r.heading_mc_arcmin == pytest.approx(rms[2] / ARCMIN, rel=1e-9)
        assert r.level_mc_arcmin == pytest.approx(math.hypot(rms[0], rms[1]) / ARCMIN,
                                                  rel=1e-9)
    # the east and north 1σ differ here, so the larger is not the RSS over sqrt(2)
    assert not np.allclose(table.level_axis_max_cov_arcmin, table.level_cov_arcmin / math.sqrt(2))


def test_table2_grid_takes_a_generator_and_the_default_configuration():
    """A Generator seeds the spawned streams through one draw: the same Generator state gives
    the same table, another seed another Monte Carlo (the covariance is the same)."""
    a = t2.table2_grid(SHORT, rng=np.random.default_rng(3), runs=2)
    b = t2.table2_grid(SHORT, rng=np.random.default_rng(3), runs=2)
    c = t2.table2_grid(SHORT, rng=np.random.default_rng(4), runs=2)
    pd.testing.assert_frame_equal(a, b)
    assert not np.allclose(a.heading_mc_arcmin, c.heading_mc_arcmin)
    np.testing.assert_allclose(a.heading_cov_arcmin, c.heading_cov_arcmin, rtol=1e-12)
    draw = np.random.default_rng(3).integers(2**63)
    pd.testing.assert_frame_equal(a, t2.table2_grid(SHORT, rng=int(draw), runs=2))


def test_describe_states_the_configuration_in_the_units_people_use():
    """By hand: dt 0.01 s -> IMU 100 Hz; kf_interval 4 -> update every 0.04 s, 25 Hz; ARW
    0.01 °/√h = 0.01 pi / 180 / 60 rad/√s; VRW 50 µg/√Hz = 50e-6 g; attitude noise 0.25 mrad;
    bank 20°, initial misalignment 1σ 0.25° about each level axis, 2° in heading."""
    cfg = ta.AlignmentConfig(manoeuvre="wing_rock", speed=150.0, bank=math.radians(20.0),
                             period=40.0, duration=90.0, dt=0.01, kf_interval=4,
                             velocity_noise=0.1, attitude_matching=True,
                             attitude_noise=0.25e-3, gyro_arw=0.01 * math.pi / 180 / 60,
                             accel_vrw=50e-6 * 9.80665, initial_level=math.radians(0.25),
                             initial_heading=math.radians(2.0))
    assert t2.describe(cfg) == (
        "velocity + attitude matching; wing_rock (speed 150 m/s, bank 20°, period 40 s), 90 s; "
        "IMU 100 Hz, Kalman update 25 Hz; master velocity noise 0.1 m/s, attitude noise "
        "0.25 mrad; ARW 0.01 °/√h, VRW 50 µg/√Hz; initial misalignment 1σ 0.25° about each "
        "level axis, 2° in heading")
    assert t2.describe(ta.AlignmentConfig()) == (
        "velocity matching; s_turn (speed 200 m/s, bank 30°, period 60 s), 120 s; IMU 50 Hz, "
        "Kalman update 5 Hz; master velocity noise 0.05 m/s; ARW 0.005 °/√h, VRW 20 µg/√Hz; "
        "initial misalignment 1σ 0.5° about each level axis, 1° in heading")


def _hand_table(runs=7):
    rows = []
    for i, (g, a, h, lv) in enumerate(SEED_TABLE2):
        rows.append({"gyro_deg_h": g, "accel_g": a, "paper_heading_arcmin": h,
                     "paper_level_arcmin": lv, "heading_cov_arcmin": 0.125 + i,
                     "heading_mc_arcmin": 0.375 + i, "level_cov_arcmin": 1.625 + i,
                     "level_mc_arcmin": 1.875 + i, "level_axis_max_cov_arcmin": 9.0,
                     "runs": runs})
    return pd.DataFrame(rows)


def test_table2_text_prints_the_papers_rows_beside_ours():
    """Each row: the paper's gyro [°/h], accelerometer [g], heading and level [′] as printed,
    ours (cov, mc) to two decimals, and sqrt(2) b / g in arc-minutes, the level error a bias b
    alone leaves: sqrt(2) 5e-4 rad = 7.071e-4 rad = 2.43′, 1e-4 -> 0.49′, 5e-5 -> 0.24′."""
    text = t2.format_table2(_hand_table(), SHORT)
    lines = text.splitlines()
    rows = lines[6:11]
    expected_bias = ["2.43", "0.49", "0.24", "0.24", "0.24"]
    for i, (line, (g, a, h, lv)) in enumerate(zip(rows, SEED_TABLE2, strict=True)):
        grade, heading, level, bias = (part.split() for part in line.split("|"))
        assert [float(grade[0]), float(grade[1])] == [g, a]
        assert grade == [f"{g:.2f}", f"{a:.0e}"]
        assert heading == [str(h), f"{0.125 + i:.2f}", f"{0.375 + i:.2f}"]
        assert level == [str(lv), f"{1.625 + i:.2f}", f"{1.875 + i:.2f}"]
        assert bias == [expected_bias[i]]
    assert f"{math.sqrt(2) * 5e-4 / ARCMIN:.2f}" == "2.43"
    assert lines[1] == "Ours: " + t2.describe(SHORT) + "."
    assert lines[2] == ("Heading = phi_U; level = RSS of the two level axes (phi_E, phi_N); "
                        "cov = filter 1σ, mc = rms of the actual error over 7 runs.")
    assert lines[11:] == [
        "",
        "bias/g x √2: the level error (RSS of two axes) that an accelerometer bias alone leaves",
        "without any manoeuvre (tilt and horizontal bias indistinguishable), in arc-min."]


def test_table2_text_has_the_papers_columns_over_its_numbers():
    """Title and column names (the paper's: gyro °/h, accel g, heading and level, 1σ, arc-min)
    and every column name right-aligned over its numbers."""
    lines = t2.format_table2(_hand_table(), SHORT).splitlines()
    assert lines[0] == ("Seed 000, Table 2: transfer-alignment accuracy of the slave IMU, "
                        "1σ [arc-min]")
    assert lines[3] == ""
    names, units, first = lines[4], lines[5], lines[6]
    assert names.split() == ["gyro", "accel", "|", "heading", "ours", "ours", "|", "level",
                             "ours", "ours", "|", "bias/g"]
    assert units.split() == ["°/h", "g", "|", "paper", "cov", "mc", "|", "paper", "cov", "mc",
                             "|", "x", "√2"]
    ends = [m.end() for m in re.finditer(r"\S+", first)]
    assert [m.end() for m in re.finditer(r"\S+", names)] == ends
    assert [m.end() for m in re.finditer(r"\S+", units.replace("x √2", "x_√2"))] == ends


def test_table2_grid_defaults_seed_0_and_100_runs():
    """``montecarlo transfer-alignment`` reports 100 runs per grade, seeded with 0."""
    default = t2.table2_grid(SHORT)
    assert (default["runs"] == 100).all()
    pd.testing.assert_frame_equal(default, t2.table2_grid(SHORT, rng=0, runs=100))
