"""Seed 003's procedure fit (section 3.2) against a generalised least-squares fit written out here.

The residuals are written from the definitions of docs/reference/collimation.md ("The paper's
procedure"):
with reference rows the relative heading and pitch read at a measured mirror are the direction
of its INS axis ``direction(heading, pitch)`` in the frame ``x = s normalize(a_r - (a_r . a_c)
a_c), y = a_c, z = x cross y`` of the INS axes at the central and the roll mirror (Gram-Schmidt,
below); without reference rows they are the readings themselves. The model is
:func:`montecarlo.seed003.reference.relative_readings`, tested against scipy's ``Rotation`` in
``tests/test_collimation_reference.py``. The residual covariance is propagated from the reading
errors by central differences over every reading (and, for relative readings, over the INS's
heading and pitch at the two reference pointings, which the readings carry unseen), the rolls
carry the prior ``N(0, roll_sigma)`` as pseudo-observations, and
``scipy.optimize.least_squares`` (trust region, central differences) minimises the whitened
residuals, started at the truth. The covariance is re-evaluated at each solution until it no
longer moves the solution (the fixed point): the procedure recomputes it once, at its first
solution, so the two agree to the change of the covariance between those points, second order in
the offsets (about 1e-3 rad): they agree to 1e-5 of a standard error, and the tests allow 1e-3.
"""

import copy
import math

import numpy as np
import pytest
from scipy.optimize import least_squares

from montecarlo.seed003 import procedure as pr
from montecarlo.seed003 import reference as ref
from montecarlo.seed003.model import Noise, autocollimate
from montecarlo.units import ARCSEC

A = ARCSEC
AZ, EL, SETS = pr.procedure_layout(pitches=pr.HIGH_PITCHES)
M = AZ.size


def _unit(az, el):
    az, el = np.broadcast_arrays(np.asarray(az, float), np.asarray(el, float))
    return np.stack([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)], axis=-1)


