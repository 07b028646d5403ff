"""A second real calibration set: OpenCV's sample chessboard photographs (corners in
tests/data/camera/opencv_left_*.csv, source in tests/data/camera/README.md), run through
``diagnose camera --pixel-sigma-px auto --leave-one-out`` as a user would, against OpenCV
itself on the same corners: ``cv2.calibrateCamera`` with the camera model the workflow ends
with, and OpenCV's leave-one-view-out cross-validation (calibrate on eleven views, fit the
twelfth's pose by ``cv2.solvePnP`` with the intrinsics held, project it)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy import stats

from montecarlo.cli import main
from montecarlo.io.camera_csv import CameraData, read_camera_csv

cv2 = pytest.importorskip("cv2")

pytestmark = pytest.mark.slow  # one diagnosis with leave one view out: ~40 s of CPU

DATA = Path(__file__).parent / "data" / "camera"
MODEL, VIEWS = DATA / "opencv_left_model.csv", DATA / "opencv_left_views.csv"
IMAGE_SIZE = (640, 480)
FloatArray = NDArray[np.float64]
ALPHA = 0.01  # the command's default
NAMED = ["radial_k1", "radial_k2", "tangential"]
CRITERIA = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 1000, 1e-15)
FIXED = {"radial_k1": cv2.CALIB_FIX_K1, "radial_k2": cv2.CALIB_FIX_K2,
         "radial_k3": cv2.CALIB_FIX_K3, "tangential": cv2.CALIB_ZERO_TANGENT_DIST}
"""OpenCV's flag that leaves each candidate out of its camera model."""
TOLERANCE_SD = 0.01
"""Largest difference from OpenCV's value, in OpenCV's standard deviations: both fits minimise
the same sum of squares, so they differ only by where each optimiser stops."""


def _flags(effects: list[str]) -> int:
    """OpenCV's camera model of the pinhole (square pixels, no skew) plus ``effects``."""
    flags = cv2.CALIB_FIX_ASPECT_RATIO
    for effect, flag in FIXED.items():
        if effect not in effects:
            flags |= flag
    return flags


def _opencv_views(data: CameraData, views: list[int]) -> tuple[list[Any], list[Any]]:
    obj = [np.column_stack([data.points[data.view == v], np.zeros(np.sum(data.view == v))])
           for v in views]
    img = [data.pixels[data.view == v].reshape(-1, 1, 2) for v in views]
    return obj, img


def opencv_calibration(data: CameraData, effects: list[str], views: list[int] | None = None
                       ) -> dict[str, Any]:
    """``cv2.calibrateCameraExtended`` of ``views`` (all by default) with the pinhole plus
    ``effects``: camera matrix, distortion, standard deviations, sum of squared residuals
    [px²], number of image coordinates and of parameters."""
    views = list(range(len(data.views))) if views is None else views
    obj, img = _opencv_views(data, views)
    rms, K, dist, _, _, sd, *_ = cv2.calibrateCameraExtended(
        [o.astype(np.float32) for o in obj], [i.astype(np.float32) for i in img], IMAGE_SIZE,
        np.eye(3), np.zeros(5), flags=_flags(effects), criteria=CRITERIA)
    n = 2 * sum(len(o) for o in obj)
    free = 3 + sum({"radial_k1": 1, "radial_k2": 1, "radial_k3": 1, "tangential": 2}[e]
                   for e in effects) + 6 * len(views)
    sd, dist = sd.ravel(), dist.ravel()
    values = {"f": K[0, 0], "cx": K[0, 2], "cy": K[1, 2], "k1": dist[0], "k2": dist[1],
              "p1": dist[2], "p2": dist[3]}
    # OpenCV's order: f_x, f_y, c_x, c_y, k1, k2, p1, p2, k3; with FIX_ASPECT_RATIO f_y is
    # the free one (f_x follows it), f_x's deviation is 0
    sds = {"f": sd[1], "cx": sd[2], "cy": sd[3], "k1": sd[4], "k2": sd[5], "p1": sd[6],
           "p2": sd[7]}
    return {"K": K, "dist": dist, "values": values, "sd": sds,
            "ssr": rms**2 * n / 2, "n": n, "parameters": free}


def opencv_prediction(data: CameraData, effects: list[str], left: int) -> FloatArray:
    """Residuals [px] of view ``left`` predicted by OpenCV: the camera calibrated on every
    other view, the left-out view's pose fitted to it alone (``solvePnP`` refined by
    Levenberg-Marquardt), its corners projected."""
    cal = opencv_calibration(data, effects, [v for v in range(len(data.views)) if v != left])
    (obj,), (img,) = _opencv_views(data, [left])
    K, dist = cal["K"], cal["dist"]
    _, rvec, tvec = cv2.solvePnP(obj, img, K, dist)
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, dist, rvec, tvec, CRITERIA)
    projected, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
    return np.asarray(img.reshape(-1, 2) - projected.reshape(-1, 2), dtype=np.float64)


@pytest.fixture(scope="module")
def data() -> CameraData:
    return read_camera_csv(MODEL, VIEWS)


@pytest.fixture(scope="module")
def diagnosis(tmp_path_factory) -> dict[str, Any]:
    """The command's JSON, as a user runs it."""
    out = tmp_path_factory.mktemp("opencv") / "diagnosis.json"
    code = main(["diagnose", "camera", str(MODEL), str(VIEWS), "--pixel-sigma-px", "auto",
                 "--leave-one-out", "--quiet", "--json", str(out)])
    assert code == 0
    return dict(json.loads(out.read_text()))


