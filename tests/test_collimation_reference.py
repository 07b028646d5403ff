"""Seed 003's measuring procedure: readings relative to the reference the INS sets up itself."""

import json
import math

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from montecarlo.cli import main
from montecarlo.seed003 import procedure as pr
from montecarlo.seed003 import reference as ref
from montecarlo.seed003.model import Noise
from montecarlo.units import ARCSEC

A = ARCSEC
rng = np.random.default_rng(33)
AZ, EL, SETS = pr.procedure_layout()


def _unit(az, el):
    return np.array([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)])


def _scipy_attitude(gamma, lam, az, el, roll):
    """Attitude (scipy, Z-X-Y with yaw = -heading) at roll ``roll`` turning the optical axis onto
    the mirror normal, solved numerically (independent of the module's closed form)."""
    u, w = _unit(gamma, lam), _unit(az, el)

    def miss(x):
        return Rotation.from_euler("ZXY", [-x[0], x[1], roll]).apply(u) - w

    x = least_squares(miss, [az, el], xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    return Rotation.from_euler("ZXY", [-x[0], x[1], roll])


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_relative_readings_agree_with_an_independent_construction(side):
    """Attitudes solved numerically with scipy; the reference frame by Gram-Schmidt written out;
    the reading as scipy's Z-X-Y decomposition of R^T C_k."""
    local = np.random.default_rng(4)
    for _ in range(10):
        gamma, lam = local.uniform(-0.01, 0.01, 2)
        rolls = local.normal(0, 0.03, 3)
        az_c = local.uniform(-1, 1)
        k_az, k_el = local.uniform(-1.2, 1.2), local.uniform(-1.0, 1.0)
        C_c = _scipy_attitude(gamma, lam, az_c, 0.0, rolls[0]).as_matrix()
        C_r = _scipy_attitude(gamma, lam, az_c + side * math.pi / 2, 0.0, rolls[1]).as_matrix()
        C_k = _scipy_attitude(gamma, lam, k_az, k_el, rolls[2]).as_matrix()
        y = C_c[:, 1]
        x = C_r[:, 1] - (C_r[:, 1] @ y) * y
        x = side * x / np.linalg.norm(x)
        C_R = np.column_stack([x, y, np.cross(x, y)])
        yaw, pitch, roll = Rotation.from_matrix(C_R.T @ C_k).as_euler("ZXY")
        h, p, r = ref.relative_readings(gamma, lam, k_az, k_el, rolls[2],
                                        (az_c, 0.0, rolls[0]),
                                        (az_c + side * math.pi / 2, 0.0, rolls[1]), side)
        assert ref.wrap(h + yaw) == pytest.approx(0.0, abs=1e-9)
        assert p == pytest.approx(pitch, abs=1e-9)
        assert r == pytest.approx(roll, abs=1e-9)


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_reference_reading_errors_build_the_frame_from_the_axes_read(side):
    """The INS reads its heading and pitch at the central and the roll mirror with errors e; its
    frame is built from the attitudes it read there (scipy's Z-X-Y with those errors added to
    heading and pitch), the measured mirror's attitude is the true one. A heading error at C
    alone turns the frame about the (near-vertical) z axis: every relative heading by -e_h."""
    local = np.random.default_rng(8)
    for _ in range(6):
        gamma, lam = local.uniform(-0.01, 0.01, 2)
        rolls = local.normal(0, 0.03, 3)
        e = local.normal(0, 20 * A, 4)
        k_az, k_el = local.uniform(-1.2, 1.2), local.uniform(-1.0, 1.0)
        axes = []
        for j, az in enumerate((0.3, 0.3 + side * math.pi / 2)):
            yaw, pitch, roll = _scipy_attitude(gamma, lam, az, 0.0, rolls[j]).as_euler("ZXY")
            read = Rotation.from_euler("ZXY", [yaw - e[2 * j], pitch + e[2 * j + 1], roll])
            axes.append(read.as_matrix()[:, 1])
        y = axes[0]
        x = axes[1] - (axes[1] @ y) * y
        x = side * x / np.linalg.norm(x)
        C_R = np.column_stack([x, y, np.cross(x, y)])
        C_k = _scipy_attitude(gamma, lam, k_az, k_el, rolls[2]).as_matrix()
        yaw, pitch, roll = Rotation.from_matrix(C_R.T @ C_k).as_euler("ZXY")
        args = (gamma, lam, k_az, k_el, rolls[2], (0.3, 0.0, rolls[0]),
                (0.3 + side * math.pi / 2, 0.0, rolls[1]), side)
        h, p, r = ref.relative_readings(*args, reference_error=e)
        assert ref.wrap(h + yaw) == pytest.approx(0.0, abs=1e-9)
        assert p == pytest.approx(pitch, abs=1e-9)
        assert r == pytest.approx(roll, abs=1e-9)
        h0, _, _ = ref.relative_readings(*args)
        h1, _, _ = ref.relative_readings(*args, reference_error=[e[0], 0.0, 0.0, 0.0])
        assert ref.wrap(h1 - h0) == pytest.approx(-e[0], rel=0.1)


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_reference_reading_errors_to_first_order(side):
    """No offsets, level mount, horizontal mirrors at alpha = az - az_c: an error e read at C or
    R moves the readings by heading -e_hC, pitch -e_pC cos(alpha) - s e_pR sin(alpha)
    (docs/reference/collimation.md, "The reference's own errors"); e_hR moves nothing to first
    order (the
    roll mirror only sets the frame's x direction about y_R). Differences over 1e-7 rad."""
    az, el, az_c, step = np.array([-0.5, 0.2, 0.8, 2.0]), np.zeros(4), 0.1, 1e-7
    alpha = az - az_c
    args = (0.0, 0.0, az, el, 0.0, (az_c, 0.0, 0.0), (az_c + side * math.pi / 2, 0.0, 0.0), side)
    h0, p0, _ = ref.relative_readings(*args)
    want = {0: (-np.ones(4), np.zeros(4)), 1: (np.zeros(4), -np.cos(alpha)),
            2: (np.zeros(4), np.zeros(4)), 3: (np.zeros(4), -side * np.sin(alpha))}
    for j, (dh, dp) in want.items():
        e = np.zeros(4)
        e[j] = step
        h, p, _ = ref.relative_readings(*args, reference_error=e)
        np.testing.assert_allclose(ref.wrap(h - h0) / step, dh, atol=1e-6)
        np.testing.assert_allclose((p - p0) / step, dp, atol=1e-6)


def test_reference_mirrors_read_zero_and_frame_is_a_rotation():
    """At the central mirror the reading is heading 0, pitch 0; at the roll mirror pitch 0."""
    gamma, lam = 300 * A, -200 * A
    rolls = rng.normal(0, 0.02, 2)
    center, mirror = (0.2, 0.0, rolls[0]), (0.2 + math.pi / 2, 0.0, rolls[1])
    h, p, _ = ref.relative_readings(gamma, lam, np.array([0.2, 0.2 + math.pi / 2]), np.zeros(2),
                                    rolls, center, mirror)
    np.testing.assert_allclose([h[0], p[0], p[1]], 0.0, atol=1e-14)
    C_R = ref.reference_frame(ref.attitude_at(gamma, lam, *center),
                              ref.attitude_at(gamma, lam, *mirror))
    np.testing.assert_allclose(C_R.T @ C_R, np.eye(3), atol=1e-15)
    assert np.linalg.det(C_R) == pytest.approx(1.0, abs=1e-14)


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_first_order_form_is_exact_to_second_order(side):
    """Error of the first-order form shrinks 4x when the offsets are halved (rolls exact)."""
    rolls = rng.normal(0, 0.02, AZ.size)
    rc, rr = 0.015, -0.01
    errors = []
    for scale in (1.0, 0.5):
        gamma, lam = 200 * A * scale, -150 * A * scale
        exact = ref.relative_readings(gamma, lam, AZ, EL, rolls, (0.0, 0.0, rc),
                                      (side * math.pi / 2, 0.0, rr), side)[:2]
        approx = ref.first_order_readings(gamma, lam, AZ, EL, rolls, 0.0, rc, rr, side)
        errors.append(max(np.abs(ref.wrap(exact[0] - approx[0])).max(),
                          np.abs(exact[1] - approx[1]).max()))
    assert errors[0] < 0.2 * A  # (offset ~ 1e-3 rad)^2 / 2 ~ 0.1″
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.05)
    # and the first-order signal itself is far larger than its error: lambda does not drop out
    lam_only = ref.first_order_readings(0.0, 200 * A, AZ, EL, side=side)
    assert np.abs(lam_only[1] - EL).max() > 100 * A


