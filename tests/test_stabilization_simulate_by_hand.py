"""Seed 001's simulator: batches held by one input only (the compensation's fields too, and the
compiled target view against the numpy matrices), the noise of interval-mean rows, and the
interval means of a carrier at rest.

A batch of runs is the broadcast of the leading shapes of all inputs (:func:`simulate`'s
docstring): each run of a batch held by one input alone must be the run of that input's
element with the others as given (noise-free, so that no random draw depends on the batch).
The values of single runs are checked against closed forms in ``test_stabilization.py`` and
``test_stabilization_by_hand.py``; here only the batch is at stake, on the compiled path, the
literal path (``reference=True``) and the numpy camera chain (inner-gimbal mount, target off
the centre).
"""

import dataclasses

import numpy as np
import pytest

from montecarlo.geometry.camera import Camera
from montecarlo.seed001 import kinematics as kin
from montecarlo.seed001 import simulate as sim

D = np.pi / 180.0
SETUP = sim.Setup(duration=2.0, rate=25.0, aim_azimuth=20 * D, aim_pitch=10 * D,
                  camera=Camera.from_degrees(4.0, 3.0, 1280, 960), image_noise=0.0)
AMPLITUDE = np.array([3.0, 2.0, 4.0]) * D
FREQUENCY = np.array([0.3, 0.5, 0.4])
PHASE = np.array([0.2, 1.0, 2.5])
DELTA_G = np.array([0.5, -0.3, 0.7]) * D
DELTA_P = np.array([0.4, 0.6, -0.6]) * D
BIAS = np.array([10.0, -20.0, 5.0]) * D / 3600.0
SCALE = np.array([[1.0], [-0.5], [2.0]])
"""The three runs of a batch: the input times 1, -0.5 and 2."""


def _run(setup, reference, amplitude=AMPLITUDE, frequency=FREQUENCY, phase=PHASE,
         delta_g=DELTA_G, delta_p=DELTA_P, bias=BIAS, compensation=None):
    rock = kin.Rocking(amplitude, frequency, phase)
    return sim.simulate(rock, setup, delta_g, delta_p, bias, rng=1, reference=reference,
                        compensation=compensation)


SETUPS = {
    "patent-point-centre": SETUP,
    "inner-mean-off": dataclasses.replace(SETUP, mount="inner-gimbal",
                                          gyro_sampling="interval-mean", target_px=(60.0, -40.0)),
}


@pytest.mark.parametrize("reference", [False, True])
@pytest.mark.parametrize("name", list(SETUPS))
@pytest.mark.parametrize("key", ["amplitude", "frequency", "phase", "delta_g", "delta_p",
                                 "bias"])
def test_a_batch_in_one_input_is_the_runs_of_its_elements(key, name, reference):
    setup = SETUPS[name]
    base = {"amplitude": AMPLITUDE, "frequency": FREQUENCY, "phase": PHASE,
            "delta_g": DELTA_G, "delta_p": DELTA_P, "bias": BIAS}[key]
    values = base * SCALE if key != "frequency" else base * np.abs(SCALE)
    batch = _run(setup, reference, **{key: values})
    n = setup.times.size
    assert batch.gyro.shape == (3, n, 3) and batch.los_px.shape == (3, n, 2)
    assert batch.eta.shape == batch.eps.shape == batch.los_error.shape == (3, n)
    for i in range(3):
        one = _run(setup, reference, **{key: values[i]})
        for field in ("gyro", "eta", "eps", "los_px", "los_error"):
            np.testing.assert_allclose(getattr(batch, field)[i], getattr(one, field),
                                       rtol=1e-12, atol=1e-12, err_msg=field)


