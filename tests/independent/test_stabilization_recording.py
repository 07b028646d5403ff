"""Self-checks of the independent seed 001 simulator against analytic references."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from montecarlo.io.stabilization_csv import CSV_COLUMNS as PROJECT_COLUMNS
from montecarlo.io.stabilization_csv import read_csv

from .stabilization_recording import (
    ARCMIN,
    CSV_COLUMNS,
    DEFAULT_ROCKING,
    DEG_PER_H,
    DEG_PER_SQRT_H,
    body_rate,
    camera_dcm,
    carrier_attitude,
    main,
    rot,
    simulate_recording,
    write_csv,
)

QUIET = {"gyro_bias_deg_h": (0.0, 0.0, 0.0), "gyro_arw": 0.0, "image_noise_px": 0.0,
         "encoder_lsb_rad": None}
K = np.array([1280, 960]) / (2.0 * np.tan(np.radians([4.0, 3.0]) / 2.0))
"""Focal lengths [px/rad] of the default camera."""


def _passive(axes: str, angles) -> np.ndarray:
    """Product R_a1(x1) R_a2(x2) ... of passive rotations, from scipy's active ones."""
    return Rotation.from_euler(axes[::-1].upper(), angles[::-1]).as_matrix().T


def test_rot_matches_scipy_passive_rotations():
    a = np.array([0.3, -1.1, 2.0])
    ours = rot("y", a[0]) @ rot("x", a[1]) @ rot("z", a[2])
    np.testing.assert_allclose(ours, _passive("yxz", a), atol=1e-15)


def _loop_bound(duration: float, rate: float) -> float:
    """Bound [rad] of the gimbal loop's error with the default rocking (its midpoint step).

    Per step the rate changes by ~h Ω' while the angles change by ~h Ω: a local error
    ~h³ Ω Ω'/12, over T/h steps T h² Ω Ω'/12 at most (Ω, Ω' bound the rate and its derivative).
    """
    terms = [(np.radians(a), 2 * np.pi * f) for axis in DEFAULT_ROCKING for a, f, _ in axis]
    omega = sum(a * w for a, w in terms)
    omega_dot = sum(a * w**2 for a, w in terms)
    return duration * rate**-2 * omega * omega_dot / 12.0


@pytest.mark.parametrize("sampling", ["point", "interval-mean"])
def test_target_stays_still_without_errors(sampling):
    """No installation angle, bias or noise: eq. (4) holds the LOS, so a centred target stays put.

    What remains is the loop's error (``_loop_bound``); being second order, halving h divides it
    by ~4 (an error that does not shrink so would be a modelling fault, not the step).
    """
    duration = 30.0
    errors = []
    for rate in (100.0, 200.0):
        rec = simulate_recording(delta_g_arcmin=(0, 0, 0), delta_p_arcmin=(0, 0, 0),
                                 mount="patent", gyro_sampling=sampling, duration_s=duration,
                                 rate_hz=rate, **QUIET)
        bound = _loop_bound(duration, rate)
        assert np.abs(rec.los_error_rad).max() < bound
        assert np.abs(rec.los_px).max() < bound * K.max()
        errors.append(np.abs(rec.los_px).max())
    assert 3.0 < errors[0] / errors[1] < 5.0


def test_off_centre_target_turns_about_the_image_centre():
    """The two-axis gimbal leaves the roll about the LOS free: an off-centre target keeps its
    distance from the centre (in normalised coordinates) while it turns about it."""
    rec = simulate_recording(delta_g_arcmin=(0, 0, 0), delta_p_arcmin=(0, 0, 0), mount="patent",
                             gyro_sampling="interval-mean", target_offset_px=(200.0, -150.0),
                             duration_s=20.0, **QUIET)
    xz = rec.los_px / K
    radius = np.hypot(*xz.T)
    np.testing.assert_allclose(radius, radius[0], rtol=0, atol=_loop_bound(20.0, 100.0))
    turn = np.unwrap(np.arctan2(xz[:, 1], xz[:, 0]))
    assert np.ptp(turn) > np.radians(1.0)


