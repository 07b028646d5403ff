"""The batched observations' tests (data snooping) against the literal per-candidate reference.

:func:`analyse_observations` must give what :func:`analyse_candidates` gives for the same
observation candidates (whose columns it differentiates numerically, one candidate at a time),
on real data: a part of Zhang's 1998 calibration set (tests/data/camera).
"""

from __future__ import annotations

import math
import pickle
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from montecarlo.discrepancy import camera_effects as cam
from montecarlo.discrepancy.candidate_tests import analyse_candidates
from montecarlo.discrepancy.fit import fit_model, jacobian
from montecarlo.discrepancy.observation_tests import analyse_observations
from montecarlo.discrepancy.problem import with_outliers
from montecarlo.io.camera_csv import CameraData, read_camera_csv

CAMERA = Path(__file__).resolve().parents[1] / "tests" / "data" / "camera"


def _part_of_zhang(per_view: int) -> CameraData:
    """The first ``per_view`` corners of each of Zhang's five views."""
    data = read_camera_csv(CAMERA / "zhang_model.csv", CAMERA / "zhang_views.csv")
    keep = np.concatenate([np.flatnonzero(data.view == v)[:per_view]
                           for v in range(len(data.views))])
    return CameraData(data.views, tuple(data.point_id[i] for i in keep), data.view[keep],
                      data.points[keep], data.pixels[keep], data.rows[keep], data.unit)


@pytest.fixture(scope="module")
def snooping():
    problem = cam.camera_problem(_part_of_zhang(12), 0.25)
    full = with_outliers(problem)
    observations = replace(full, candidates=full.candidates[len(problem.candidates):])
    # a flagged corner in the model: its own test is "in_model"
    flagged = observations.candidates[3].name
    return observations, fit_model(full, ["radial_k1", flagged])