def test_relative_from_absolute_is_independent_of_the_frame_heading():
    data = [pr.simulate_procedure(250 * A, 120 * A, AZ, EL, Noise(0, 0, 0, 0, 0.02), 5,
                                  frame_heading=h) for h in (0.0, 2.0)]
    out = []
    for d in data:
        out.append(ref.relative_from_absolute(d.ins_az, d.ins_el, d.ins_roll,
                                              (d.ins_az[0], d.ins_el[0], d.ins_roll[0]),
                                              (d.ins_az[1], d.ins_el[1], d.ins_roll[1])))
    for a, b in zip(*out, strict=True):
        np.testing.assert_allclose(ref.wrap(a - b), 0.0, atol=1e-12)
    rel = pr.simulate_procedure(250 * A, 120 * A, AZ, EL, Noise(0, 0, 0, 0, 0.02), 5,
                                reference_rows=False)
    np.testing.assert_allclose(ref.wrap(out[0][0][2:] - rel.ins_az), 0.0, atol=1e-12)
    np.testing.assert_allclose(out[0][1][2:] - rel.ins_el, 0.0, atol=1e-12)
    np.testing.assert_allclose(out[0][2][2:] - rel.ins_roll, 0.0, atol=1e-12)


def test_relative_roll_input_reproduces_the_absolute_model():
    rolls = rng.normal(0, 0.03, AZ.size)
    center, mirror = (0.0, 0.0, 0.01), (math.pi / 2, 0.0, -0.02)
    h, p, r = ref.relative_readings(300 * A, 100 * A, AZ, EL, rolls, center, mirror)
    h2, p2, _ = ref.relative_readings(300 * A, 100 * A, AZ, EL, r, center, mirror,
                                      roll_is_relative=True)
    np.testing.assert_allclose(ref.wrap(h - h2), 0.0, atol=1e-13)
    np.testing.assert_allclose(p - p2, 0.0, atol=1e-13)


