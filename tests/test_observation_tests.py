"""The batched observations' tests (data snooping) against the literal per-candidate reference.

:func:`analyse_observations` must give what :func:`analyse_candidates` gives for the same
observation candidates (whose columns it differentiates numerically, one candidate at a time),
on real data: a part of Zhang's 1998 calibration set (tests/data/camera).
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from montecarlo.discrepancy import camera_effects as cam
from montecarlo.discrepancy.candidate_tests import analyse_candidates
from montecarlo.discrepancy.fit import fit_model
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
    reference = analyse_candidates(observations, fit, absorbed=absorbed, level=level, test=test)
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
