"""Seed 003's batched procedure fit against independent references: noise-free truths, degrees of
freedom counted by hand, column-by-column central differences, scipy's Levenberg-Marquardt and
numpy's matrix inverse, and the literal fit where the batch hands a trial over to it."""

import math

import numpy as np
import pytest
from scipy.optimize import least_squares

from montecarlo.seed003 import batch_fit as bf
from montecarlo.seed003 import procedure as pr
from montecarlo.seed003 import reference as ref
from montecarlo.seed003.model import Noise, attitude_angles, direction, wrap

A = math.radians(1.0 / 3600.0)  # one arc-second [rad]
AZ, EL, _ = pr.procedure_layout()  # 5 azimuth + 5 pitch mirrors: m = 10
GAMMA, LAMBDA = 200 * A, -300 * A


def _block(noise: Noise, n: int = 3, seed: int = 3, **kw) -> bf.BatchData:
    return bf.simulate_block(GAMMA, LAMBDA, AZ, EL, noise, np.random.default_rng(seed), n,
                             frame_heading=0.4, az_center=0.2, **kw)


def test_noise_free_readings_give_the_offsets_back_exactly():
    """Reference rows, rolls recorded, no reading error (mount rolls of 1 deg): the fit is the
    truth (to 1e-12 rad), chi2 = 0, dof = 2m - p = 20 - 2 = 18, the rolls used are the recorded
    ones and the corrected readings meet the theodolite's directions (angle 0)."""
    d = _block(Noise(0, 0, 0, 0, math.radians(1.0)))
    f = bf.fit_block(d, sigma_ins=2 * A, sigma_theodolite=2 * A)
    assert f.names == ("axis_az", "axis_el") and f.dof == 18 and f.roll_recorded
    assert f.ok.all()
    np.testing.assert_allclose(f.values, [[GAMMA, LAMBDA]] * 3, rtol=0, atol=1e-12)
    assert (f.chi2 < 1e-12).all()
    np.testing.assert_allclose(f.residuals, 0.0, atol=1e-12)
    assert f.residuals.shape == (3, 20) and f.covariance.shape == (3, 2, 2)
    np.testing.assert_array_equal(f.rolls, d.ins_roll)
    np.testing.assert_allclose(bf.consistency_angles(d, f), 0.0, atol=1e-12)


