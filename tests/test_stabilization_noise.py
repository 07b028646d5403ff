"""Noise statistics of the seed 001 simulator against the densities it is given.

A white gyro noise of density ``N`` [rad/s/√Hz] sampled at ``rate`` [Hz] has per-sample standard
deviation ``σ = N √rate`` (its variance is the density squared times the bandwidth ``rate``;
equivalently an angle random walk ``N`` [rad/√s] gives ``N²·h`` of angle variance per step
``h = 1/rate``, i.e. a rate of variance ``N²/h``). The rate used here, 37 Hz, is not the default
100 Hz, so ``N·√rate`` and ``N/√rate`` differ by a factor 37 and a wrong power of the rate
cannot hide in a default.

Tolerances: ``n`` independent zero-mean Gaussian samples of variance σ² have
``Σ x² / σ² ~ χ²_n``; the test accepts the ratio ``mean(x²)/σ²`` between the χ²_n quantiles at
1e-6 and 1 - 1e-6 (divided by n).
"""

from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from montecarlo.geometry.camera import Camera
from montecarlo.seed001 import kinematics as kin
from montecarlo.seed001 import simulate as sim

D = np.pi / 180.0
RATE = 37.0
"""A non-default sample rate [Hz]."""
DENSITY = 2e-4
"""Gyro white-noise density [rad/s/√Hz]."""
STILL = kin.Rocking(np.zeros(3), [0.1, 0.1, 0.1])
"""A carrier at rest: the gimbal then moves only by the noise the loop integrates."""
CAMERA = Camera.from_degrees(4.0, 3.0, 1280, 960)
"""A non-square camera."""


def _chi2_band(n: int, p: float = 1e-6) -> tuple[float, float]:
    """Bounds of ``mean(x²)/σ²`` for n standard Gaussian samples, two-sided probability p."""
    lo, hi = stats.chi2.ppf([p, 1.0 - p], n)
    return lo / n, hi / n


def _pair(sampling: str, duration: float = 20.0, batch: int = 4):
    """One noisy batch of runs and the same runs without noise (the noise is the difference)."""
    setup = sim.Setup(duration=duration, rate=RATE, aim_azimuth=15 * D, aim_pitch=-10 * D,
                      camera=CAMERA, image_noise=0.25, gyro_noise=DENSITY,
                      gyro_sampling=sampling)
    rock = kin.Rocking(np.full(3, 2 * D), [0.21, 0.33, 0.27], [0.0, 1.0, 2.0])
    delta_g = np.tile(np.array([0.3, -0.2, 0.4]) * D, (batch, 1))
    noisy = sim.simulate(rock, setup, delta_g, [0.2 * D, 0.1 * D, -0.3 * D], rng=5)
    clean = sim.simulate(rock, replace(setup, gyro_noise=0.0, image_noise=0.0),
                         delta_g, [0.2 * D, 0.1 * D, -0.3 * D], rng=5)
    return setup, noisy, clean


@pytest.mark.parametrize("sampling", ["point", "interval-mean"])
def test_gyro_noise_per_sample_is_density_times_root_rate(sampling):
    """σ per gyro row = N·√rate = 2e-4·√37 = 1.2166e-3 rad/s at 37 Hz (by hand); the bug
    ``N/√rate`` would give 3.29e-5, 37 times smaller. 4 runs x 741 rows x 3 axes = 8892
    samples: the ratio band is [0.930, 1.073]."""
    _, noisy, clean = _pair(sampling)
    noise = noisy.gyro - clean.gyro
    sigma = DENSITY * np.sqrt(RATE)
    assert sigma == pytest.approx(1.2166e-3, rel=1e-4)
    lo, hi = _chi2_band(noise.size)
    assert lo < np.mean(noise**2) / sigma**2 < hi
    # white: neighbouring rows uncorrelated (|r| < 5 / sqrt(n) for n pairs)
    a, b = noise[:, :-1, :].ravel(), noise[:, 1:, :].ravel()
    assert abs(np.corrcoef(a, b)[0, 1]) < 5.0 / np.sqrt(a.size)


def test_image_noise_per_axis_is_the_stated_sigma():
    """The image rows carry white noise of the stated σ [px] on each axis, whatever the
    camera's aspect (4 x 3 deg, 1280 x 960 px)."""
    setup, noisy, _ = _pair("point")
    noise = noisy.los_px - noisy.los_px_true
    lo, hi = _chi2_band(noise[..., 0].size)
    for axis in (0, 1):
        assert lo < np.mean(noise[..., axis] ** 2) / setup.image_noise**2 < hi


def test_the_loop_integrates_the_recorded_noise():
    """A carrier at rest with the gimbal at zero: eq. (4) gives η' = -w_z, ε' = -w_x, so the
    gimbal angles are minus the running sum of the recorded noise times h (the noise is held
    over each interval), and their variance after time T is N²·T (an angle random walk):
    N²·T = (2e-4)²·20 s = 8e-7 rad²."""
    setup = sim.Setup(duration=20.0, rate=RATE, camera=CAMERA, image_noise=0.0,
                      gyro_noise=DENSITY)
    run = sim.simulate(STILL, setup, np.zeros((200, 3)), 0.0, rng=11)
    h = 1.0 / RATE
    walk_z = -h * np.concatenate([np.zeros((200, 1)), np.cumsum(run.gyro[:, :-1, 2], -1)], -1)
    walk_x = -h * np.concatenate([np.zeros((200, 1)), np.cumsum(run.gyro[:, :-1, 0], -1)], -1)
    # the walks are ~ N·√T = 9e-4 rad; eq. (4)'s second-order terms (ε·w_y in η', η·w_y in ε')
    # add ~ (9e-4)² ~ 1e-6 rad: 2e-5 is 2 % of the walk and far above them
    np.testing.assert_allclose(run.eta, walk_z, atol=2e-5)
    np.testing.assert_allclose(run.eps, walk_x, atol=2e-5)
    lo, hi = _chi2_band(run.eta.shape[0])
    expected = DENSITY**2 * setup.duration
    assert expected == pytest.approx(8e-7)
    assert lo < np.mean(run.eta[:, -1] ** 2) / expected < hi