@pytest.mark.parametrize("sampling", ["point", "interval-mean"])
def test_gyro_columns_are_the_exact_rate_through_the_imu(sampling):
    """Row k = C_b^g ω + bias with ω the rate at t_k, or its exact mean over (t_k - h, t_k] from
    the antiderivative of each sinusoid A 2πf cos(2πft + φ), A sin(2πft + φ)."""
    dg, bias, h = np.array([7.0, -5.0, 11.0]), np.array([3.0, -2.0, 1.0]), 0.01
    rec = simulate_recording(delta_g_arcmin=dg, delta_p_arcmin=(0, 0, 0), mount="patent",
                             gyro_sampling=sampling, duration_s=5.0,
                             **{**QUIET, "gyro_bias_deg_h": bias})
    t = rec.t_s
    omega = np.zeros((len(t), 3))
    for axis, terms in enumerate(DEFAULT_ROCKING):
        for a, f, phase in terms:
            w = 2 * np.pi * f
            if sampling == "point":
                omega[:, axis] += np.radians(a) * w * np.cos(w * t + phase)
            else:
                omega[:, axis] += np.radians(a) * (np.sin(w * t + phase)
                                                   - np.sin(w * (t - h) + phase)) / h
    expected = omega @ _passive("yxz", dg[[1, 0, 2]] * ARCMIN).T + bias * DEG_PER_H
    np.testing.assert_allclose(rec.gyro, expected, rtol=0, atol=1e-13)


def test_mounts_coincide_while_the_gimbal_pitch_stays_zero():
    """With ε ≡ 0, R_x(ε + δpx) = R_x(δpx) and R_z(η + δpz) = R_z(δpz) R_z(η): both mounts are
    R_y(δpy) R_x(δpx) R_z(δpz) R_z(η). Eq. (4) keeps ε at 0 when the IMU's x and y rates vanish:
    yaw-only rocking, δgx = δgy = 0, no x, y bias or noise. Once ε moves, they differ."""
    yaw_only = ((), (), ((2.0, 0.11, 1.2), (0.8, 0.61, 0.0)))
    common = {"delta_g_arcmin": (0, 0, 7.0), "delta_p_arcmin": (5.0, -3.0, 9.0),
              "gyro_sampling": "interval-mean", "aim_deg": (20.0, 0.0), "duration_s": 20.0,
              "gyro_bias_deg_h": (0.0, 0.0, 40.0), "gyro_arw": 0.0,
              "image_noise_px": 0.3, "rocking_deg": yaw_only}
    patent, inner = (simulate_recording(mount=m, rng=np.random.default_rng(5), **common)
                     for m in ("patent", "inner-gimbal"))
    assert np.all(patent.eps_rad == 0.0)
    assert np.abs(patent.los_true_px).max() > 5.0
    np.testing.assert_allclose(patent.columns(), inner.columns(), rtol=0, atol=1e-9)
    moving = {**common, "rocking_deg": DEFAULT_ROCKING, "aim_deg": (10.0, 15.0)}
    patent, inner = (simulate_recording(mount=m, rng=np.random.default_rng(5), **moving)
                     for m in ("patent", "inner-gimbal"))
    assert np.abs(patent.los_true_px - inner.los_true_px).max() > 0.5