def test_corrected_readings_equal_the_theodolite_without_errors():
    d = pr.simulate_procedure(400 * A, -300 * A, AZ, EL, Noise(0, 0, 0, 0, 0.03), 8)
    h, p, r = ref.relative_from_absolute(d.ins_az, d.ins_el, d.ins_roll,
                                         (d.ins_az[0], d.ins_el[0], d.ins_roll[0]),
                                         (d.ins_az[1], d.ins_el[1], d.ins_roll[1]))
    c_az, c_el = ref.corrected_readings(h[2:], p[2:], r[2:], 400 * A, -300 * A,
                                        (h[0], p[0], r[0]), (h[1], p[1], r[1]))
    t_az, t_el = ref.theodolite_relative(AZ, EL, (0.0, 0.0), (math.pi / 2, 0.0))
    np.testing.assert_allclose(ref.wrap(c_az - t_az), 0.0, atol=1e-12)
    np.testing.assert_allclose(c_el - t_el, 0.0, atol=1e-12)
    np.testing.assert_allclose(ref.wrap(t_az - AZ), 0.0, atol=1e-15)


CASES = [(rows, roll, side) for rows in (True, False) for roll in ("recorded", "level", "free")
         for side in (1.0, -1.0)]


@pytest.mark.parametrize(("rows", "roll", "side"), CASES)
def test_noise_free_fit_recovers_the_offsets(rows, roll, side):
    az, el, _ = pr.procedure_layout(pitches=pr.HIGH_PITCHES)
    mount = 0.0 if roll == "level" else 0.02
    d = pr.simulate_procedure(350 * A, -250 * A, az, el, Noise(0, 0, 0, 0, mount), 2, side=side,
                              frame_heading=1.0, az_center=0.1,
                              reference_rows=rows, with_roll=roll == "recorded")
    f = pr.fit_procedure(d, side=side, free_roll=roll == "free", sigma_ins=2 * A,
                         sigma_theodolite=2 * A)
    # fitted rolls (free, or at the reference pointings of relative rolls) carry a prior:
    # noise-free data are then recovered within the fit's sigma, otherwise exactly
    prior = roll == "free" or (roll == "recorded" and not rows)
    tol = max(f.stderr["axis_az"], f.stderr["axis_el"]) if prior else 1e-4 * A
    assert f.params["axis_az"] == pytest.approx(350 * A, abs=tol)
    assert f.params["axis_el"] == pytest.approx(-250 * A, abs=tol)
    if not rows:
        assert f.params["reference_az"] == pytest.approx(0.1, abs=max(tol, 1e-9))
    if not prior:
        assert np.abs(f.residuals).max() < 1e-6 * A


