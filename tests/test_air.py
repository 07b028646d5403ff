"""Air dynamic calibration, seed 000 section 2: eq. (19), error model, 1.70 / 5.10 mrad."""

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from montecarlo import units
from montecarlo.errors import InputError
from montecarlo.geometry import metrics
from montecarlo.geometry.rotations import mounting_matrix
from montecarlo.seed000 import air
from montecarlo.seed000 import table2 as t2
from montecarlo.systems.air import AIR
from montecarlo.units import ARCMIN, MRAD

rng = np.random.default_rng(19)
ANGLES = tuple(np.radians([30.0, 20.0, 10.0]))


def _random_passive(n):
    return Rotation.random(n, random_state=rng).as_matrix().transpose(0, 2, 1)


def test_eq19_recovers_the_mounting_from_two_attitudes():
    """C_b^a = C_g^a (C_g^{b_f})^T when C_g^a = C_b^a C_g^{b_f} (seed 000, eq. 19)."""
    C_ba, C_gbf = _random_passive(50), _random_passive(50)
    np.testing.assert_allclose(air.mounting_from_attitudes(C_ba @ C_gbf, C_gbf), C_ba,
                               atol=1e-14)


def test_frame_turned_by_is_the_transpose_of_scipy_active_rotation():
    v = rng.normal(size=(20, 3))
    np.testing.assert_allclose(air.frame_turned_by(v),
                               Rotation.from_rotvec(v).inv().as_matrix(), atol=1e-14)


def test_no_error_gives_the_true_mounting():
    C_ba, C_gbf = mounting_matrix(*ANGLES), _random_passive(10)
    C_bc = air.computed_mounting(C_ba, C_gbf, np.zeros(3))
    np.testing.assert_allclose(C_bc, np.broadcast_to(C_ba, C_bc.shape), atol=1e-14)


def test_transfer_alignment_error_appears_in_product_axes():
    """D = exp([(C_g^a phi) x]): the rotation vector of D is the slave's misalignment expressed
    in the product frame, so its angle is |phi| exactly, for any aircraft attitude."""
    C_ba, C_gbf = mounting_matrix(*ANGLES), _random_passive(200)
    phi = rng.normal(scale=1e-2, size=(200, 3))
    D = metrics.error_matrix(air.computed_mounting(C_ba, C_gbf, phi), C_ba)
    C_ga = C_ba @ C_gbf
    np.testing.assert_allclose(Rotation.from_matrix(D).as_rotvec(),
                               np.einsum("nij,nj->ni", C_ga, phi), atol=1e-14)
    np.testing.assert_allclose(metrics.rotation_angle(D), np.linalg.norm(phi, axis=-1),
                               rtol=1e-10)


def test_installation_error_is_a_rotation_in_the_product_frame():
    """Only C_{a_1}^a: D = C_a^{a_1}, rotation vector -epsilon (a_1 is a turned by epsilon)."""
    C_ba, C_gbf = mounting_matrix(*ANGLES), _random_passive(30)
    eps = rng.normal(scale=1e-3, size=(30, 3))
    D = metrics.error_matrix(air.computed_mounting(C_ba, C_gbf, np.zeros(3), eps), C_ba)
    np.testing.assert_allclose(D, air.frame_turned_by(eps), atol=1e-14)


def test_master_error_cancels_when_shared_and_enters_when_not():
    C_ba, C_gbf = mounting_matrix(*ANGLES), _random_passive(30)
    phi_m = rng.normal(scale=1e-3, size=(30, 3))
    zero = np.zeros(3)
    D1 = metrics.error_matrix(air.computed_mounting(C_ba, C_gbf, zero, zero, phi_m, 1.0), C_ba)
    np.testing.assert_allclose(D1, np.broadcast_to(np.eye(3), D1.shape), atol=1e-14)
    D0 = metrics.error_matrix(air.computed_mounting(C_ba, C_gbf, zero, zero, phi_m, 0.0), C_ba)
    np.testing.assert_allclose(metrics.rotation_angle(D0), np.linalg.norm(phi_m, axis=-1),
                               rtol=1e-10)