class Independent:
    """The procedure's GLS problem for one data set, written out from its definition.

    ``roll``: "recorded", "level" or "free". Parameters: gamma, lambda, (reference_az without
    reference rows), then the rolls that carry the prior: every pointing's with "free" (reference
    rows: in row order; without: measured mirrors, then central, then roll mirror), the two
    reference pointings' with recorded relative rolls.
    """

    def __init__(self, d, side, roll, roll_sigma):
        self.d, self.side, self.roll, self.roll_sigma = d, side, roll, roll_sigma
        self.rows = d.center is not None
        self.m = d.ins_az.size - (2 if self.rows else 0)  # measured mirrors
        self.readings = {"ins_az": d.ins_az, "ins_el": d.ins_el, "t_az": d.theodolite_az,
                         "t_el": d.theodolite_el}
        if roll == "recorded":
            self.readings["ins_roll"] = d.ins_roll
        n_rolls = {"free": self.m + 2, "level": 0, "recorded": 0 if self.rows else 2}[roll]
        self.n_core = 2 if self.rows else 3
        self.n = self.n_core + n_rolls

    def _frame(self, a_c, a_r):
        """Columns x, y, z of the frame of the axes ``a_c``, ``a_r`` (Gram-Schmidt)."""
        y = a_c
        x = a_r - np.sum(a_r * y, axis=-1, keepdims=True) * y
        x = self.side * x / np.linalg.norm(x, axis=-1, keepdims=True)
        return np.stack([x, y, np.cross(x, y)], axis=-1)

    def _in_frame(self, a_c, a_r, v):
        """Heading and pitch of the directions ``v`` in the frame of the axes ``a_c``, ``a_r``."""
        c = np.matmul(v[..., None, :], self._frame(a_c, a_r))[..., 0, :]
        return np.arctan2(c[..., 0], c[..., 1]), np.arcsin(c[..., 2])

    def observed(self, r):
        if not self.rows:
            return r["ins_az"], r["ins_el"]
        a = _unit(r["ins_az"], r["ins_el"])  # (..., rows, 3)
        return self._in_frame(a[..., 0, None, :], a[..., 1, None, :], a[..., 2:, :])

    def reference_columns(self, p, step=1e-6):
        """Relative readings only: (2m, 4) central differences of the model's readings by
        errors of the INS's heading and pitch at the central, then the roll pointing. The INS
        builds its frame from the axes it read there; the readings are the measured mirrors'
        INS axes in that frame (with recorded relative rolls, the attitude with that roll in it
        which autocollimates the mirror)."""
        g, lam, az_c = p[0], p[1], p[2]
        rolls = {"free": p[3 + self.m:5 + self.m], "recorded": p[3:5]}.get(self.roll, (0, 0))
        axes = [ref.attitude_at(g, lam, az, 0.0, roll)[:, 1] for az, roll in
                zip((az_c, az_c + self.side * math.pi / 2), rolls, strict=True)]
        read = [(np.arctan2(a[0], a[1]), np.arcsin(a[2])) for a in axes]
        w = _unit(self.d.theodolite_az, self.d.theodolite_el)
        if self.roll == "recorded":  # the relative roll as read: the attitude in the frame
            relative_roll = self.d.ins_roll
        else:
            roll_k = p[3:3 + self.m] if self.roll == "free" else np.zeros(self.m)
            v = ref.attitude_at(g, lam, self.d.theodolite_az, self.d.theodolite_el, roll_k)
            v = v[..., :, 1]
        cols = []
        for j in range(4):
            pair = []
            for sgn in (1.0, -1.0):
                moved = [list(angles) for angles in read]
                moved[j // 2][j % 2] += sgn * step
                a_c, a_r = (_unit(*angles) for angles in moved)
                if self.roll == "recorded":
                    heading, pitch = autocollimate(_unit(g, lam), w @ self._frame(a_c, a_r),
                                                   relative_roll)
                else:
                    heading, pitch = self._in_frame(a_c, a_r, v)
                pair.append(np.concatenate([heading, pitch]))
            cols.append((pair[0] - pair[1]) / (2 * step))
        return np.array(cols).T

    def predicted(self, p, r):
        """Relative heading and pitch of the model; ``p`` may have a leading batch axis."""
        p = np.asarray(p, float)
        g, lam = p[..., 0, None], p[..., 1, None]
        if self.rows:
            zero = np.zeros((*p.shape[:-1], self.m + 2))
            rolls = {"free": p[..., 2:], "level": zero}.get(self.roll, r.get("ins_roll"))
            t_az, t_el = r["t_az"], r["t_el"]
            return ref.relative_readings(
                g, lam, t_az[..., 2:], t_el[..., 2:], rolls[..., 2:],
                (t_az[..., 0, None], t_el[..., 0, None], rolls[..., 0, None]),
                (t_az[..., 1, None], t_el[..., 1, None], rolls[..., 1, None]), self.side)[:2]
        az_c = p[..., 2, None]
        relative = self.roll == "recorded"
        if self.roll == "free":
            m = self.m
            roll_k, roll_c, roll_r = p[..., 3:3 + m], p[..., 3 + m, None], p[..., 4 + m, None]
        elif relative:
            roll_k, roll_c, roll_r = r["ins_roll"], p[..., 3, None], p[..., 4, None]
        else:
            roll_k, roll_c, roll_r = np.zeros(self.m), 0.0, 0.0
        return ref.relative_readings(g, lam, r["t_az"], r["t_el"], roll_k,
                                     (az_c, 0.0, roll_c),
                                     (az_c + self.side * math.pi / 2, 0.0, roll_r), self.side,
                                     roll_is_relative=relative)[:2]

    def residuals(self, p, r=None):
        r = self.readings if r is None else r
        h_obs, p_obs = self.observed(r)
        h, pt = self.predicted(p, r)
        return np.concatenate(np.broadcast_arrays(ref.wrap(h_obs - h), p_obs - pt), axis=-1)

    def covariance(self, p, sigma_ins, sigma_theodolite, step=1e-6):
        """``G diag(sigma^2) G^T``, G the central differences of the residuals by every reading
        (one batch: row j moves reading j up, row Q + j down)."""
        q = sum(v.size for v in self.readings.values())
        moved = {k: np.repeat(v[None], 2 * q, axis=0) for k, v in self.readings.items()}
        sigma, j = [], 0
        for name, values in self.readings.items():
            for i in range(values.size):
                moved[name][j, i] += step
                moved[name][q + j, i] -= step
                sigma.append(sigma_ins if name.startswith("ins") else sigma_theodolite)
                j += 1
        r = self.residuals(p, moved)
        G = (r[:q] - r[q:]).T / (2 * step)
        cov = (G * np.square(sigma)) @ G.T
        if not self.rows:
            H = self.reference_columns(np.asarray(p, float), step)
            cov = cov + sigma_ins**2 * (H @ H.T)
        return cov

    def whitened(self, p, L):
        """``L^-1 r`` and the prior's pseudo-observations; ``p`` may have a batch axis."""
        p = np.asarray(p, float)
        prior = p[..., self.n_core:] / self.roll_sigma
        return np.concatenate([self.residuals(p) @ np.linalg.inv(L).T, prior], axis=-1)

    def jacobian(self, p, L, free, step=1e-7):
        """Central differences of :meth:`whitened` by the parameters ``free``, one batch."""
        k = len(free)
        P = np.repeat(np.asarray(p, float)[None], 2 * k, axis=0)
        P[np.arange(k), free] += step
        P[k + np.arange(k), free] -= step
        w = self.whitened(P, L)
        return ((w[:k] - w[k:]) / (2 * step)).T

    def fit(self, start, sigma_ins, sigma_theodolite, free=None):
        """GLS at the fixed point of the covariance; returns x, its covariance and chi2."""
        free = np.arange(self.n) if free is None else np.asarray(free)
        x = np.asarray(start, float).copy()

        def f(xf, L):
            xx = x.copy()
            xx[free] = xf
            return self.whitened(xx, L)

        def jac(xf, L):
            xx = x.copy()
            xx[free] = xf
            return self.jacobian(xx, L, free)

        for _ in range(3):
            L = np.linalg.cholesky(self.covariance(x, sigma_ins, sigma_theodolite))
            sol = least_squares(f, x[free], jac=jac, args=(L,), xtol=1e-15, ftol=1e-15,
                                gtol=1e-15, x_scale=1e-3)
            x[free] = sol.x
        J = jac(x[free], L)
        w = f(x[free], L)
        return x, np.linalg.inv(J.T @ J), float(w @ w)


def _data(rows, roll, side, seed, g=350 * A, lam=-250 * A, sigma=2 * A):
    noise = Noise(theodolite=sigma, ins_heading=1.5 * sigma, ins_pitch=1.5 * sigma,
                  ins_roll=1.5 * sigma, mount_roll=0.0 if roll == "level" else 0.02)
    return pr.simulate_procedure(g, lam, AZ, EL, noise, seed, side=side, frame_heading=1.0,
                                 az_center=0.1, reference_rows=rows,
                                 with_roll=roll == "recorded")


def _truth(ind, d, g, lam, seed):
    """The start at the truth: offsets, reference azimuth 0.1, the simulated mount rolls."""
    x = np.zeros(ind.n)
    x[:2] = g, lam
    if not ind.rows:
        x[2] = 0.1
    if ind.roll == "free":
        rolls = 0.02 * np.random.default_rng(seed).standard_normal(M + 2)  # the simulator's draw
        x[ind.n_core:] = rolls if ind.rows else np.r_[rolls[2:], rolls[:2]]
    return x


CASES = [(True, "recorded", 1.0), (True, "level", -1.0), (True, "free", 1.0),
         (False, "recorded", -1.0), (False, "level", 1.0), (False, "free", -1.0)]


@pytest.mark.parametrize(("rows", "roll", "side"), CASES)
def test_fit_is_the_gls_solution_written_out(rows, roll, side):
    """INS errors 3″, theodolite 2″ (different, so the two kinds of reading are weighted
    apart), mount rolls 0.02 rad (1σ), roll prior 0.05 rad: the fitted parameters, their
    covariance, the chi-square (prior included), the residuals and the rolls are those of the
    fit written out here. Tolerances: parameters within 1e-3 of their standard error (the
    covariance's fixed point, module docstring; they agree to 1e-5), covariance within 1e-4 of
    the product of the two standard errors, chi-square 1e-5 relative (a parameter shift of 1e-3
    sigma changes it by 1e-6)."""
    seed, g, lam, roll_sigma = 5, 350 * A, -250 * A, 0.05
    s_ins, s_theo = 3 * A, 2 * A
    d = _data(rows, roll, side, seed, g, lam)
    f = pr.fit_procedure(d, side=side, free_roll=roll == "free", roll_sigma=roll_sigma,
                         sigma_ins=s_ins, sigma_theodolite=s_theo)
    ind = Independent(d, side, roll, roll_sigma)
    x, cov, chi2 = ind.fit(_truth(ind, d, g, lam, seed), s_ins, s_theo)
    se = np.sqrt(np.diag(cov))
    names = {"free": tuple(f"roll_{i}" for i in range(M + 2)), "level": (),
             "recorded": () if rows else ("roll_center", "roll_mirror")}[roll]
    assert f.names == ("axis_az", "axis_el") + (() if rows else ("reference_az",)) + names
    assert np.all(np.abs(f.values - x) < 1e-3 * se), (f.values - x) / se
    np.testing.assert_allclose(f.covariance / np.outer(se, se), cov / np.outer(se, se), rtol=0,
                               atol=1e-4)
    assert f.chi2 == pytest.approx(chi2, rel=1e-5)
    assert f.dof == 2 * M + (ind.n - ind.n_core) - ind.n
    res = ind.residuals(x)
    sigma_res = np.sqrt(np.diag(ind.covariance(x, s_ins, s_theo)))
    assert np.all(np.abs(f.residuals.T.ravel() - res) < 1e-3 * sigma_res)
    if roll == "free":
        np.testing.assert_allclose(f.rolls, x[ind.n_core:], atol=1e-3 * se[ind.n_core:].min())
    assert (f.sigma_ins, f.sigma_theodolite, f.sigma_source) == (s_ins, s_theo, "given")


@pytest.mark.parametrize(("rows", "roll", "side"), [(True, "recorded", 1.0),
                                                    (False, "free", -1.0)])
def test_residuals_before_are_the_gls_fit_with_the_offsets_at_zero(rows, roll, side):
    """``residuals_before``: gamma and lambda held at zero, everything else (the reference
    azimuth, fitted rolls) fitted as written out here; the same residuals within 1e-3 of each
    residual's sigma. With the offsets at zero the INS axis is the optical axis, the rolls
    change no reading and the prior holds them at zero."""
    seed, g, lam, roll_sigma = 6, 350 * A, -250 * A, 0.05
    d = _data(rows, roll, side, seed, g, lam)
    f = pr.fit_procedure(d, side=side, free_roll=roll == "free", roll_sigma=roll_sigma,
                         sigma_ins=3 * A, sigma_theodolite=2 * A)
    ind = Independent(d, side, roll, roll_sigma)
    start = _truth(ind, d, 0.0, 0.0, seed)
    # with reference rows and recorded rolls nothing is left to fit
    x = start if ind.n == 2 else ind.fit(start, 3 * A, 2 * A, free=np.arange(2, ind.n))[0]
    res = ind.residuals(x)
    sigma_res = np.sqrt(np.diag(ind.covariance(x, 3 * A, 2 * A)))
    assert np.all(np.abs(f.residuals_before.T.ravel() - res) < 1e-3 * sigma_res)
    assert np.abs(res).max() > 100 * A  # the offsets' signal, which the fit then removes
    assert np.abs(f.residuals).max() < 20 * A


def _jacobian(fun, x, step=1e-7):
    cols = []
    for i in range(x.size):
        e = np.zeros(x.size)
        e[i] = step
        cols.append((fun(x + e) - fun(x - e)) / (2 * step))
    return np.column_stack(cols)


@pytest.mark.parametrize(("rows", "side"), [(True, 1.0), (False, -1.0)])
def test_heading_floor_is_the_rms_derivative_of_the_headings_by_the_rolls(rows, side):
    """``sqrt(mean_k sum_j (d heading_k / d phi_j)^2)`` over the measured mirrors k and every
    pointing's absolute roll j, at the fitted offsets and all rolls 0: central differences of
    the model written out here, 1e-4 relative."""
    d = _data(rows, "recorded", side, 2, g=100 * A, lam=400 * A, sigma=0.0)
    f = pr.fit_procedure(d, side=side, sigma_ins=2 * A, sigma_theodolite=2 * A, before=False)
    ind = Independent(d, side, "free", 1.0)
    x = np.zeros(ind.n)
    x[:ind.n_core] = f.values[:ind.n_core]
    J = _jacobian(lambda r: ind.predicted(np.r_[x[:ind.n_core], r], ind.readings)[0],
                  x[ind.n_core:])
    assert J.shape == (M, M + 2)
    floor = math.sqrt(np.mean(np.sum(J**2, axis=1)))
    assert pr.heading_floor(d, f) == pytest.approx(floor, rel=1e-4)


@pytest.mark.parametrize(("rows", "side"), [(True, -1.0), (False, 1.0)])
def test_predicted_stderr_with_free_rolls_is_the_gls_covariance_written_out(rows, side):
    """Noise-free readings, fitted with recorded rolls; ``predicted_stderr`` with free rolls
    (prior 0.05 rad) at the fitted offsets and all rolls 0: the square roots of the diagonal of
    ``(J^T J)^-1``, J the whitened residuals and the prior rows, differentiated here (1e-4)."""
    roll_sigma = 0.05
    d = _data(rows, "recorded", side, 3, sigma=0.0)
    f = pr.fit_procedure(d, side=side, sigma_ins=3 * A, sigma_theodolite=2 * A, before=False)
    ind = Independent(d, side, "free", roll_sigma)
    x = np.zeros(ind.n)
    x[:ind.n_core] = f.values[:ind.n_core]
    L = np.linalg.cholesky(ind.covariance(x, 3 * A, 2 * A))
    J = _jacobian(lambda p: ind.whitened(p, L), x)
    se = np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
    got = pr.predicted_stderr(d, f, True, roll_sigma)
    names = ["axis_az", "axis_el"] + ([] if rows else ["reference_az"])
    assert list(got) == names + [f"roll_{i}" for i in range(M + 2)]
    np.testing.assert_allclose(list(got.values()), se, rtol=1e-4)
    assert got["axis_az"] > f.stderr["axis_az"]  # the free rolls cost precision


def test_free_rolls_keep_the_lowest_of_the_mirror_image_starts():
    """Free rolls, paper-like layout, relative readings, mount rolls 1 deg, errors 2″ (a trial
    of the acceptance harness, seed 592). Written out here, the GLS cost has two minima: one
    reached from the truth (its rolls included), chi2 16.1, and one from the truth with gamma
    negated, chi2 12.8. The fit must end in the lower one: its parameters within 1e-3 of their
    sigma, its chi2 within 1e-5."""
    az, el, _ = pr.procedure_layout()
    rng = np.random.default_rng(592)
    truth = rng.uniform(10 * A, 600 * A, 2) * rng.choice([-1.0, 1.0], 2)
    # the simulator's next draw: the rolls at the central, the roll and the measured mirrors
    rolls = math.radians(1.0) * copy.deepcopy(rng).standard_normal(az.size + 2)
    noise = Noise(2 * A, 2 * A, 2 * A, 2 * A, math.radians(1.0))
    d = pr.simulate_procedure(*truth, az, el, noise, rng, reference_rows=False, with_roll=False)
    f = pr.fit_procedure(d, free_roll=True, sigma_ins=2 * A, sigma_theodolite=2 * A,
                         before=False)
    ind = Independent(d, 1.0, "free", math.radians(2.0))
    start = np.r_[truth, 0.0, rolls[2:], rolls[:2]]
    at_truth = ind.fit(start, 2 * A, 2 * A)
    start[0] *= -1
    x, cov, chi2 = ind.fit(start, 2 * A, 2 * A)
    assert at_truth[2] == pytest.approx(16.102, abs=1e-3)
    assert chi2 == pytest.approx(12.769, abs=1e-3)
    assert f.chi2 == pytest.approx(chi2, rel=1e-5)
    assert np.all(np.abs(f.values - x) < 1e-3 * np.sqrt(np.diag(cov)))


@pytest.mark.parametrize(("rows", "roll", "mirrors"), [(False, "recorded", M), (False, "level", 2)])
def test_a_posteriori_sigma_scales_the_readings_not_the_prior(rows, roll, mirrors):
    """Both sigmas None: one sigma for both kinds of reading, ``sqrt(r^T C1^-1 r / dof)`` at the
    fit with 1″ readings (C1 their residual covariance; the prior's pseudo-observations are
    not part of r: the roll prior is a fixed spread, not scaled). Relative readings with the
    rolls at the reference mirrors fitted (a prior: 20 - 5 + 2 = 17 dof), and two mirrors
    without roll (4 - 3 = 1 dof). 1e-4 relative (the fixed point of the covariance)."""
    idx = np.r_[0, 5] if mirrors == 2 else np.arange(M)
    noise = Noise(3 * A, 3 * A, 3 * A, 3 * A, 0.02 if roll == "recorded" else 0.0)
    d = pr.simulate_procedure(350 * A, -250 * A, AZ[idx], EL[idx], noise, 8, az_center=0.1,
                              reference_rows=rows, with_roll=roll == "recorded")
    f = pr.fit_procedure(d, roll_sigma=0.05, before=False)
    ind = Independent(d, 1.0, roll, 0.05)
    x = ind.fit(_truth(ind, d, 350 * A, -250 * A, 8), A, A)[0]
    r = ind.residuals(x)
    dof = 2 * idx.size + (ind.n - ind.n_core) - ind.n
    assert f.dof == dof == (17 if mirrors == M else 1)
    sigma = A * math.sqrt(r @ np.linalg.solve(ind.covariance(x, A, A), r) / dof)
    assert f.sigma_source == "a posteriori"
    assert f.sigma_ins == f.sigma_theodolite == pytest.approx(sigma, rel=1e-4)