def test_covariance_matches_the_first_order_design():
    """Relative readings, level mount, theodolite error only (INS error 0): the fit covariance
    and ``predicted_stderr`` equal sigma^2 (X^T X)^-1 of the first-order design in
    (gamma, lambda, az_c)."""
    sigma = 2 * A
    d = pr.simulate_procedure(20 * A, 20 * A, AZ, EL, Noise(0, 0, 0, 0, 0), 1,
                              reference_rows=False, with_roll=False)
    f = pr.fit_procedure(d, sigma_ins=0.0, sigma_theodolite=sigma)
    m = AZ.size
    X = np.zeros((2 * m, 3))
    X[:m, 0] = 1 - 1 / np.cos(EL)
    X[:m, 1] = -np.tan(EL) * np.cos(AZ)
    X[m:, 1] = -1 + np.cos(AZ) + np.sin(AZ)
    X[:m, 2] = -1.0
    # the theodolite angle enters the residual with derivative -1: heading via az, pitch via el
    ref_cov = sigma**2 * np.linalg.inv(X.T @ X)
    np.testing.assert_allclose(f.covariance, ref_cov, rtol=2e-3, atol=2e-3 * ref_cov.max())
    # the predicted standard errors, computed from the layout alone at the fitted offsets
    got = pr.predicted_stderr(d, f, False, 1.0)
    assert list(got) == ["axis_az", "axis_el", "reference_az"]
    np.testing.assert_allclose(list(got.values()), np.sqrt(np.diag(ref_cov)), rtol=2e-3)


def test_free_rolls_leave_the_offset_direction_unobserved():
    """Turning the offset about the INS axis by beta and every roll by -beta leaves the relative
    heading and pitch unchanged (they are INS-axis directions): with all rolls free only the size
    of the offset is observed, its direction comes from the prior on the rolls."""
    gamma, lam, beta = 300 * A, -200 * A, 0.3
    rolls = rng.normal(0, 0.02, AZ.size)
    rc, rr = 0.01, -0.02
    h, p, _ = ref.relative_readings(gamma, lam, AZ, EL, rolls, (0.0, 0.0, rc),
                                    (math.pi / 2, 0.0, rr))
    u = Rotation.from_euler("Y", beta).apply(_unit(gamma, lam))
    g2, l2 = math.atan2(u[0], u[1]), math.asin(u[2])
    h2, p2, _ = ref.relative_readings(g2, l2, AZ, EL, rolls - beta, (0.0, 0.0, rc - beta),
                                      (math.pi / 2, 0.0, rr - beta))
    np.testing.assert_allclose(ref.wrap(h - h2), 0.0, atol=1e-13)
    np.testing.assert_allclose(p - p2, 0.0, atol=1e-13)
    assert abs(g2 - gamma) > 50 * A  # a different offset, the same readings


