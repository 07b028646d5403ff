"""The collimation study's batched procedure fit against the literal trial-by-trial loop.

Tolerance, derived: both paths minimise the same cost from the same starts, and the cost itself
is known only to about 1e-11 of its value (residuals rounded to about 1e-16 rad on angles of
order 1 rad, whitened by 1/sigma, sigma about 3e-6 rad here). Each stops within 1e-10 of the
cost of the minimum (``batch_fit.COST_TOL``), i.e. within about 1e-4 sigma of it, so the two
solutions may differ by about 2e-4 sigma (2e-9 rad for a sigma of 1e-5 rad). We allow, on
every angle, 1e-3 of the trial's predicted sigma of the offset concerned (the larger of the two
for the other angles) or 1e-8 rad (2 milli-arc-seconds, 1/1000 of the 2 arc-second reading
noise), whichever is larger; 1e-4 relative on the predicted sigmas and 1e-5 on chi2_red and the
residual ratio (their changes at that distance are second order).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from montecarlo.seed003 import batch_fit as bf
from montecarlo.seed003 import procedure as pr
from montecarlo.seed003.model import Noise
from montecarlo.systems.collimation import METRICS, run_trials
from montecarlo.units import ARCSEC

ANGLE_TOL = 1e-8  # [rad]
SIGMA_TOL = 1e-3  # of the trial's predicted sigma
ANGLES = ("axis_az_error", "axis_el_error", "axis_error_angle", "residual_rms_after",
          "consistency_max_after")

BASE = dict(procedure=1, reference_rows=1, axis_az=300 * ARCSEC, axis_el=300 * ARCSEC,
            frame_heading=math.radians(30.0), n_azimuth=3, n_pitch=3,
            azimuth_span=math.radians(75.0), pitch_span=math.radians(30.0),
            mount_roll_sigma=math.radians(1.0), use_roll=1)


def _compare(params: dict, n: int, seed: int = 5) -> None:
    literal = run_trials(params, np.random.default_rng(seed), n, reference=True)
    batch = run_trials(params, np.random.default_rng(seed), n)
    assert np.isfinite(literal["axis_az_error"]).all()
    for key in METRICS:
        assert np.array_equal(np.isnan(literal[key]), np.isnan(batch[key])), key
    sigma = np.maximum(literal["axis_az_sigma"], literal["axis_el_sigma"])
    tol = {"axis_az_error": literal["axis_az_sigma"], "axis_el_error": literal["axis_el_sigma"]}
    for key in ANGLES:
        allowed = np.maximum(ANGLE_TOL, SIGMA_TOL * tol.get(key, sigma))
        assert (np.abs(batch[key] - literal[key]) <= allowed).all(), \
            (key, np.max(np.abs(batch[key] - literal[key]) / allowed))
    for key in ("axis_az_sigma", "axis_el_sigma"):
        np.testing.assert_allclose(batch[key], literal[key], rtol=1e-4, err_msg=key)
    for key in ("chi2_red", "residual_rms_ratio"):
        np.testing.assert_allclose(batch[key], literal[key], rtol=1e-5, err_msg=key)
    for k in ("axis_az", "axis_el"):  # equal, unless the error sits on the 2-sigma edge
        edge = np.abs(np.abs(literal[f"{k}_error"]) - 2 * literal[f"{k}_sigma"]) < ANGLE_TOL
        same = batch[f"{k}_within_2sigma"] == literal[f"{k}_within_2sigma"]
        assert (same | edge).all()


@pytest.mark.parametrize("variant", [
    dict(use_roll=1),                                     # rolls recorded, reference rows
    dict(use_roll=0),                                     # level mount assumed, mount rolls
    dict(reference_rows=0),                               # relative readings, roll recorded
    dict(reference_rows=0, use_roll=0, roll_mirror_left=1, mount_roll_sigma=0.0),
])
def test_batch_equals_literal(variant):
    _compare({**BASE, **variant}, 4)


@pytest.mark.parametrize("variant", [
    dict(use_roll=0, free_roll=1),                        # one roll per pointing fitted
    dict(reference_rows=0, use_roll=0, free_roll=1, roll_mirror_left=1),
])
def test_batch_equals_literal_free_roll(variant):
    """Four starts per trial and a local minimum per start: the same one is kept."""
    _compare({**BASE, **variant}, 3)


@pytest.mark.slow
def test_batch_equals_literal_paper_layout_many_trials():
    """The study's base point (5 + 5 mirrors, 18 deg reach), 64 trials, every roll variant."""
    base = {**BASE, "n_azimuth": 5, "n_pitch": 5, "pitch_span": math.radians(18.0)}
    for variant in (dict(use_roll=1), dict(use_roll=0), dict(use_roll=0, free_roll=1)):
        _compare({**base, **variant}, 64, seed=11)


