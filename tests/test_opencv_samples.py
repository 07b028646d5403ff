"""A second real calibration set: OpenCV's sample chessboard photographs (corners in
tests/data/camera/opencv_left_*.csv, source in tests/data/camera/README.md). The workflow
rejects the pinhole, and its camera is OpenCV's own: ``cv2.calibrateCamera`` on the same
corners with the same camera model."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from montecarlo.cli import main
from montecarlo.discrepancy import camera_effects as cam
from montecarlo.discrepancy.fit import fit_model
from montecarlo.io.camera_csv import CameraData, read_camera_csv

cv2 = pytest.importorskip("cv2")

DATA = Path(__file__).parent / "data" / "camera"
MODEL, VIEWS = DATA / "opencv_left_model.csv", DATA / "opencv_left_views.csv"
IMAGE_SIZE = (640, 480)


def opencv_calibration(data: CameraData, effects: list[str]) -> dict[str, dict[str, float]]:
    """``cv2.calibrateCameraExtended`` of ``data`` with the camera model of the pinhole plus
    ``effects`` (square pixels unless ``aspect_ratio``; no skew: OpenCV has none), iterated to
    convergence: each parameter's value and OpenCV's standard deviation, in our names."""
    obj = [np.column_stack([data.points[data.view == v], np.zeros(np.sum(data.view == v))])
           .astype(np.float32) for v in range(len(data.views))]
    img = [data.pixels[data.view == v].astype(np.float32).reshape(-1, 1, 2)
           for v in range(len(data.views))]
    flags = 0
    for effect, flag in (("aspect_ratio", cv2.CALIB_FIX_ASPECT_RATIO),
                         ("radial_k1", cv2.CALIB_FIX_K1), ("radial_k2", cv2.CALIB_FIX_K2),
                         ("radial_k3", cv2.CALIB_FIX_K3),
                         ("tangential", cv2.CALIB_ZERO_TANGENT_DIST)):
        if effect not in effects:
            flags |= flag
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 1000, 1e-15)
    _, K, dist, _, _, sd, *_ = cv2.calibrateCameraExtended(
        obj, img, IMAGE_SIZE, np.eye(3), np.zeros(5), flags=flags, criteria=criteria)
    sd = sd.ravel()
    values = {"f": K[0, 0], "cx": K[0, 2], "cy": K[1, 2], "k1": dist[0, 0], "k2": dist[0, 1],
              "p1": dist[0, 2], "p2": dist[0, 3], "k3": dist[0, 4]}
    sds = {"f": sd[0], "cx": sd[2], "cy": sd[3], "k1": sd[4], "k2": sd[5], "p1": sd[6],
           "p2": sd[7], "k3": sd[8]}
    return {k: {"value": float(values[k]), "sd": float(sds[k])} for k in values}


def without(data: CameraData, flagged: set[str]) -> CameraData:
    """``data`` without the corners named ``VIEW/ID`` in ``flagged``."""
    keep = np.array([f"{data.views[v]}/{i}" not in flagged
                     for v, i in zip(data.view, data.point_id, strict=True)])
    return CameraData(data.views, tuple(np.array(data.point_id)[keep]), data.view[keep],
                      data.points[keep], data.pixels[keep], data.rows[keep], data.unit)
