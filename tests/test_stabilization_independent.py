"""The seed 001 estimator on recordings of a simulator written independently of it.

``tests/independent/stabilization_recording.py`` was written from the frames, the CSV format and
the patent only, without reading the project's simulator or estimator: a sum of sinusoids per
axis for the rocking, a quaternion integration by ``solve_ivp``, its own gimbal loop, encoder
quantisation, 1280 x 960 px over 4 x 3 deg. Its files are read as the command line reads them.
Criteria: each of delta_px, delta_gx, delta_gy, delta_z within 3 sigma and within
max(5 %, 0.01 deg) of the truth; over many runs about 95 % within 2 sigma.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from montecarlo.geometry.camera import Camera
from montecarlo.io.stabilization_csv import read_csv
from montecarlo.seed001.estimate import estimate
from tests.independent.stabilization_recording import (
    ARCMIN,
    DEG_PER_SQRT_H,
    simulate_recording,
    write_csv,
)

FOV_DEG, PIXELS, ARW, IMAGE_NOISE = (4.0, 3.0), (1280, 960), 0.02, 0.3


def _estimate(tmp_path, rng, mount, sampling, offset_px, duration=60.0):
    """One independent recording through its CSV file; truth and the estimate [rad]."""
    delta_g = rng.uniform(-30.0, 30.0, 3)
    delta_p = rng.uniform(-30.0, 30.0, 3)
    angle = rng.uniform(0.0, 2.0 * math.pi)
    target = offset_px * np.array([math.cos(angle), math.sin(angle)])
    rec = simulate_recording(delta_g_arcmin=delta_g, delta_p_arcmin=delta_p, mount=mount,
                             gyro_sampling=sampling, target_offset_px=tuple(target),
                             duration_s=duration, fov_deg=FOV_DEG, pixels=PIXELS, gyro_arw=ARW,
                             image_noise_px=IMAGE_NOISE, rng=rng)
    path = tmp_path / "run.csv"
    write_csv(path, rec)
    r = read_csv(path)
    camera = Camera(math.radians(FOV_DEG[0]), math.radians(FOV_DEG[1]), *PIXELS)
    est = estimate(r.t, r.gyro, r.eta, r.eps, r.los_px, camera, IMAGE_NOISE,
                   ARW * DEG_PER_SQRT_H, mount=mount, gyro_sampling=sampling)
    truth = np.array([delta_p[0], delta_g[0], delta_g[1], delta_p[2] - delta_g[2]]) * ARCMIN
    return truth, est.observable, est.sigma[:4]


def _check(truth, value, sigma):
    error = np.abs(value - truth)
    assert np.all(error <= 3.0 * sigma), (error / sigma, truth / ARCMIN)
    spec = np.maximum(0.05 * np.abs(truth), math.radians(0.01))
    assert np.all(error <= spec), (error / ARCMIN, truth / ARCMIN)


@pytest.mark.parametrize(("mount", "sampling", "offset"),
                         [("patent", "point", 0.0), ("inner-gimbal", "interval-mean", 300.0)])
def test_independent_recording_gives_the_angles(tmp_path, mount, sampling, offset):
    """One 20 s recording of each of two contrasting set-ups (fast version)."""
    truth, value, sigma = _estimate(tmp_path, np.random.default_rng(7), mount, sampling, offset,
                                    duration=20.0)
    _check(truth, value, sigma)


VARIANTS = [(m, s, o) for m in ("patent", "inner-gimbal") for s in ("point", "interval-mean")
            for o in (0.0, 300.0)]


@pytest.mark.slow
@pytest.mark.parametrize(("mount", "sampling", "offset"), VARIANTS)
def test_independent_recordings_every_variant(tmp_path, mount, sampling, offset):
    """A 60 s recording of every mount, sampling and target offset (centred, 300 px)."""
    truth, value, sigma = _estimate(tmp_path, np.random.default_rng(11), mount, sampling, offset)
    _check(truth, value, sigma)


@pytest.mark.slow
def test_sigma_is_honest_on_independent_recordings(tmp_path):
    """200 recordings over the eight variants (25 each): the four combinations within 2 sigma in
    0.93-0.97 of the 800 cases (binomial SD 0.8 % at p = 0.95, so the band is +-2.5 SD;
    correlations between the four combinations of one run widen it a little)."""
    rng = np.random.default_rng(2026)
    inside = []
    for i in range(200):
        mount, sampling, offset = VARIANTS[i % len(VARIANTS)]
        truth, value, sigma = _estimate(tmp_path, rng, mount, sampling, offset, duration=30.0)
        inside.append(np.abs(value - truth) <= 2.0 * sigma)
    fraction = float(np.mean(inside))
    print(f"within 2 sigma: {fraction:.3f}")
    assert 0.93 <= fraction <= 0.97