@pytest.mark.parametrize("reference_rows", [True, False])
@pytest.mark.parametrize("with_roll", [True, False])
def test_simulate_block_draws_what_the_loop_draws(reference_rows, with_roll):
    """One standard_normal call per block equals the per-trial calls: the same readings."""
    az, el, _ = pr.procedure_layout()
    noise = Noise(2 * ARCSEC, 3 * ARCSEC, 4 * ARCSEC, 5 * ARCSEC, math.radians(1.0))
    rng = np.random.default_rng(7)
    loop = [pr.simulate_procedure(1e-3, -2e-3, az, el, noise, rng, side=-1.0,
                                  frame_heading=0.5, reference_rows=reference_rows,
                                  with_roll=with_roll) for _ in range(4)]
    block = bf.simulate_block(1e-3, -2e-3, az, el, noise, np.random.default_rng(7), 4,
                              side=-1.0, frame_heading=0.5, reference_rows=reference_rows,
                              with_roll=with_roll)
    for i, one in enumerate(loop):
        got = block.trial(i)
        for name in ("theodolite_az", "theodolite_el", "ins_az", "ins_el"):
            np.testing.assert_allclose(getattr(got, name), getattr(one, name), rtol=0,
                                       atol=1e-14, err_msg=name)
        assert (got.ins_roll is None) == (one.ins_roll is None)
        if with_roll:
            np.testing.assert_allclose(got.ins_roll, one.ins_roll, rtol=0, atol=1e-14)
        assert (got.center, got.roll_mirror) == (one.center, one.roll_mirror)


def test_too_few_mirrors_fail_every_trial_as_the_literal_path_does():
    """One azimuth and no pitch mirror cannot give gamma: every trial is NaN in both paths."""
    params = {**BASE, "n_azimuth": 1, "n_pitch": 0}
    for reference in (True, False):
        out = run_trials(params, np.random.default_rng(1), 3, reference=reference)
        assert np.isnan(out["axis_az_error"]).all()


def _procedure_study():
    from montecarlo.systems import study_from_dict

    return study_from_dict({
        "study": {"name": "batch-repro", "system": "collimation", "trials": 70, "seed": 9,
                  "block_size": 32},
        "params": {"procedure": 1, "n_azimuth": 3, "n_pitch": 3, "pitch_span_deg": 30.0,
                   "mount_roll_sigma_deg": 1.0},
        "sweep": [{"params.use_roll": [1, 0]}]}, "<test>")


@pytest.mark.parametrize("options", [dict(chunk_size=32), dict(chunk_size=96)])
def test_batched_study_is_identical_for_any_chunking(options):
    """Same study and seed: identical numbers whatever the chunks (blocks are fixed)."""
    from montecarlo.engine.runner import RunOptions, run_study

    study = _procedure_study()
    base = run_study(study, RunOptions(n_jobs=1, progress=False)).to_frame()
    other = run_study(study, RunOptions(n_jobs=1, progress=False, **options)).to_frame()
    assert base.equals(other)


@pytest.mark.slow
def test_batched_study_is_identical_on_two_workers():
    from montecarlo.engine.runner import RunOptions, run_study

    study = _procedure_study()
    base = run_study(study, RunOptions(n_jobs=1, progress=False)).to_frame()
    two = run_study(study, RunOptions(n_jobs=2, chunk_size=32, progress=False)).to_frame()
    assert base.equals(two)


def test_a_batch_stopped_by_a_matrix_goes_trial_by_trial(monkeypatch):
    """If one trial's matrix stops the batch, every trial is fitted by the literal path (on the
    batch's readings, equal to the loop's to rounding): the literal numbers, within tolerance."""
    calls = []

    def stop(*args, **kwargs):
        calls.append(1)
        raise np.linalg.LinAlgError("not positive definite")

    monkeypatch.setattr(bf, "_fit_from_starts", stop)
    _compare({**BASE, "use_roll": 1}, 3, seed=3)
    assert calls