def test_level_mount_without_roll_readings_uses_zero_rolls():
    """No roll read, level mount, no error: the truth again, rolls taken as 0 at all 12 rows."""
    d = _block(Noise(0, 0, 0, 0, 0.0), with_roll=False)
    f = bf.fit_block(d, sigma_ins=3 * A, sigma_theodolite=1 * A)
    assert not f.roll_recorded and f.dof == 18
    np.testing.assert_allclose(f.values, [[GAMMA, LAMBDA]] * 3, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(f.rolls, np.zeros((3, 12)))
    np.testing.assert_allclose(bf.consistency_angles(d, f), 0.0, atol=1e-12)
    d = _block(Noise(0, 0, 0, 0, 0.0), with_roll=False, reference_rows=False)
    f = bf.fit_block(d, sigma_ins=3 * A, sigma_theodolite=1 * A)
    assert f.names == ("axis_az", "axis_el", "reference_az") and f.dof == 17  # 20 - 3
    np.testing.assert_allclose(f.values[:, :2], [[GAMMA, LAMBDA]] * 3, rtol=0, atol=1e-12)
    np.testing.assert_allclose(f.values[:, 2], 0.2, rtol=0, atol=1e-12)  # the central azimuth
    np.testing.assert_array_equal(f.rolls, np.zeros((3, 12)))  # 10 mirrors + 2 references
    np.testing.assert_allclose(bf.consistency_angles(d, f), 0.0, atol=1e-12)


@pytest.mark.parametrize("reference_rows", [True, False])
def test_where_the_rolls_come_from_and_the_degrees_of_freedom(reference_rows):
    """Free rolls: one per pointing (12), each with a prior pseudo-observation, so dof = 2m +
    12 - (2 + 12) = 18 with reference rows, 20 + 12 - 15 = 17 without; the rolls are the fitted
    ones. Relative readings with the roll read: the two reference rolls are fitted with their
    prior, dof = 20 + 2 - 5 = 17, the rolls are the 10 recorded then the 2 fitted ones."""
    d = _block(Noise(2 * A, 2 * A, 2 * A, 2 * A, math.radians(1.0)), n=2,
               reference_rows=reference_rows)
    f = bf.fit_block(d, sigma_ins=2 * A, sigma_theodolite=2 * A, free_roll=True)
    core = 2 if reference_rows else 3
    assert f.names[core:] == tuple(f"roll_{i}" for i in range(12))
    assert f.dof == (18 if reference_rows else 17) and not f.roll_recorded and f.ok.all()
    np.testing.assert_array_equal(f.rolls, f.values[:, core:])
    if not reference_rows:
        f = bf.fit_block(d, sigma_ins=2 * A, sigma_theodolite=2 * A)
        assert f.names[3:] == ("roll_center", "roll_mirror") and f.dof == 17
        assert f.roll_recorded
        np.testing.assert_array_equal(f.rolls, np.concatenate([d.ins_roll, f.values[:, 3:]], 1))


def test_too_few_readings_are_refused_with_their_counts():
    d = bf.simulate_block(GAMMA, LAMBDA, [0.3], [0.0], Noise(A, A, A, A), np.random.default_rng(1),
                          2, reference_rows=False)
    with pytest.raises(pr.NotDetermined, match="1 measured mirrors give 2 readings; 3 parameters"):
        bf.fit_block(d, sigma_ins=A, sigma_theodolite=A)


def test_inverse_spd_is_numpys_inverse_and_refuses_an_indefinite_matrix():
    rng = np.random.default_rng(0)
    M = rng.standard_normal((4, 3, 3))
    S = M @ np.swapaxes(M, 1, 2) + 0.1 * np.eye(3)
    np.testing.assert_allclose(bf._inverse_spd(S), np.linalg.inv(S), rtol=1e-10, atol=1e-12)
    with pytest.raises(np.linalg.LinAlgError):
        bf._inverse_spd(np.diag([1.0, -1.0])[None])


def test_levenberg_marquardt_reaches_scipys_minimum_trial_by_trial():
    """y = a exp(b t) + noise, five trials with their own data and starts: each trial's solution
    is scipy's MINPACK one (1e-7 relative), and a linear problem's is its normal equations."""
    rng = np.random.default_rng(4)
    t = np.linspace(0.0, 1.0, 9)
    truth = np.column_stack([rng.uniform(1, 3, 5), rng.uniform(-2, 2, 5)])
    y = truth[:, :1] * np.exp(truth[:, 1:] * t) + 0.05 * rng.standard_normal((5, t.size))

    def fun(x, idx):
        return x[:, :1] * np.exp(x[:, 1:] * t) - y[idx]

    def jac(x, idx):
        e = np.exp(x[:, 1:] * t)
        return np.stack([e, x[:, :1] * t * e], axis=-1)

    x0 = np.column_stack([np.ones(5), np.linspace(-1, 1, 5)])
    got = bf._levenberg_marquardt(fun, jac, x0)
    for i in range(5):
        want = least_squares(lambda x, yi=y[i]: x[0] * np.exp(x[1] * t) - yi, x0[i], method="lm",
                             xtol=1e-15, ftol=1e-15, gtol=1e-15).x
        np.testing.assert_allclose(got[i], want, rtol=1e-7)
    X = np.column_stack([np.ones(t.size), t, t**2])
    lin = bf._levenberg_marquardt(lambda x, idx: x @ X.T - y[idx],
                                  lambda x, idx: np.repeat(X[None], idx.size, axis=0),
                                  np.zeros((5, 3)))
    np.testing.assert_allclose(lin, np.linalg.lstsq(X, y.T, rcond=None)[0].T, rtol=1e-8)


def _marquardt_one_trial(fun, jac, x):
    """The iteration of ``batch_fit._levenberg_marquardt``'s docstring and constants, written
    again for one trial: step ``(A + mu diag A) d = -J'r`` (a zero diagonal entry taken as 1),
    mu from 1e-3, /10 (not below 1e-12) after a step that lowers the cost, x10 after one that
    does not; stop once the largest step component is at most 1e-14, or the decrease the step
    promised, ``-2 g'd - d'Ad``, is at most 1e-10 of the cost, or mu exceeds 1e12. Returns the
    solution, every point at which the residuals were evaluated and the last promised decrease
    over the cost."""
    r = fun(x)
    seen, cost, J, mu = [x.copy()], r @ r, jac(x), 1e-3
    for _ in range(200):
        A, g = J.T @ J, J.T @ r
        diag = np.diag(A)
        d = np.linalg.solve(A + mu * np.diag(np.where(diag > 0, diag, 1.0)), -g)
        predicted = -2.0 * g @ d - d @ A @ d
        r_new = fun(x + d)
        seen.append(x + d)
        if r_new @ r_new < cost:
            x, r, cost = x + d, r_new, r_new @ r_new
            J, mu = jac(x), max(mu / 10.0, 1e-12)
        else:
            mu *= 10.0
        if np.max(np.abs(d)) <= 1e-14 or predicted <= 1e-10 * cost or mu > 1e12:
            break
    return x, seen, predicted / cost


def test_levenberg_marquardt_takes_marquardts_steps_trial_by_trial():
    """y = a exp(b t) + noise for five trials whose residuals are scaled by 1, 0.01, 100, 1, 1
    (diagonals of J'J below and above 1), from starts far enough to have steps rejected, and a
    sixth trial with noise 1e-12 started near its truth (it stops while others go on, on the
    step size: its steps fall below 1e-14 before the promised decrease falls below 1e-10 of its
    cost, about 4e-24), and a seventh with noise 1 (a large residual: the iteration converges
    linearly, and stops on a promised decrease of 0.95e-10 of its cost, within a factor 2 of the
    rule's 1e-10); a third parameter enters no residual (a zero column, a zero diagonal
    entry). Each trial of the batch evaluates the residuals at the same points, in the
    same number, as the iteration written again here for that trial alone (to rounding, 1e-9
    relative)."""
    rng = np.random.default_rng(4)
    t = np.linspace(0.0, 1.0, 9)
    truth = np.column_stack([rng.uniform(1, 3, 5), rng.uniform(-2, 2, 5)])
    y = truth[:, :1] * np.exp(truth[:, 1:] * t) + 0.05 * rng.standard_normal((5, t.size))
    truth = np.vstack([truth, [2.0, 0.5], [2.0, 0.5]])
    y = np.vstack([y, 2.0 * np.exp(0.5 * t) + 1e-12 * rng.standard_normal(t.size),
                   2.0 * np.exp(0.5 * t) + np.random.default_rng(5).standard_normal(t.size)])
    scale = np.array([1.0, 0.01, 100.0, 1.0, 1.0, 1.0, 1.0])
    seen = [[] for _ in range(7)]

    def one(x, i):
        return scale[i] * (x[0] * np.exp(x[1] * t) - y[i])

    def one_jac(x, i):
        e = np.exp(x[1] * t)
        return scale[i] * np.column_stack([e, x[0] * t * e, 0 * t])

    def fun(x, idx):
        for i, row in zip(idx, x, strict=True):
            seen[i].append(row.copy())
        return np.array([one(row, i) for i, row in zip(idx, x, strict=True)])

    def jac(x, idx):
        return np.array([one_jac(row, i) for i, row in zip(idx, x, strict=True)])

    x0 = np.column_stack([np.full(7, 0.1), np.r_[np.linspace(-3, 3, 5), 0.0, 0.0], np.zeros(7)])
    x0[5] = [truth[5, 0] + 1e-3, truth[5, 1] - 1e-3, 0.0]
    x0[6] = [1.0, 0.0, 0.0]
    got = bf._levenberg_marquardt(fun, jac, x0)
    rejected, last = 0, []
    for i in range(7):
        want, points, promised = _marquardt_one_trial(lambda x, i=i: one(x, i),
                                            lambda x, i=i: one_jac(x, i), x0[i].copy())
        assert len(seen[i]) == len(points), i
        np.testing.assert_allclose(seen[i], points, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(got[i], want, rtol=1e-9)
        costs = [np.sum(one(p, i) ** 2) for p in points]
        rejected += sum(c >= min(costs[:k]) for k, c in enumerate(costs) if k)
        last.append(promised)
    assert 0.5e-10 < last[6] <= 1e-10  # the seventh stopped on the promised decrease
    assert rejected >= 5  # the damping's increase is exercised
    assert len(seen[5]) < max(len(seen[i]) for i in range(5))  # stops while others go on
    np.testing.assert_allclose(got[5, :2], truth[5], rtol=1e-10)


@pytest.mark.parametrize("kw", [dict(), dict(reference_rows=False),
                                dict(reference_rows=False, free_roll=True),
                                dict(free_roll=True)])
def test_grouped_differences_are_the_column_by_column_ones(kw):
    """The Jacobian over every parameter (and over the core ones alone) and the residual
    covariance G diag(s^2) G' of the grouped differences equal central differences taken one
    column at a time here (step 1e-6 as the model's), at a point off the solution; relative
    readings add the columns of the INS's heading and pitch errors at the reference pointings."""
    kw = dict(kw)  # not the parameter itself: a test run again must see free_roll again
    free_roll = kw.pop("free_roll", False)
    d = _block(Noise(2 * A, 2 * A, 2 * A, 2 * A, math.radians(1.0)), n=2, **kw)
    b = bf._Batch(d, 1.0, free_roll, math.radians(2.0))
    x = np.random.default_rng(5).normal(0.0, 1e-3, (2, b.n_params))
    z, h = b.z0, 1e-6

    def column(fun, size, j):
        e = np.zeros(size)
        e[j] = h
        return (fun(e) - fun(-e)) / (2 * h)

    J = np.stack([column(lambda e: b.residuals(x + e, z), b.n_params, j)
                  for j in range(b.n_params)], axis=-1)
    np.testing.assert_allclose(b.jacobian_x(x, z, np.arange(b.n_params)), J, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.jacobian_x(x, z, np.arange(b.model.n_core)),
                               J[..., :b.model.n_core], rtol=0, atol=1e-9)
    G = np.stack([column(lambda e: b.residuals(x, z + e), z.shape[-1], j)
                  for j in range(z.shape[-1])], axis=-1)
    s = np.where(b.model.is_ins, 3 * A, 5 * A)
    want = np.einsum("tik,k,tjk->tij", G, s**2, G)
    if not kw.get("reference_rows", True):  # the INS's heading, pitch errors at C and R
        H = np.stack([column(lambda e: b.residuals(x, z, e), 4, j) for j in range(4)], axis=-1)
        assert np.abs(H).max() > 0.5  # a heading error at C shifts every relative heading
        want = want + (3 * A) ** 2 * np.einsum("tik,tjk->tij", H, H)
    np.testing.assert_allclose(b.residual_covariance(x, z, 3 * A, 5 * A), want,
                               rtol=1e-7, atol=1e-9 * A**2)


def test_trials_beyond_far_are_the_literal_fit_and_failures_are_nan(monkeypatch):
    """With FAR = 0 every trial is handed to the literal path: its numbers, exactly; a trial the
    literal path cannot determine is NaN and not ok."""
    d = _block(Noise(2 * A, 2 * A, 2 * A, 2 * A, math.radians(1.0)), n=2)
    monkeypatch.setattr(bf, "FAR", 0.0)
    f = bf.fit_block(d, sigma_ins=2 * A, sigma_theodolite=3 * A, side=1.0)
    assert f.ok.all()
    for i in range(2):
        lit = pr.fit_procedure(d.trial(i), sigma_ins=2 * A, sigma_theodolite=3 * A,
                               before=False)
        np.testing.assert_array_equal(f.values[i], lit.values)
        np.testing.assert_array_equal(f.covariance[i], lit.covariance)
        assert f.chi2[i] == lit.chi2
        np.testing.assert_array_equal(f.residuals[i], np.r_[lit.residuals[:, 0],
                                                            lit.residuals[:, 1]])
    calls = []

    def refuse(data, **kw):
        calls.append(kw)
        raise pr.NotDetermined("no")

    monkeypatch.setattr(pr, "fit_procedure", refuse)
    f = bf.fit_block(d, sigma_ins=2 * A, sigma_theodolite=3 * A, side=-1.0, free_roll=True,
                     roll_sigma=0.5)
    assert len(calls) == 2 and calls[0] == dict(side=-1.0, free_roll=True, roll_sigma=0.5,
                                                sigma_ins=2 * A, sigma_theodolite=3 * A,
                                                before=False)
    assert not f.ok.any()
    assert np.isnan(f.values).all() and np.isnan(f.covariance).all()
    assert np.isnan(f.residuals).all() and np.isnan(f.chi2).all()


@pytest.mark.parametrize("reference_rows", [True, False])
def test_a_left_roll_mirror_and_fitted_rolls_are_fitted_by_the_batch_itself(monkeypatch,
                                                                           reference_rows):
    """Roll mirror on the left (side -1), rolls fitted (their prior pseudo-observations in the
    Jacobian: all 12 with reference rows, the two reference rolls of relative readings): no
    trial is handed to the literal path (refused here), the offsets are within 5 of their
    sigmas of the truth, and with no reading error (and, for relative readings, a level mount,
    where the fitted reference rolls' prior costs nothing) the truth is met exactly and the
    corrected readings meet the theodolite's directions."""
    monkeypatch.setattr(pr, "fit_procedure", None)
    d = bf.simulate_block(GAMMA, LAMBDA, AZ, EL, Noise(2 * A, 2 * A, 2 * A, 2 * A,
                                                       math.radians(1.0)),
                          np.random.default_rng(8), 3, side=-1.0, frame_heading=0.4,
                          az_center=0.2, reference_rows=reference_rows)
    f = bf.fit_block(d, sigma_ins=2 * A, sigma_theodolite=2 * A, side=-1.0,
                     free_roll=reference_rows)  # relative readings: the two reference rolls
    assert f.ok.all()
    sigma = np.sqrt(np.diagonal(f.covariance, axis1=1, axis2=2)[:, :2])
    assert (np.abs(f.values[:, :2] - [GAMMA, LAMBDA]) < 5 * sigma).all()
    mount = math.radians(1.0) if reference_rows else 0.0  # else the roll prior pulls
    d = bf.simulate_block(GAMMA, LAMBDA, AZ, EL, Noise(0, 0, 0, 0, mount),
                          np.random.default_rng(8), 2, side=-1.0, frame_heading=0.4,
                          az_center=0.2, reference_rows=reference_rows)
    f = bf.fit_block(d, sigma_ins=2 * A, sigma_theodolite=2 * A, side=-1.0)
    assert f.ok.all()
    np.testing.assert_allclose(f.values[:, :2], [[GAMMA, LAMBDA]] * 2, rtol=0, atol=1e-12)
    np.testing.assert_allclose(bf.consistency_angles(d, f, side=-1.0), 0.0, atol=1e-12)


def test_defaults_are_a_central_mirror_at_zero_and_no_frame_heading():
    """No offsets, no error, defaults: the theodolite reads the central mirror at azimuth 0 and
    the roll mirror at +90 deg (side +1), both level, rows 0 and 1; the INS reads the same
    headings (frame heading 0) and pitches."""
    d = bf.simulate_block(0.0, 0.0, AZ, EL, Noise(0, 0, 0, 0, 0.0), np.random.default_rng(2), 2)
    assert (d.center, d.roll_mirror) == (0, 1)
    np.testing.assert_allclose(d.theodolite_az[:, :2], [[0.0, math.pi / 2]] * 2, atol=1e-15)
    np.testing.assert_allclose(d.theodolite_el[:, :2], 0.0, atol=1e-15)
    np.testing.assert_allclose(d.ins_az, d.theodolite_az, rtol=0, atol=1e-12)
    np.testing.assert_allclose(d.ins_el, d.theodolite_el, rtol=0, atol=1e-12)


def test_one_degree_of_freedom_is_enough():
    """Relative readings of two mirrors, no roll read: 4 readings, 3 parameters, dof 1."""
    d = bf.simulate_block(GAMMA, LAMBDA, [0.3, 0.0], [0.0, 0.3], Noise(A, A, A, A, 0.0),
                          np.random.default_rng(1), 2, reference_rows=False, with_roll=False)
    f = bf.fit_block(d, sigma_ins=A, sigma_theodolite=A)
    assert f.dof == 1 and f.values.shape == (2, 3)


def test_fitted_rolls_keep_the_lowest_of_the_mirror_image_minima(monkeypatch):
    """A cost with a second minimum, built by hand. Reference rows, every roll fitted (prior
    sigma 2 deg), no reading error; the 12 pointings (central mirror, roll mirror at 90 deg,
    the 10 mirrors) rolled by RA = (1, 6, 1, -15, 7, 2, -8, 3, 1, 1, -2, 3) deg (trial 0,
    offsets 3000", 1000") and RB = (3, 18, 3, -46, 20, 6, -23, 10, 4, 2, -6, 9) deg (trial 1,
    offsets 1000", -1000"); both sum to 0. The truth fits every reading, so its cost is the
    roll prior alone, sum (r / 2 deg)^2 = 101 and 915 (by hand): the minimum kept must be at
    least that low. From the level start (rolls 0) trial 1 ends at a second minimum near
    gamma = -1168", lambda = 323" with chi2 13736; from its mirror image (gamma negated) at
    763. Trial 0 is the other way round (99 from the level start, 8752 from gamma negated).
    The batch decides both itself (the literal path is not called) and keeps, per trial, the
    lowest: the literal fit of trial 1 (MINPACK, one trial) agrees, to the tolerance derived
    in tests/test_collimation_batch.py."""
    literal = pr.fit_procedure
    monkeypatch.setattr(pr, "fit_procedure", None)
    ra = np.radians([1, 6, 1, -15, 7, 2, -8, 3, 1, 1, -2, 3])
    rb = np.radians([3, 18, 3, -46, 20, 6, -23, 10, 4, 2, -6, 9])
    rolls = np.stack([ra, rb])
    truth = np.array([[3000.0, 1000.0], [1000.0, -1000.0]]) * A
    prior = np.sum((rolls / math.radians(2.0)) ** 2, axis=1)
    np.testing.assert_allclose(prior, [101.0, 915.0], rtol=1e-12)
    pointing_az = np.r_[0.0, math.pi / 2, AZ]
    pointing_el = np.r_[0.0, 0.0, EL]
    heading, pitch, roll = attitude_angles(ref.attitude_at(
        truth[:, :1], truth[:, 1:], pointing_az, pointing_el, rolls))
    d = bf.BatchData(np.tile(pointing_az, (2, 1)), np.tile(pointing_el, (2, 1)), wrap(heading),
                     pitch, roll, center=0, roll_mirror=1)
    sigma = 2 * A
    f = bf.fit_block(d, sigma_ins=sigma, sigma_theodolite=sigma, free_roll=True)
    assert f.ok.all()
    assert (f.chi2 <= prior).all()
    # the premise: the level start alone ends far above the truth's cost in trial 1
    b = bf._Batch(d, 1.0, True, math.radians(2.0))
    level = bf._solve(b, np.zeros((2, b.n_params)), np.arange(2), sigma, sigma)[0]
    _, _, w, _ = bf._solve(b, level, np.arange(b.n_params), sigma, sigma)
    chi2_level = np.einsum("ti,ti->t", w, w)
    assert chi2_level[1] > 10 * prior[1] and chi2_level[0] <= prior[0]
    np.testing.assert_allclose(f.chi2[0], chi2_level[0], rtol=1e-9)
    one = literal(d.trial(1), free_roll=True, sigma_ins=sigma, sigma_theodolite=sigma,
                  before=False)
    # to 1e-3 of each parameter's sigma, as tests/test_collimation_batch.py derives
    allowed = np.maximum(1e-8, 1e-3 * np.sqrt(np.diagonal(one.covariance)))
    assert (np.abs(f.values[1] - one.values) <= allowed).all()
    assert f.chi2[1] == pytest.approx(one.chi2, rel=1e-7)
    np.testing.assert_allclose(f.covariance[1], one.covariance, rtol=1e-4,
                               atol=1e-4 * np.abs(one.covariance).max())
    np.testing.assert_array_equal(f.rolls[1], f.values[1, 2:])


def test_relative_readings_start_each_trial_at_its_own_central_azimuth(monkeypatch):
    """Relative readings, no roll read, level mount, no error, central mirror at azimuth 0.8 rad
    in one trial and -0.7 rad in the other: each trial's central azimuth is found (to 1e-12
    rad) with the offsets, by the batch alone (the literal path is not called)."""
    monkeypatch.setattr(pr, "fit_procedure", None)
    blocks = [bf.simulate_block(GAMMA, LAMBDA, AZ, EL, Noise(0, 0, 0, 0, 0.0),
                                np.random.default_rng(4), 1, az_center=c, reference_rows=False,
                                with_roll=False) for c in (0.8, -0.7)]
    d = bf.BatchData(*(np.concatenate([getattr(b, k) for b in blocks]) for k in
                       ("theodolite_az", "theodolite_el", "ins_az", "ins_el")))
    f = bf.fit_block(d, sigma_ins=2 * A, sigma_theodolite=2 * A)
    assert f.ok.all()
    np.testing.assert_allclose(f.values, [[GAMMA, LAMBDA, 0.8], [GAMMA, LAMBDA, -0.7]],
                               rtol=0, atol=1e-12)


def test_a_solution_beyond_far_is_handed_to_the_literal_path_alone(monkeypatch):
    """Relative readings as above, central azimuths 0.3 and 2.0 rad: the second solution has a
    parameter beyond FAR = 1 rad (its central azimuth; its sigmas are arc-seconds), so that
    trial, and that trial only, is fitted again by the literal path, whose numbers it keeps
    (here the truth as well)."""
    literal, called = pr.fit_procedure, []

    def spy(data, **kw):
        called.append(float(data.theodolite_az[0]))
        return literal(data, **kw)

    monkeypatch.setattr(pr, "fit_procedure", spy)
    blocks = [bf.simulate_block(GAMMA, LAMBDA, AZ, EL, Noise(0, 0, 0, 0, 0.0),
                                np.random.default_rng(4), 1, az_center=c, reference_rows=False,
                                with_roll=False) for c in (0.3, 2.0)]
    d = bf.BatchData(*(np.concatenate([getattr(b, k) for b in blocks]) for k in
                       ("theodolite_az", "theodolite_el", "ins_az", "ins_el")))
    f = bf.fit_block(d, sigma_ins=2 * A, sigma_theodolite=2 * A)
    assert called == [float(d.theodolite_az[1, 0])]
    assert f.ok.all() and (np.sqrt(np.diagonal(f.covariance, axis1=1, axis2=2)) < 1e-3).all()
    np.testing.assert_allclose(f.values, [[GAMMA, LAMBDA, 0.3], [GAMMA, LAMBDA, 2.0]],
                               rtol=0, atol=1e-12)


@pytest.mark.parametrize("reference_rows", [True, False])
def test_a_block_of_one_trial(reference_rows):
    """A block may hold a single trial (the last chunk of a study): no error, reading errors
    of 2″ with the rolls recorded, the fit is the literal fit of that trial (to 1e-3 of each
    sigma, as tests/test_collimation_batch.py derives) and its consistency angles are the
    angles between the literal path's corrected readings and the theodolite's directions."""
    d = _block(Noise(2 * A, 2 * A, 2 * A, 2 * A, math.radians(1.0)), n=1,
               reference_rows=reference_rows)
    f = bf.fit_block(d, sigma_ins=2 * A, sigma_theodolite=2 * A)
    one = pr.fit_procedure(d.trial(0), sigma_ins=2 * A, sigma_theodolite=2 * A, before=False)
    assert f.ok.all() and f.values.shape == (1, one.values.size)
    allowed = np.maximum(1e-8, 1e-3 * np.sqrt(np.diagonal(one.covariance)))
    assert (np.abs(f.values[0] - one.values) <= allowed).all()
    c_az, c_el, t_az, t_el, _ = pr.corrected_and_theodolite(d.trial(0), one)
    want = np.arccos(np.clip(np.sum(direction(c_az, c_el) * direction(t_az, t_el), axis=-1),
                             -1.0, 1.0))
    got = bf.consistency_angles(d, f)
    assert got.shape == (1, AZ.size)
    np.testing.assert_allclose(got[0], want, rtol=0, atol=1e-3 * allowed[:2].max() + 1e-8)
