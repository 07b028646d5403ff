"""`run --reference` reaches the literal path of every system that has a faster one.

The collimation procedure fit has a batched path beside its literal trial-by-trial loop; the
two minimise the same cost and stop at slightly different points (within about 2e-4 sigma,
tests/test_collimation_batch.py), so their numbers are close but not bitwise equal. That
difference tells which path ran: a reference run must equal the literal loop bit for bit.
"""

from __future__ import annotations

import numpy as np

from montecarlo.engine.distributions import Streams
from montecarlo.engine.runner import RunOptions, run_study, uses_reference
from montecarlo.systems import study_from_dict
from montecarlo.systems.collimation import COLLIMATION, run_trials

STUDY = {
    "study": {"name": "reference_path", "system": "collimation", "trials": 6, "seed": 11,
              "block_size": 3},
    "params": {"procedure": 1, "reference_rows": 1, "axis_az_arcsec": 300.0,
               "axis_el_arcsec": 300.0, "frame_heading_deg": 30.0, "n_azimuth": 3,
               "n_pitch": 3, "azimuth_span_deg": 75.0, "pitch_span_deg": 30.0,
               "mount_roll_sigma_deg": 1.0, "use_roll": 1},
}
QUIET = dict(n_jobs=1, progress=False)


def test_the_reference_flag_reaches_the_literal_loop():
    study = study_from_dict(STUDY)
    prepared = study.points[0].prepared

    def streams() -> Streams:  # block 0 of point 0, from its start
        return Streams(11, 0, 0, True)

    literal = run_trials(prepared.params, streams().generator("trials"), 3, reference=True)
    batched = run_trials(prepared.params, streams().generator("trials"), 3)
    values, _ = COLLIMATION.simulate_block(prepared, streams(), 0, 3, reference=True)
    fast, _ = COLLIMATION.simulate_block(prepared, streams(), 0, 3)
    key = ("default", "axis_az_error")
    assert np.array_equal(values[key], literal["axis_az_error"])
    assert np.array_equal(fast[key], batched["axis_az_error"])
    assert not np.array_equal(literal["axis_az_error"], batched["axis_az_error"])


def test_a_reference_run_of_a_batched_system_says_so_and_differs_from_the_fast_run():
    study = study_from_dict(STUDY)
    assert not uses_reference(study, RunOptions(**QUIET))
    assert uses_reference(study, RunOptions(reference=True, **QUIET))
    fast = run_study(study, RunOptions(**QUIET))
    literal = run_study(study, RunOptions(reference=True, **QUIET))
    assert (fast.kernel, literal.kernel) == ("fast", "reference")
    a, b = (r.to_frame().set_index("metric")["mean"] for r in (fast, literal))
    assert not np.array_equal(a.to_numpy(), b.to_numpy())
    assert np.allclose(a["axis_az_error"], b["axis_az_error"], rtol=0, atol=0.01)  # [arcsec]


def test_a_system_with_one_path_runs_it_as_the_reference():
    air = study_from_dict({"study": {"name": "air", "system": "air", "trials": 4, "seed": 1}})
    assert uses_reference(air, RunOptions(**QUIET))