@pytest.mark.parametrize("mount", ["patent", "inner-gimbal"])
def test_camera_yaw_error_moves_image_by_pinhole_amount(mount):
    """Roll γ(t) = A sin(2πft) only, gimbal at (0, 0): the gimbal holds still and the camera, turned
    left by δpz = d, rolls about the carrier y axis. The target, the LOS at t = 0, is then at
    u = R_z(d) R_y(γ) (-sin d, cos d, 0): x = k_x sd cd (1 - cγ)/D, z = -k_z sγ sd/D,
    D = sd² cγ + cd². Rolling right wing down lifts the LOS: the target goes down."""
    amp, freq, d = 3.0, 0.2, 30.0 * ARCMIN
    rec = simulate_recording(delta_g_arcmin=(0, 0, 0), delta_p_arcmin=(0, 0, 30.0), mount=mount,
                             gyro_sampling="point", aim_deg=(0.0, 0.0), duration_s=10.0,
                             rocking_deg=((), ((amp, freq, 0.0),), ()), **QUIET)
    gamma = np.radians(amp) * np.sin(2 * np.pi * freq * rec.t_s)
    sd, cd, sg, cg = np.sin(d), np.cos(d), np.sin(gamma), np.cos(gamma)
    den = sd**2 * cg + cd**2
    expected = np.column_stack([K[0] * sd * cd * (1 - cg) / den, -K[1] * sg * sd / den])
    np.testing.assert_allclose(rec.los_px, expected, rtol=0, atol=1e-5)
    big = np.abs(gamma) > np.radians(1.0)
    assert np.all(np.sign(rec.los_px[big, 1]) == -np.sign(gamma[big]))
    assert np.abs(rec.los_px[:, 1]).max() > 0.9 * K[1] * np.radians(amp) * d


def _first_order_camera_rate(mount, eta, eps, w, dg, dp):
    """Camera rate about its x (LOS up) and z (LOS left) axes [rad/s], first order in dg, dp [rad].

    Gimbal part: eq. (6) with X = (0, δgx, δgy, -δgz). Camera part, with ρ = (-sη ωx + cη ωy)/cε
    the gimbal's free roll rate about the LOS: ``patent`` adds δpz (H_1,4, H_2,4) and -δpx ρ on z;
    ``inner-gimbal`` (C_b^c = (I - [δp×]) C_b^p) adds δpz ρ on x and -δpx ρ on z.
    """
    se, ce, sp, cp = np.sin(eta), np.cos(eta), np.sin(eps), np.cos(eps)
    wx, wy, wz = w.T
    h1 = np.stack([-se * wz, ce * wz, ce * wy - se * wx], 1)
    h2 = np.stack([sp * ce * wz + cp * wy, -cp * wx + sp * se * wz, sp * ce * wx + sp * se * wy], 1)
    x_g = np.array([dg[0], dg[1], -dg[2]])
    rho = (-se * wx + ce * wy) / cp
    if mount == "patent":
        return h1 @ x_g + dp[2] * h1[:, 2], h2 @ x_g + dp[2] * h2[:, 2] - dp[0] * rho
    return h1 @ x_g + dp[2] * rho, h2 @ x_g - dp[0] * rho


@pytest.mark.parametrize("mount", ["patent", "inner-gimbal"])
def test_camera_rate_follows_the_first_order_model(mount):
    """Small installation angles: the camera's inertial rate (finite differences of C_n^c, from
    ``-dC C^T = [ω×]``) matches the first-order model to 1 % (second-order terms are ~|δ| ~ 0.3 %
    of it). The patent's printed H_2,1 = cε sη ωx - cε cη ωy - sε ωz lacks -sε η̇ (eq. (2) with
    the loop's η̇) and misses by far more."""
    dg, dp = np.array([6.0, -4.0, 3.0]) * ARCMIN, np.array([-5.0, 2.0, 8.0]) * ARCMIN
    rec = simulate_recording(delta_g_arcmin=dg / ARCMIN, delta_p_arcmin=dp / ARCMIN, mount=mount,
                             gyro_sampling="interval-mean", duration_s=20.0, **QUIET)
    t = rec.t_s
    w = body_rate(t, DEFAULT_ROCKING)
    c = camera_dcm(rec.eta_rad, rec.eps_rad, dp, mount) @ carrier_attitude(
        t, lambda tau: body_rate(tau, DEFAULT_ROCKING))
    skew = -np.gradient(c, t, axis=0) @ c.transpose(0, 2, 1)
    measured = (skew[5:-5, 2, 1], skew[5:-5, 1, 0])
    model = _first_order_camera_rate(mount, rec.eta_rad, rec.eps_rad, w, dg, dp)
    for m, f in zip(measured, model, strict=True):
        assert np.std(m - f[5:-5]) < 0.01 * np.std(f[5:-5])
    if mount == "patent":
        se, ce, sp, cp = (np.sin(rec.eta_rad), np.cos(rec.eta_rad), np.sin(rec.eps_rad),
                          np.cos(rec.eps_rad))
        printed = model[1] + dp[0] * ((se * w[:, 0] - ce * w[:, 1]) * (cp - 1 / cp) - sp * w[:, 2])
        assert np.std(measured[1] - printed[5:-5]) > 0.05 * np.std(model[1][5:-5])