def test_per_axis_errors_follow_the_product_axes():
    """Level aircraft, zero mounting: a pure heading error phi_U is a yaw error (eq. 17) and a
    pure east tilt is a pitch error about x."""
    out = air.run_trials({"mount_psi": 0.0, "mount_theta": 0.0, "mount_gamma": 0.0,
                          "level_sigma": 0.0, "install_bound": 0.0}, np.random.default_rng(1),
                         100)
    np.testing.assert_allclose(out["delta_psi"], -out["heading_error"], atol=1e-15)
    np.testing.assert_allclose(out["delta_theta"], 0.0, atol=1e-15)
    np.testing.assert_allclose(out["delta_gamma"], 0.0, atol=1e-15)
    C_ba = np.eye(3)
    D = metrics.error_matrix(air.computed_mounting(C_ba, np.eye(3), [1e-3, 0, 0]), C_ba)
    psi, theta, gamma = metrics.error_angles(D)
    assert theta == pytest.approx(-1e-3, rel=1e-6)
    assert abs(psi) < 1e-12
    assert abs(gamma) < 1e-12


def test_level_split_readings():
    """'total': each level axis level/sqrt(2); 'per_axis': each axis level."""
    total = air.level_heading_covariance(3.0, 5.0, "total")
    per_axis = air.level_heading_covariance(3.0, 5.0, "per_axis")
    np.testing.assert_allclose(np.diag(total), [12.5, 12.5, 9.0])
    np.testing.assert_allclose(np.diag(per_axis), [25.0, 25.0, 9.0])
    with pytest.raises(InputError, match="level_split"):
        air.level_heading_covariance(3.0, 5.0, "both")


def test_paper_arithmetic_is_the_rss_of_the_inputs():
    """Seed 000, section 2: 1.70 mrad (two decimals) = sqrt(3² + 5²)′; 5.10 = 3 x 1.70 (rounded
    first: 3 x 1.6962 = 5.089 would print as 5.09)."""
    rss = air.rss_of_inputs() / MRAD
    assert round(rss, 2) == 1.70
    assert round(3 * round(rss, 2), 2) == 5.10
    assert round(3 * rss, 2) == 5.09


def test_one_d_from_the_1sigma_inputs():
    """A single D with heading 3′ and one 5′ tilt: phi = RSS; eq. (18) as printed gives phi/2
    and the Table 1 metric about phi/sqrt(2), neither of which is 1.70 mrad."""
    det = air.one_sigma_rotation(1)
    rss = air.rss_of_inputs()
    assert det["rotation_angle"] == pytest.approx(rss, rel=1e-12)
    assert det["eq18_angle"] == pytest.approx(rss / 2, rel=1e-9)
    assert det["table1_angle"] == pytest.approx(rss / np.sqrt(2), rel=1e-6)


def test_rms_rotation_angle_matches_the_sum_of_variances():
    """E[phi²] = sum of the axis variances exactly (no installation error): sigma_U² +
    level² ('total' split). The sample mean of phi² has standard error sqrt(2 sum sigma^4 / n)
    for Gaussian axes; allow 4 of them."""
    n = 40_000
    out = air.run_trials({"install_bound": 0.0}, np.random.default_rng(2), n)
    sig2 = np.diag(air.level_heading_covariance(air.PAPER_HEADING, air.PAPER_LEVEL, "total"))
    se = np.sqrt(2 * np.sum(sig2**2) / n)
    assert abs(np.mean(out["rotation_angle"] ** 2) - sig2.sum()) < 4 * se
    # and the installation error adds its variance, bound²/3 per axis
    out = air.run_trials({}, np.random.default_rng(3), n)
    b = air.PAPER_INSTALL_BOUND
    expect = sig2.sum() + b**2
    se = np.sqrt(2 * np.sum(sig2**2) / n + 3 * (b**4 / 5 - b**4 / 9) / n)
    assert abs(np.mean(out["rotation_angle"] ** 2) - expect) < 4 * se


