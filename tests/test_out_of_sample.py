"""Leave one group out (montecarlo.discrepancy.out_of_sample) against references it does not
compute: OpenCV's projection and its analytic Jacobian with numpy least squares (the
prediction error of a model without k1, in closed form to first order) and scipy's paired t
test."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from scipy import stats

from montecarlo.camera_calibration.simulate import standard_poses, target_grid
from montecarlo.discrepancy import camera_effects as cam
from montecarlo.discrepancy.fit import fit_model
from montecarlo.discrepancy.out_of_sample import (
    format_leave_one_out,
    leave_one_group_out,
    markdown_leave_one_out,
    prediction_test,
)
from montecarlo.io.camera_csv import CameraData

cv2 = pytest.importorskip("cv2")

F, CX, CY = 830.0, 318.0, 243.0


def _opencv_views(k1: float, n_views: int, grid: int, sigma: float, seed: int
                  ) -> tuple[CameraData, np.ndarray, np.ndarray]:
    """Views of a planar grid projected by ``cv2.projectPoints`` (square pixels, no skew,
    radial k1 only), plus normal noise ``sigma`` [px]."""
    rvec, tvec = standard_poses(n_views)
    pts = target_grid(grid, 0.025)
    obj = np.column_stack([pts, np.zeros(len(pts))])
    K = np.array([[F, 0, CX], [0, F, CY], [0, 0, 1.0]])
    rng = np.random.default_rng(seed)
    pixels = np.concatenate([
        cv2.projectPoints(obj, rvec[v], tvec[v], K, np.array([k1, 0, 0, 0, 0.0]))[0].reshape(-1, 2)
        for v in range(n_views)])
    pixels = pixels + sigma * rng.standard_normal(pixels.shape)
    view = np.repeat(np.arange(n_views), len(pts))
    data = CameraData(tuple(str(v + 1) for v in range(n_views)),
                      tuple(str(i) for i in np.tile(np.arange(len(pts)), n_views)), view,
                      np.tile(pts, (n_views, 1)), pixels, np.arange(view.size) + 2)
    return data, rvec, tvec


def _camera_loo(data: CameraData, sigma: float, effects: list[str], alpha: float = 0.01
                ) -> dict[str, Any]:
    problem = cam.camera_problem(data, sigma)
    d = SimpleNamespace(problem=problem, after=fit_model(problem, effects), alpha=alpha)
    return leave_one_group_out(d, cam.report_view(data, sigma),  # type: ignore[arg-type]
                               cam.view_groups(data), "view")


def _linear_prediction(k1: float, rvec: np.ndarray, tvec: np.ndarray) -> list[float]:
    """Prediction RMS [px] of each left-out view by the pinhole without k1, to first order in
    k1: from the truth, the data's departure from the pinhole (k1's image displacement) is
    fitted by the shared intrinsics f, cx, cy and each training view's pose (OpenCV's
    Jacobian, numpy least squares); the left-out view keeps what those intrinsics leave,
    minus what its own pose absorbs."""
    pts = target_grid(6, 0.025)
    obj = np.column_stack([pts, np.zeros(len(pts))])
    K = np.array([[F, 0, CX], [0, F, CY], [0, 0, 1.0]])
    n_views = len(rvec)
    blocks, departure = [], []
    for v in range(n_views):
        with_k1 = cv2.projectPoints(obj, rvec[v], tvec[v], K, np.array([k1, 0, 0, 0, 0.0]))[0]
        plain, J = cv2.projectPoints(obj, rvec[v], tvec[v], K, np.zeros(5))
        departure.append((with_k1 - plain).reshape(-1))
        # OpenCV's columns: rvec (3), tvec (3), fx, fy, cx, cy, distortion
        intrinsic = np.column_stack([J[:, 6] + J[:, 7], J[:, 8], J[:, 9]])
        blocks.append((intrinsic, J[:, :6]))
    out = []
    for left in range(n_views):
        train = [v for v in range(n_views) if v != left]
        rows = sum(len(departure[v]) for v in train)
        A = np.zeros((rows, 3 + 6 * len(train)))
        at = 0
        for j, v in enumerate(train):
            n = len(departure[v])
            A[at:at + n, :3] = blocks[v][0]
            A[at:at + n, 3 + 6 * j:9 + 6 * j] = blocks[v][1]
            at += n
        shift = np.linalg.lstsq(A, np.concatenate([departure[v] for v in train]),
                                rcond=None)[0][:3]
        left_over = departure[left] - blocks[left][0] @ shift
        pose = blocks[left][1]
        e = left_over - pose @ np.linalg.lstsq(pose, left_over, rcond=None)[0]
        out.append(float(np.sqrt(np.mean(e ** 2))))
    return out


def test_dropping_k1_costs_the_first_order_prediction_error() -> None:
    """Noise-free views with k1 = -0.2 (Zhang's camera has -0.23): the final model (pinhole +
    k1) predicts every left-out view exactly; without k1 each view's prediction RMS is |k1|
    times a fixed projection of k1's image displacement (first order; the k1^2 terms measured
    below 2e-4 of it here), and k1 predicts."""
    k1 = -0.2
    data, rvec, tvec = _opencv_views(k1, 4, 6, 0.0, 0)
    loo = _camera_loo(data, 0.1, ["radial_k1"])
    final, without = loo["models"]["final model"], loo["models"]["without radial_k1"]
    assert final["rms"] < 1e-6
    expected = _linear_prediction(k1, rvec, tvec)
    got = [without["per_group"][str(v + 1)]["rms"] for v in range(4)]
    assert min(expected) > 0.3  # px: what the intrinsics cannot absorb of k1
    assert got == pytest.approx(expected, rel=2e-3)
    assert without["rms"] == pytest.approx(np.sqrt(np.mean(np.square(expected))), rel=2e-3)
    # the same at half the k1: the prediction error scales with |k1| (first order)
    half = _camera_loo(_opencv_views(k1 / 2, 4, 6, 0.0, 0)[0], 0.1, ["radial_k1"])
    assert half["models"]["without radial_k1"]["rms"] == pytest.approx(without["rms"] / 2,
                                                                       rel=2e-3)
    assert without["verdict"] == "predicts"
    assert without["test"]["worse_without"] == 4


def test_an_effect_the_data_do_not_carry_does_not_predict() -> None:
    """k1 = -0.2 and 0.2 px of noise; the model is given k1 and a skew the camera does not
    have (gamma = 0): k1 predicts, the skew does not; the tables name both."""
    data, _, _ = _opencv_views(-0.2, 5, 6, 0.2, 3)
    loo = _camera_loo(data, 0.2, ["radial_k1", "skew"])
    assert loo["models"]["without radial_k1"]["verdict"] == "predicts"
    assert loo["models"]["without skew"]["verdict"] == "does not predict"
    text = format_leave_one_out(loo, [{"name": "skew", "label": "significant, negligible"}])
    assert "does not predict / significant, negligible" in text
    assert "pose is fitted" not in text and "own parameters" in text
    md = "\n".join(markdown_leave_one_out(loo))
    assert md.count("\n| ") == (1 + 5 + 2) + (1 + 2)  # header, views, pooled; header, effects


def test_prediction_test_is_scipys_paired_t_test() -> None:
    rng = np.random.default_rng(7)
    with_, without = rng.gamma(2.0, size=6), rng.gamma(2.0, size=6) + 0.3
    ours = prediction_test(without - with_, 0.05)
    ref = stats.ttest_rel(without, with_, alternative="greater")
    assert ours["t"] == pytest.approx(ref.statistic, rel=1e-12)
    assert ours["p_value"] == pytest.approx(ref.pvalue, rel=1e-12)
    assert ours["verdict"] == ("predicts" if ref.pvalue < 0.05 else "does not predict")
    assert prediction_test([0.2, 0.2, 0.2], 0.01)["verdict"] == "predicts"
    assert prediction_test([-0.1, -0.1], 0.01)["verdict"] == "does not predict"


NULL_SETS = 200


@pytest.mark.slow
def test_the_rule_rarely_calls_an_absent_effect_predictive(figures) -> None:
    """200 sets of five views (36 corners each, cv2.projectPoints, k1 = -0.2, 0.2 px of
    noise, seeds fixed), the final model given k1, k2 and the tangential terms, the last two
    absent from the data. Each absent effect is called "predicts" at level 0.01 and 0.05 in
    no more sets than the binomial allows at that rate (one-sided at 0.001: 8 and 21 of 200);
    the two-sided binomial p-value of each count against its level is recorded (the rule is
    conservative by design: an absent effect fitted to noise costs prediction accuracy, so its
    rises centre below 0). k1, which the data carry, predicts in more than half the sets at
    0.01 (a rule that never says "predicts" fails): not nearly all, because the model without
    k1 keeps k2, whose r^4 stands in for much of k1's r^2, and 5 views give t 4 dof."""
    p_values: dict[str, list[float]] = {"radial_k1": [], "radial_k2": [], "tangential": []}
    for seed in range(NULL_SETS):
        data, _, _ = _opencv_views(-0.2, 5, 6, 0.2, 1000 + seed)
        loo = _camera_loo(data, 0.2, list(p_values))
        for effect, found in p_values.items():
            found.append(loo["models"][f"without {effect}"]["test"]["p_value"])
    for effect in ("radial_k2", "tangential"):
        p = np.array(p_values[effect])
        for level in (0.01, 0.05):
            count = int(np.sum(p < level))
            limit = int(stats.binom.ppf(1 - 1e-3, NULL_SETS, level))
            figures.record(f"absent.{effect}.predicts_at_{level:g}", count / NULL_SETS,
                           high=limit / NULL_SETS)
            figures.record(f"absent.{effect}.two_sided_p_at_{level:g}",
                           stats.binomtest(count, NULL_SETS, level).pvalue)
            assert count <= limit, (effect, level, count)
        figures.record(f"absent.{effect}.median_p", float(np.median(p)))
    present = float(np.mean(np.array(p_values["radial_k1"]) < 0.01))
    figures.record("present.radial_k1.predicts", present, 0.5)
    assert present > 0.5