def test_noise_has_its_stated_size():
    """Gyro noise std N/√h per row and image noise std; 5σ bands of a sample std, 1/√(2n)."""
    kw = {"delta_g_arcmin": (0, 0, 0), "delta_p_arcmin": (0, 0, 0), "mount": "patent",
          "gyro_sampling": "point", "duration_s": 20.0, "encoder_lsb_rad": None,
          "gyro_bias_deg_h": (0.0, 0.0, 0.0)}
    clean = simulate_recording(**{**kw, "gyro_arw": 0.0, "image_noise_px": 0.0})
    noisy = simulate_recording(**{**kw, "gyro_arw": 0.05, "image_noise_px": 0.4},
                               rng=np.random.default_rng(11))
    gyro_noise = (noisy.gyro - clean.gyro) / (0.05 * DEG_PER_SQRT_H / np.sqrt(0.01))
    image_noise = (noisy.los_px - noisy.los_true_px) / 0.4
    for z in (gyro_noise, image_noise):
        assert abs(z.std() - 1.0) < 5.0 / np.sqrt(2.0 * z.size)
        assert abs(z.mean()) < 5.0 / np.sqrt(z.size)


def test_encoders_report_the_nearest_step():
    lsb = 2 * np.pi / 2**20
    kw = {"delta_g_arcmin": (3, 2, 1), "delta_p_arcmin": (0, 0, 0), "mount": "patent",
          "gyro_sampling": "point", "duration_s": 10.0}
    exact = simulate_recording(**kw, encoder_lsb_rad=None, rng=np.random.default_rng(2))
    coded = simulate_recording(**kw, encoder_lsb_rad=lsb, rng=np.random.default_rng(2))
    for a, b in ((exact.eta_rad, coded.eta_rad), (exact.eps_rad, coded.eps_rad)):
        np.testing.assert_allclose(b / lsb, np.round(b / lsb), rtol=0, atol=1e-6)
        assert np.abs(a - b).max() <= 0.5 * lsb * (1 + 1e-9)
        assert np.abs(a - b).max() > 0.3 * lsb


def test_csv_is_read_back_by_the_project_reader(tmp_path):
    assert CSV_COLUMNS == PROJECT_COLUMNS
    rec = simulate_recording(delta_g_arcmin=(4, -3, 2), delta_p_arcmin=(-5, 1, 6),
                             mount="inner-gimbal", gyro_sampling="interval-mean",
                             target_offset_px=(120.0, 80.0), duration_s=2.0,
                             rng=np.random.default_rng(3))
    write_csv(tmp_path / "run.csv", rec)
    back = read_csv(tmp_path / "run.csv")
    np.testing.assert_array_equal(
        np.column_stack([back.t, back.gyro, back.eta, back.eps, back.los_px]), rec.columns())
    assert list(tmp_path.iterdir()) == [tmp_path / "run.csv"]


def test_cli_writes_a_run_and_refuses_an_impossible_one(tmp_path, capsys):
    out = tmp_path / "run.csv"
    assert main([str(out), "--seed", "4", "--duration-s", "2", "--mount", "inner-gimbal"]) == 0
    assert len(read_csv(out).t) == 200
    assert "dz=5" in capsys.readouterr().out
    bad = tmp_path / "bad.csv"
    assert main([str(bad), "--aim-deg", "0", "89.5", "--duration-s", "2"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "gimbal pitch" in err
    assert not bad.exists()
    with pytest.raises(SystemExit) as exit_info:
        main([str(bad), "--mount", "turret"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'turret'" in err