def test_too_few_or_unseparable_mirrors_raise():
    d = pr.simulate_procedure(300 * A, 300 * A, AZ[:3], EL[:3], Noise(0, 0, 0, 0, 0), 0,
                              reference_rows=False, with_roll=False)
    with pytest.raises(pr.NotDetermined, match="not separable"):
        pr.fit_procedure(d, sigma_ins=2 * A, sigma_theodolite=2 * A)
    d = pr.simulate_procedure(300 * A, 300 * A, AZ[:1], EL[:1], Noise(0, 0, 0, 0, 0), 0,
                              reference_rows=False, with_roll=False)
    with pytest.raises(pr.NotDetermined, match="measured mirrors"):
        pr.fit_procedure(d)


def test_pitch_reach_and_heading_floor():
    """Paper-like layout: gamma is not determined to 15″ and higher pitch mirrors fix it; the
    heading floor of an unrecorded roll is about |lambda| per radian (first-order form)."""
    d = pr.simulate_procedure(100 * A, 400 * A, AZ, EL, Noise(0, 0, 0, 0, 0), 0,
                              reference_rows=False, with_roll=False)
    f = pr.fit_procedure(d, sigma_ins=2 * A, sigma_theodolite=2 * A)
    assert 2 * f.stderr["axis_az"] > pr.CLAIM
    reach = pr.pitch_reach(d, f, np.array([s == "pitch" for s in SETS]), False, 1.0)
    assert math.radians(30) < reach < math.radians(60)
    sims = pr.simulate_procedure(100 * A, 400 * A, AZ, EL * reach / EL.max(), Noise(0, 0, 0, 0, 0),
                                 0, reference_rows=False, with_roll=False)
    se = pr.fit_procedure(sims, sigma_ins=2 * A, sigma_theodolite=2 * A).stderr["axis_az"]
    assert se <= pr.CLAIM / 2 + 1e-3 * A
    floor = pr.heading_floor(d, f)
    # first order: d heading_k / d phi_k = -lambda / cos el, d/d phi_c = +lambda, others small
    first = 400 * A * np.sqrt(np.mean(1 / np.cos(EL) ** 2 + 1))
    assert floor == pytest.approx(first, rel=0.15)


OLD_CSV = """mirror,set,theodolite_az_deg,theodolite_el_deg,ins_az_deg,ins_el_deg,ins_roll_deg
A1,azimuth,0.000272134,-0.001023186,29.915816963,0.033395632,0.001038554
A2,azimuth,22.500198271,-0.000130606,52.416488447,0.033585943,0.148706497
A3,azimuth,45.000058563,-0.000704137,74.916043554,0.032453328,-0.137027530
A4,azimuth,67.499483073,0.000150702,97.415960783,0.032727012,-0.444975536
A5,azimuth,89.999983749,0.000087084,119.917124467,0.033757363,-0.227440272
P1,pitch,0.000386280,11.999896149,29.914064624,12.031764428,-0.495443883
P2,pitch,-0.000746786,23.998601800,29.908781415,24.033881507,0.030034847
P3,pitch,-0.000254231,35.999700726,29.897974580,36.034415620,0.670478316
P4,pitch,-0.001056235,47.999973055,29.874923206,48.032686282,-0.245304080
P5,pitch,-0.000716410,60.000062949,29.832912594,60.034098420,-0.310612818
"""