def _close(a: float, b: float) -> bool:
    return (math.isnan(a) and math.isnan(b)) or a == pytest.approx(b, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize(("test", "absorbed"), [("chi2", 0.05), ("tau", 0.05),
                                                ("chi2", 0.75), ("F", 0.8)])
def test_batched_observation_tests_equal_the_reference(snooping, test, absorbed):
    observations, fit = snooping
    level = lambda k: 0.002 / max(k, 1)  # noqa: E731
    # the reference differentiates every column numerically, the shifts' too
    reference = analyse_candidates(replace(observations, unit_columns={}), fit,
                                   absorbed=absorbed, level=level, test=test)
    batched = analyse_observations(observations, fit, absorbed=absorbed, level=level, test=test)
    statuses = {t.status for t in reference}
    # the cases the batched path hands to the reference's code are exercised too
    assert "in_model" in statuses and "testable" in statuses
    if absorbed > 0.5:
        assert "absorbed" in statuses
        assert any(t.status == "testable" and t.absorbed_by for t in reference)
    assert [t.name for t in batched] == [t.name for t in reference]
    for a, b in zip(reference, batched, strict=True):
        assert (a.status, a.active, a.dof, a.dof2, a.test, a.reason) == \
            (b.status, b.active, b.dof, b.dof2, b.test, b.reason)
        assert a.absorbed_by == b.absorbed_by
        for f in ("statistic", "p_value", "log_p", "p_adjusted", "lambda0", "level"):
            assert _close(getattr(a, f), getattr(b, f)), (a.name, f)
        for f in ("retained", "estimate", "stderr", "mdb", "influence"):
            x, y = getattr(a, f), getattr(b, f)
            assert x.keys() == y.keys()
            assert all(_close(x[k], y[k]) for k in x), (a.name, f)
        if a.projected is None:
            assert b.projected is None and b.basis is None
            continue
        np.testing.assert_allclose(b.projected, a.projected, atol=1e-12)
        # the same space: each basis projects the other's columns onto themselves
        assert b.basis.shape == a.basis.shape
        np.testing.assert_allclose(b.basis @ (b.basis.T @ a.basis), a.basis, atol=1e-12)


def test_fields_read_later_survive_copies_and_pickling(snooping):
    """A batched test fills its estimate, MDB, influence and kept shares when first read (the
    test above checks them against the reference); a copy or a pickled test made before that
    fills the same values, and a name that is no field is still an AttributeError."""
    observations, fit = snooping
    fresh = analyse_observations(observations, fit)
    filled = analyse_observations(observations, fit)
    testable = [k for k, t in enumerate(filled) if t.status == "testable"]
    assert len(testable) > 10
    for k in testable:
        assert "_later" in fresh[k].__dict__
        copy = pickle.loads(pickle.dumps(fresh[k].with_fields(p_adjusted=0.5)))
        for f in ("retained", "estimate", "stderr", "mdb"):
            assert getattr(copy, f) == getattr(filled[k], f)
        assert dict(copy.influence) == dict(filled[k].influence)
        assert copy.p_adjusted == 0.5 and "_later" not in copy.__dict__
    with pytest.raises(AttributeError):
        fresh[testable[0]].not_a_field  # noqa: B018


def test_columns_only_below_the_threshold(snooping):
    """With ``columns_below`` the projected columns and bases are those of the reference for the
    observations whose own p-value is below it, None for the others; the statistics are
    unchanged."""
    observations, fit = snooping
    every = analyse_observations(observations, fit)
    p = np.sort([t.p_value for t in every if t.status == "testable"])
    cut = float(np.sqrt(p[p.size // 2] * p[p.size // 2 + 1]))  # between two tests' p-values
    some = analyse_observations(observations, fit, columns_below=cut)
    below = 0
    for a, b in zip(every, some, strict=True):
        assert (a.statistic, a.p_value, a.mdb) == (b.statistic, b.p_value, b.mdb) or \
            a.status != "testable"
        if a.projected is not None and a.p_value < cut:
            below += 1
            np.testing.assert_array_equal(b.projected, a.projected)
            np.testing.assert_allclose(b.basis, a.basis, atol=1e-14)
        else:
            assert b.projected is None and b.basis is None
    assert below > 3


def test_shift_columns_are_the_identity_rows_finite_differences_give(snooping):
    """The exact columns of the observations' shifts equal central differences of the same
    residual function (the problem without ``unit_columns``), with the model's columns."""
    observations, fit = snooping
    base = observations.base.parameters
    names = [*base, *observations.candidates[0].parameters,
             *observations.candidates[7].parameters]
    values = {**fit.params, **dict.fromkeys(names[len(base):], 0.3)}
    exact = jacobian(observations, values, names)
    numeric = jacobian(replace(observations, unit_columns={}), values, names)
    assert set(names[len(base):]) <= set(observations.unit_columns)
    np.testing.assert_allclose(exact, numeric, atol=1e-8)
    assert np.count_nonzero(exact[:, len(base):]) == 4


def test_pose_columns_differentiated_together_equal_one_at_a_time(snooping):
    """A view's pose moves only that view's corners (checked on the one-at-a-time columns of
    the model itself), so the same pose parameter of every view is perturbed in one model
    evaluation: the columns are those of one parameter at a time, and the evaluations drop
    from two per parameter to two per group."""
    observations, fit = snooping
    names = list(observations.base.parameters)
    values = fit.params
    alone = jacobian(replace(observations, local_rows={}), values, names)
    for j, name in enumerate(names):
        if name in observations.local_rows:
            outside = np.ones(alone.shape[0], bool)
            outside[observations.local_rows[name]] = False
            assert not np.any(alone[outside, j]), name
            assert np.any(alone[observations.local_rows[name], j]), name
    sizes = []

    def counted(v):
        sizes.append(max((np.shape(x)[0] for x in v.values() if np.ndim(x)), default=1))
        return observations.residuals(v)

    together = jacobian(replace(observations, residuals=counted), values, names)
    np.testing.assert_array_equal(together, alone)
    n_views = 5
    assert len(names) == 3 + 6 * n_views and sizes == [2 * (3 + 6)]


def test_flagged_corners_fitted_without_their_rows_equal_the_fit_of_their_shifts(snooping):
    """A flagged observation's shifts are not iterated on (its rows are left out and the
    shifts are the residuals there); scipy iterating on every parameter, the shifts' columns
    differentiated numerically, finds the same fit."""
    observations, _ = snooping
    full = with_outliers(cam.camera_problem(_part_of_zhang(12), 0.25))
    flagged = [c.name for c in observations.candidates[2:5]]
    fast = fit_model(full, ["radial_k1", *flagged])
    reference = fit_model(replace(full, unit_columns={}), ["radial_k1", *flagged])
    assert fast.names == reference.names
    shifts = [j for j, n in enumerate(fast.names) if n in full.unit_columns]
    assert len(shifts) == 6 and np.all(fast.residual[[full.unit_columns[fast.names[j]]
                                                      for j in shifts]] == 0.0)
    scale = np.sqrt(np.diag(reference.covariance))
    assert np.max(np.abs(fast.values - reference.values) / scale) < 1e-6
    # the two solutions differ by 3e-7 of a standard error (each solver's convergence)
    assert np.max(np.abs(fast.covariance - reference.covariance) / np.outer(scale, scale)) < 1e-5
    assert np.all(np.linalg.norm(fast.jacobian - reference.jacobian, axis=0)
                  < 1e-6 * np.linalg.norm(reference.jacobian, axis=0))
    assert fast.chi2 == pytest.approx(reference.chi2, rel=1e-9)