def test_reproduction_of_1_70_and_5_10_mrad():
    """Acceptance of the air calibration: 1.70 mrad (1σ) and 5.10 mrad (3σ) within 2 %.

    They are reproduced by the rms of the true rotation angle phi (and 3 x rms), level 5′ read
    as the RSS of the two level axes. Tolerance: 2 % (the issue), the standard error of the rms
    at this n is 0.3 %."""
    table = air.reproduce_paper(n=20_000, rng=4)
    pairs = air.consistent_readings(table)
    found = {(r.scenario, r.metric, r.one_sigma) for r in pairs.itertuples()}
    assert ("rss", "rotation_angle", "rms") in found
    row = pairs[(pairs.scenario == "rss") & (pairs.metric == "rotation_angle")].iloc[0]
    assert abs(row.one_sigma_dev) < 0.02 and abs(row.three_sigma_dev) < 0.02
    # eq. (18) as printed and the Table 1 metric never reach 1.70 under any reading
    assert not pairs.metric.isin(["eq18_angle", "table1_angle"]).any()
    # the 99.73rd percentile of phi is far below 5.10 mrad under the reproducing reading
    p997 = table.query("scenario == 'rss' and metric == 'rotation_angle' "
                       "and statistic == 'p99.7'").value_mrad.iloc[0]
    assert p997 < 0.8 * 5.10


def test_run_trials_contract():
    out = air.run_trials({}, np.random.default_rng(7), 64)
    assert set(out) == {m.name for m in AIR.metrics_}
    for v in out.values():
        assert v.shape == (64,) and v.dtype == np.float64 and np.isfinite(v).all()
    again = air.run_trials({}, np.random.default_rng(7), 64)
    for k in out:
        np.testing.assert_array_equal(out[k], again[k])
    assert set(air.DEFAULT_PARAMS) >= {"ta_source", "gyro_drift", "accel_bias", "install_bound"}


def test_table2_source_equals_the_sigmas_of_its_row():
    row = t2.TABLE2_ROWS[0]
    a = air.run_trials({"ta_source": "table2", "gyro_drift": row.gyro_drift,
                        "accel_bias": row.accel_bias}, np.random.default_rng(8), 50)
    b = air.run_trials({"heading_sigma": 13 * ARCMIN, "level_sigma": 20 * ARCMIN},
                       np.random.default_rng(8), 50)
    np.testing.assert_allclose(a["rotation_angle"], b["rotation_angle"], rtol=1e-12)


def test_kalman_source_draws_from_the_filter_covariance():
    """Heading error rms of the draws against the filter's sigma_U (chi-square 99.9 %)."""
    from scipy import stats
    n = 2000
    params = {"ta_source": "kalman", "gyro_drift": 0.05 * units.DEG_PER_HOUR,
              "accel_bias": 5e-4 * units.G0}
    out = air.run_trials(params, np.random.default_rng(9), n)
    _, P = air.transfer_alignment_moments({**air.DEFAULT_PARAMS, **params})
    ratio = np.mean(out["heading_error"] ** 2) / P[2, 2]
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], n) / n
    assert lo < ratio < hi


@pytest.mark.parametrize("params, match", [
    ({"nonsense": 1.0}, "nonsense"),
    ({"ta_source": "guess"}, "ta_source"),
    ({"ta_source": "table2", "gyro_drift": 1e-6}, "not a Table 2 grade"),
    ({"level_split": "half"}, "level_split"),
    ({"install_bound": -1e-4}, "install_bound"),
    ({"heading_sigma": float("nan")}, "heading_sigma"),
])
def test_bad_params_raise_input_error(params, match):
    with pytest.raises(InputError, match=match):
        air.run_trials(params, np.random.default_rng(0), 3)