@pytest.mark.parametrize("reference", [False, True])
@pytest.mark.parametrize("held_by", ["angles", "gyro_bias", "delta_gz", "delta_g"])
def test_a_batch_in_one_compensation_field_or_beside_it(held_by, reference):
    """A compensated loop whose batch of three is held by one field of the compensation alone
    (``delta_gz`` with the inner-gimbal mount, where it is used), or by ``delta_g`` with a
    single compensation: each run is that of its element."""
    setup = SETUP if held_by != "delta_gz" else SETUPS["inner-mean-off"]
    fields = {"angles": np.array([0.4, 0.5, -0.3, -1.3]) * D, "gyro_bias": BIAS,
              "delta_gz": 0.7 * D}
    batch_inputs = {"delta_g": DELTA_G * SCALE} if held_by == "delta_g" else {}
    if held_by in fields:
        fields[held_by] = fields[held_by] * (SCALE if held_by != "delta_gz" else SCALE[:, 0])
    mount = setup.mount

    def element(i):
        return {k: v[i] if k == held_by else v for k, v in fields.items()}

    batch = _run(setup, reference, compensation=sim.Compensation(**fields, mount=mount),
                 **batch_inputs)
    assert batch.eta.shape == (3, setup.times.size)
    for i in range(3):
        one = _run(setup, reference, compensation=sim.Compensation(**element(i), mount=mount),
                   **{k: v[i] for k, v in batch_inputs.items()})
        np.testing.assert_allclose(batch.eta[i], one.eta, rtol=0, atol=1e-12)
        np.testing.assert_allclose(batch.los_px[i], one.los_px, rtol=0, atol=1e-9)


def test_interval_mean_rows_hold_the_noise_the_loop_integrated():
    """A carrier at rest with the gimbal at zero: eq. (4) gives eta' = -w_z, eps' = -w_x, and
    the noise is held over each interval; an interval-mean row k >= 1 is the mean over
    ``(t_{k-1}, t_k]``, i.e. the noise the loop used over that interval, so the gimbal angles
    are minus the running sum of rows 1, 2, ... times h (row 0 holds an earlier interval)."""
    rate, density = 37.0, 2e-4
    setup = sim.Setup(duration=5.0, rate=rate, image_noise=0.0, gyro_noise=density,
                      gyro_sampling="interval-mean")
    still = kin.Rocking(np.zeros(3), [0.1, 0.1, 0.1])
    run = sim.simulate(still, setup, np.zeros((20, 3)), 0.0, rng=11)
    h = 1.0 / rate
    for angle, axis in ((run.eta, 2), (run.eps, 0)):
        walk = -h * np.concatenate([np.zeros((20, 1)), np.cumsum(run.gyro[:, 1:, axis], -1)], -1)
        # the walk is ~ density sqrt(5 s) = 4.5e-4 rad; eq. (4)'s second-order terms ~ 2e-7
        np.testing.assert_allclose(angle, walk, rtol=0, atol=4e-6)


def test_interval_means_of_a_still_carrier_are_the_bias_and_none_by_default():
    """Eq. (1) on a carrier at rest: the IMU measures its bias only, whatever its installation
    angles, so every interval mean is the bias, and zero without one."""
    still = kin.Rocking(np.zeros(3), [0.1, 0.1, 0.1], 0.0)
    t = np.arange(5) / 10.0
    np.testing.assert_array_equal(sim.interval_mean_rate(still, t, 0.1, DELTA_G), np.zeros((5, 3)))
    np.testing.assert_allclose(sim.interval_mean_rate(still, t, 0.1, DELTA_G, BIAS),
                               np.broadcast_to(BIAS, (5, 3)), rtol=1e-12)


@pytest.mark.parametrize("held_by", ["carrier", "eta", "eps", "delta_p"])
def test_compiled_target_view_takes_the_batch_from_whichever_input_has_it(held_by):
    """``u_k = C_n^c(k) c_0`` with ``c_0`` row y of ``C_n^c(0)`` (the LOS at t = 0) and
    ``C_n^c = camera_matrix(eta, eps, delta_p) C_n^b`` (eq. (2), the carrier's attitude from its
    Euler angles), written with the numpy matrices, for a batch of three in one input only."""
    t = SETUP.times
    g = np.random.default_rng(6)
    rock = kin.Rocking(AMPLITUDE * (SCALE if held_by == "carrier" else 1.0), FREQUENCY, PHASE)
    eta = 0.3 + 0.1 * np.sin(t) * (SCALE if held_by == "eta" else 1.0)
    eps = 0.2 - 0.1 * np.cos(t) * (SCALE if held_by == "eps" else 1.0)
    delta_p = DELTA_P * (SCALE if held_by == "delta_p" else 1.0) + g.normal(0, 1e-3, 3)
    got = sim.target_view_compiled(sim.carrier_trig(rock.angles(t)), eta, eps, delta_p)
    C_nc = kin.camera_matrix(eta, eps, np.asarray(delta_p)[..., None, :]) @ rock.attitude(t)
    expected = C_nc @ C_nc[..., :1, 1, :, None]
    assert got.shape == (3, t.size, 3)
    np.testing.assert_allclose(got, np.broadcast_to(expected[..., 0], got.shape), rtol=0,
                               atol=1e-13)
