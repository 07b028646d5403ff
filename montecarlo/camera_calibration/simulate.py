"""Synthetic views of a planar target: a grid of points, tilted poses, pixel noise.

The layout imitates Zhang's data set (MSR-TR-98-71, section 5): a target about 17 cm square
seen from about 0.33 m by a camera of f = 830 px on a 640 x 480 image, tilted by up to 30 deg
about axes in the target plane, so that the points fill most of the image.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from montecarlo.camera_calibration.model import project

FloatArray = NDArray[np.float64]

DEFAULT_CAMERA = {"f": 830.0, "cx": 320.0, "cy": 240.0}
"""Intrinsics of the synthetic camera [px]."""


def target_grid(n: int = 8, pitch: float = 0.02) -> FloatArray:
    """(n*n, 2) points of a square grid, ``pitch`` apart [m], centred on the origin."""
    g = (np.arange(n) - (n - 1) / 2.0) * pitch
    X, Y = np.meshgrid(g, g, indexing="xy")
    return np.column_stack([X.ravel(), Y.ravel()])


def standard_poses(n_views: int = 5, distance: float = 0.33, tilt_deg: float = 30.0
                   ) -> tuple[FloatArray, FloatArray]:
    """(rvec, tvec), each (V, 3): the first view faces the camera, the others tilted by
    ``tilt_deg`` about axes in the target plane at azimuths spread over half a turn, the
    target centre on the optical axis at ``distance`` [m]."""
    tilt = math.radians(tilt_deg)
    r, t = [], []
    for v in range(n_views):
        if v == 0:
            r.append([0.0, 0.0, 0.1])
        else:
            az = math.pi * (v - 1) / max(1, n_views - 1)
            r.append([tilt * math.cos(az), tilt * math.sin(az), 0.1 * v])
        t.append([0.0, 0.0, distance])
    return np.array(r), np.array(t)


def simulate(points: FloatArray, truth: Mapping[str, float], rvec: FloatArray,
             tvec: FloatArray, sigma: float, rng: int | np.random.Generator | None = None
             ) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]:
    """Every point in every view: (model points (n, 2) [m], pixels (n, 2) [px], view (n,)).

    Pixels are :func:`montecarlo.camera_calibration.model.project` of ``truth`` (intrinsics and
    distortion; missing ones zero) plus independent normal noise of ``sigma`` per coordinate.
    """
    rng = np.random.default_rng(rng)
    V = rvec.shape[0]
    pts = np.tile(points, (V, 1))
    view = np.repeat(np.arange(V), points.shape[0])
    pixels = project(truth, rvec, tvec, pts, view)
    return pts, pixels + sigma * rng.standard_normal(pixels.shape), view