def test_level_error_combines_east_with_north():
    """``level_error`` is the tilt of the slave's level plane, ``hypot(φ_E, φ_N)``, never a
    combination with the heading axis φ_U.

    By hand, with no installation or master error the error matrix D is the rotation φ_ta
    turned into product axes, so its angle is ``|φ_ta|``: per trial
    ``level² + heading² = φ_E² + φ_N² + φ_U² = rotation_angle²`` (``hypot(φ_E, φ_U)`` would
    give ``φ_E² + 2 φ_U²``). Limits: heading alone (level 0) gives a level error of exactly 0;
    level alone (heading 0) gives ``level_error = rotation_angle``. Spread: level 5′ read as the
    RSS of two axes of 5′/√2 has ``E[level²] = 25 arcmin²``; ``Σ level²/(12.5 arcmin²)`` is
    χ² with 2n degrees of freedom.
    """
    from scipy import stats
    n = 4000
    base = {"install_bound": 0.0, "mount_psi": 0.7, "mount_theta": -0.4, "mount_gamma": 1.1}
    out = air.run_trials(base, np.random.default_rng(24), n)
    np.testing.assert_allclose(out["level_error"] ** 2 + out["heading_error"] ** 2,
                               out["rotation_angle"] ** 2, rtol=1e-7)
    heading_only = air.run_trials({**base, "level_sigma": 0.0}, np.random.default_rng(25), n)
    np.testing.assert_array_equal(heading_only["level_error"], 0.0)
    assert np.all(heading_only["rotation_angle"] > 0.0)
    level_only = air.run_trials({**base, "heading_sigma": 0.0}, np.random.default_rng(26), n)
    np.testing.assert_allclose(level_only["level_error"], level_only["rotation_angle"],
                               rtol=1e-7)
    per_axis_var = (5.0 * ARCMIN) ** 2 / 2.0
    lo, hi = stats.chi2.ppf([1e-6, 1.0 - 1e-6], 2 * n)
    assert lo < np.sum(out["level_error"] ** 2) / per_axis_var < hi


def test_the_master_error_is_shared_by_default():
    """By default the slave inherits the whole master error (shared = 1), so it cancels:
    eq. (19) returns the true mounting exactly."""
    C_ba, C_gbf = mounting_matrix(*ANGLES), _random_passive(5)
    phi_m = np.array([2e-3, -1e-3, 3e-3])
    C_bc = air.computed_mounting(C_ba, C_gbf, np.zeros(3), np.zeros(3), phi_m)
    np.testing.assert_allclose(C_bc, np.broadcast_to(C_ba, C_bc.shape), atol=1e-14)


def test_run_trials_draws_an_unshared_master_error_per_trial():
    """Master heading error 2′ alone, not shared (0), no other error: each trial's rotation
    angle is the magnitude of its own master draw, so the angles differ between trials and
    Σφ²/(2′)² is χ² with n dof."""
    from scipy import stats
    n = 2000
    out = air.run_trials({"heading_sigma": 0.0, "level_sigma": 0.0, "install_bound": 0.0,
                          "master_heading_sigma": 2 * ARCMIN, "master_error_shared": 0.0},
                         np.random.default_rng(31), n)
    assert np.unique(out["rotation_angle"]).size == n
    lo, hi = stats.chi2.ppf([1e-6, 1 - 1e-6], n)
    assert lo < np.sum(out["rotation_angle"] ** 2) / (2 * ARCMIN) ** 2 < hi


def test_table2_rows_are_matched_to_one_part_in_a_million():
    """A grade 5e-6 off a Table 2 row (in either figure) or 2 % off the gyro drift (5e-9 rad/s,
    below numpy's default absolute tolerance) is not a Table 2 grade; the message lists the
    five grades."""
    row = t2.TABLE2_ROWS[2]
    assert air.table2_row(row.gyro_drift * (1 + 5e-7), row.accel_bias) == row
    for drift, bias in ((row.gyro_drift * (1 + 5e-6), row.accel_bias),
                        (row.gyro_drift, row.accel_bias * (1 + 5e-6)),
                        (row.gyro_drift * 1.02, row.accel_bias),
                        (row.gyro_drift, 3.0 * row.accel_bias)):
        with pytest.raises(InputError, match=r"\(0\.05 °/h, 0\.0005 g\), \(0\.05 °/h, 0\.0001 g\)"):
            air.table2_row(drift, bias)


def test_unknown_parameters_are_all_named():
    with pytest.raises(InputError, match=r"parameter\(s\): heading, levle$"):
        air.run_trials({"levle": 1.0, "heading": 2.0}, np.random.default_rng(0), 1)