def test_the_pinhole_is_rejected_as_opencv_fits_it(data, diagnosis, figures):
    """The base model's rms is OpenCV's pinhole (f_x = f_y, no distortion) rms, and the
    global test rejects it."""
    pinhole = opencv_calibration(data, [])
    rms = np.sqrt(pinhole["ssr"] / pinhole["n"])
    before = diagnosis["gap"]["before"]
    figures.record("pinhole.rms_px", before["rms"], rms - 1e-3, rms + 1e-3, "px")
    figures.record("pinhole.chi2_red", before["chi2_red"])
    assert before["rms"] == pytest.approx(rms, abs=1e-3)
    assert before["p_value"] < ALPHA


def test_k1_k2_and_tangential_named_nothing_flagged(diagnosis):
    assert [e["name"] for e in diagnosis["named_effects"]] == NAMED
    assert diagnosis["outliers"] == [] and not diagnosis["unexplained"]
    assert diagnosis["gap"]["after"]["p_value"] > ALPHA


def test_the_final_camera_is_opencvs_with_the_same_model(data, diagnosis, figures):
    """Each intrinsic and distortion value within 0.01 of OpenCV's standard deviation of
    OpenCV's value; each standard error within 2 % of OpenCV's (ours at the first pass's
    sigma estimate, OpenCV's at its residual variance)."""
    cv = opencv_calibration(data, NAMED)
    camera = diagnosis["camera"]
    ours = {"f": camera["alpha"], "cx": camera["u0"], "cy": camera["v0"],
            **{k: camera[k] for k in ("k1", "k2", "p1", "p2")}}
    for name, value in cv["values"].items():
        sd = cv["sd"][name]
        off = (ours[name]["value"] - value) / sd
        figures.record(f"final.{name}", ours[name]["value"])
        figures.record(f"final.{name}.off_opencv_sd", off, -TOLERANCE_SD, TOLERANCE_SD)
        assert abs(off) < TOLERANCE_SD, (name, ours[name]["value"], value, sd)
        assert ours[name]["stderr"] == pytest.approx(sd, rel=0.02), name
    assert camera["beta"]["value"] == camera["alpha"]["value"]


def test_the_estimated_sigma_is_opencvs_residual_sigma(data, diagnosis, figures):
    """sigma-hat = sqrt(SSR / (n - p)) of OpenCV's fit with the same model; its 95 % interval
    sigma-hat * sqrt(dof / chi2 quantiles) (scipy)."""
    cv = opencv_calibration(data, NAMED)
    dof = cv["n"] - cv["parameters"]
    sigma = np.sqrt(cv["ssr"] / dof)
    est = diagnosis["noise_estimate"]["estimates"][0]
    assert est["dof"] == dof == 1217
    figures.record("sigma_hat_px", est["value"], sigma * 0.999, sigma * 1.001, "px")
    figures.record("sigma_hat_low_px", est["low"], unit="px")
    figures.record("sigma_hat_high_px", est["high"], unit="px")
    assert est["value"] == pytest.approx(sigma, rel=1e-3)
    low = sigma * np.sqrt(dof / stats.chi2.ppf(0.975, dof))
    high = sigma * np.sqrt(dof / stats.chi2.ppf(0.025, dof))
    assert (est["low"], est["high"]) == pytest.approx((low, high), rel=1e-3)


def test_leave_one_view_out_is_opencvs_cross_validation(data, diagnosis, figures):
    """Every left-out view's prediction RMS under each model is OpenCV's to 0.5 %, and the
    t of each effect's rule is scipy's one-sided paired t test on OpenCV's per-view mean
    squares: k1 predicts, k2 and the tangential terms do not at alpha = 0.01."""
    loo = diagnosis["leave_one_out"]
    views = list(range(len(data.views)))
    assert loo["groups"] == list(data.views)
    mean_square = {}
    for label, model in loo["models"].items():
        effects = model["effects"]
        ms = []
        for v in views:
            r = opencv_prediction(data, effects, v)
            rms = float(np.sqrt(np.mean(r**2)))
            ours = model["per_group"][data.views[v]]["rms"]
            assert ours == pytest.approx(rms, rel=5e-3), (label, data.views[v], ours, rms)
            ms.append(float(np.mean(r**2)))
        mean_square[label] = np.array(ms)
        figures.record(f"loo.{label.replace(' ', '_')}.rms_px", model["rms"], unit="px")
    verdicts = {}
    for effect in NAMED:
        test = loo["models"][f"without {effect}"]["test"]
        ref = stats.ttest_rel(mean_square[f"without {effect}"], mean_square["final model"],
                              alternative="greater")
        figures.record(f"loo.{effect}.t", test["t"], ref.statistic - 0.05, ref.statistic + 0.05)
        figures.record(f"loo.{effect}.p", test["p_value"])
        figures.record(f"loo.{effect}.worse_without", test["worse_without"])
        assert test["t"] == pytest.approx(ref.statistic, abs=0.05), effect
        assert test["verdict"] == ("predicts" if ref.pvalue < ALPHA else "does not predict")
        verdicts[effect] = test["verdict"]
    assert verdicts == {"radial_k1": "predicts", "radial_k2": "does not predict",
                        "tangential": "does not predict"}