def test_absolute_readings_give_the_previous_results(tmp_path):
    """``--readings absolute`` on a file of the absolute model: the numbers the fit gave before
    the procedure was added (same file, same command without --readings)."""
    data, out = tmp_path / "old.csv", tmp_path / "fit.json"
    data.write_text(OLD_CSV)
    assert main(["collimation", "fit", str(data), "--readings", "absolute", "--json",
                 str(out)]) == 0
    r = json.loads(out.read_text())
    expected = {"frame_heading": 107995.17181161974, "axis_az": 295.7665989598084,
                "axis_el": -121.45291188447257}
    stderr = {"frame_heading": 3.269667570794533, "axis_az": 2.669262632353943,
              "axis_el": 0.8307763367844244}
    for k in expected:
        # 1e-6 arcsec: the round-off of the iterative fit, which moves with the LAPACK build
        assert r["parameters"][k] == pytest.approx(expected[k], rel=0, abs=1e-6)
        assert r["stderr"][k] == pytest.approx(stderr[k], rel=1e-9)
    assert r["rms_arcsec"]["after"]["all"] == pytest.approx(2.4222814748130665, rel=1e-9)
    assert r["rms_arcsec"]["before"]["all"] == pytest.approx(107.65476732647608, rel=1e-9)
    assert r["chi2"] == pytest.approx(17.00241376880737, rel=1e-9)


@pytest.mark.parametrize(("rows", "expected_dof"), [(True, 2), (False, 1)])
def test_free_roll_dof_counts_the_roll_prior(rows, expected_dof):
    """Hand count, 2 measured mirrors (one azimuth, one pitch), free rolls at all 4 pointings:
    4 readings + 4 prior pseudo-observations - (gamma, lambda [, reference_az] + 4 rolls) =
    2 with reference rows, 1 without. The layout is solvable and must not be refused."""
    az, el, _ = pr.procedure_layout([math.radians(30.0)], [math.radians(20.0)])
    d = pr.simulate_procedure(300 * A, -900 * A, az, el, Noise(A, A, A, A, math.radians(0.5)),
                              4, reference_rows=rows, with_roll=False)
    f = pr.fit_procedure(d, free_roll=True, sigma_ins=A, sigma_theodolite=A, before=False)
    assert f.dof == expected_dof
    assert len(f.names) == (2 if rows else 3) + 4
    assert np.isfinite(f.chi2) and all(np.isfinite(list(f.stderr.values())))


def test_study_hands_the_fit_the_per_reading_ins_sigma(monkeypatch):
    """docs/reference/collimation.md: the procedure's fit takes sigma_INS per heading, pitch and
    roll
    read, not the root-sum-square of heading and pitch (a residual's). With INS heading and
    pitch errors of 3″ each and the theodolite's 2″, the fit must be handed 3″ and 2″, on the
    literal path (trial by trial) and on the block path."""
    from montecarlo.seed003 import batch_fit as bf
    from montecarlo.systems import collimation as sc

    seen = []
    real, real_block = pr.fit_procedure, bf.fit_block

    def spy(data, **kw):
        seen.append((kw["sigma_ins"], kw["sigma_theodolite"]))
        return real(data, **kw)

    def spy_block(data, **kw):
        seen.append((kw["sigma_ins"], kw["sigma_theodolite"]))
        return real_block(data, **kw)

    monkeypatch.setattr(pr, "fit_procedure", spy)
    monkeypatch.setattr(bf, "fit_block", spy_block)
    params = {"procedure": 1, "ins_heading_sigma": 3 * A, "ins_pitch_sigma": 3 * A,
              "ins_roll_sigma": 3 * A, "theodolite_sigma": 2 * A}
    for reference in (True, False):
        seen.clear()
        sc.run_trials(params, np.random.default_rng(0), 1, reference=reference)
        assert seen and seen[0][0] / A == pytest.approx(3.0, rel=1e-12)
        assert seen[0][1] / A == pytest.approx(2.0, rel=1e-12)