def test_summaries_rss_and_single_rotations_by_hand():
    """summarise of 0, 1, ..., 10000: rms sqrt(mean k²) = 5773.79, p68 = 6827, p99.7 = 9973
    (linear interpolation); rss of 3, 4, 12 is 13; one D with level 5′ on each of two axes
    and heading 3′ has φ = sqrt(3² + 5² + 5²)′ = 7.681′ (the default is one level axis:
    sqrt(34)′)."""
    s = air.summarise(np.arange(10001.0))
    assert s["p68"] == pytest.approx(6827.0, abs=1e-9)
    assert s["p99.7"] == pytest.approx(9973.0, abs=1e-9)
    assert s["rms"] == pytest.approx(np.sqrt(np.mean(np.arange(10001.0) ** 2)), rel=1e-12)
    assert s["3rms"] == pytest.approx(3 * s["rms"], rel=1e-12)
    assert air.rss_of_inputs(3.0, 4.0, 12.0) == pytest.approx(13.0, rel=1e-15)
    assert air.one_sigma_rotation(2)["rotation_angle"] == pytest.approx(
        np.sqrt(59.0) * ARCMIN, rel=1e-9)
    assert air.one_sigma_rotation()["rotation_angle"] == pytest.approx(np.sqrt(34.0) * ARCMIN,
                                                                       rel=1e-9)


def test_reproduction_table_columns_units_and_seeding():
    """The table's columns; values in mrad (the rms rotation angle of the RSS reading is near
    1.70 mrad, 2 % at 4000 trials covers its 0.9 % standard error several times); the paper's
    figures 1.70 mrad beside rms and p68, 5.10 beside p99.7 and 3rms; an integer seed and a
    Generator seeded alike give one table; the consistent readings carry the table's values,
    and an empty selection still has its columns."""
    table = air.reproduce_paper(n=4000, rng=5)
    assert list(table.columns) == ["scenario", "description", "metric", "statistic",
                                   "value_mrad", "paper_mrad", "deviation", "trials"]
    assert (table.trials == 4000).all()
    rms = table.query("scenario == 'rss' and metric == 'rotation_angle' and statistic == 'rms'")
    assert rms.value_mrad.iloc[0] == pytest.approx(1.70, rel=0.02)
    assert set(table.paper_mrad.dropna().round(2)) == {1.70, 5.10}
    assert list(table.scenario.unique()) == list(air.SCENARIOS)
    again = air.reproduce_paper(n=300, rng=np.random.default_rng(5).integers(2**63))
    other = air.reproduce_paper(n=300, rng=np.random.default_rng(5))
    pd.testing.assert_frame_equal(again, other)
    rot = table[table.metric == "rotation_angle"]
    np.testing.assert_array_equal(rot[rot.statistic.isin(["rms", "p68"])].paper_mrad.round(2),
                                  1.70)
    np.testing.assert_array_equal(rot[rot.statistic.isin(["p99.7", "3rms"])].paper_mrad
                                  .round(2), 5.10)
    columns = ["scenario", "metric", "one_sigma", "one_sigma_mrad", "one_sigma_dev",
               "three_sigma", "three_sigma_mrad", "three_sigma_dev"]
    pairs = air.consistent_readings(table)
    assert list(pairs.columns) == columns and len(pairs) > 0 and not pairs.isna().any().any()
    first = pairs.iloc[0]
    for stat, key in ((first.one_sigma, "one_sigma"), (first.three_sigma, "three_sigma")):
        row = table[(table.scenario == first.scenario) & (table.metric == first.metric)
                    & (table.statistic == stat)].iloc[0]
        assert first[f"{key}_mrad"] == row.value_mrad and first[f"{key}_dev"] == row.deviation
    assert list(air.consistent_readings(table, tolerance=0.0).columns) == columns
    close = air.matches(table)  # the default tolerance is 2 %
    assert (close.deviation.abs() <= 0.02).all() and rms.index[0] in close.index
    assert len(air.matches(table, 0.0)) == 0
