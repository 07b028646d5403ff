"""Acceptance of the diagnosis at scale for seed 001: 1,000 null recordings from our simulator
and 1,000 from the second one, something named in at most 1.5 % (one-sided binomial test at
the suites' alpha; the detection family's rate is at most alpha = 1 %), as
:mod:`tests.test_large_data_acceptance` checks the other systems.

Recordings of 20 s at 50 Hz (1,001 samples, the length of the suites' other stabilization
diagnoses) from :func:`montecarlo.seed001.simulate.simulate` (mount, gyro sampling and a 0 or
300 px target in turn, each analysed with its own mount and sampling) and from
:mod:`tests.independent.stabilization_second` (its own scenario, installation angles within
±0.6°, diagnosed through ``montecarlo diagnose stabilization``; a named convention counts as
named). The length is chosen for time (a second or two a diagnosis, 1,000 of each in about 16
minutes on 2 shared cores): the null rate is a property of the tests at their alpha, whatever
the number of samples.

Slow: about half an hour on 2 cores.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from joblib import Parallel, delayed, parallel_config

from montecarlo.cli import main
from montecarlo.discrepancy import stabilization_effects as ste
from montecarlo.discrepancy.engine import diagnose
from montecarlo.seed001 import kinematics as kin
from montecarlo.seed001 import simulate as sim
from tests.test_large_data_acceptance import NULL_SETS, _null_share

pytestmark = pytest.mark.slow


def _sets_named(one_set, seed: int) -> int:
    """How many of :data:`NULL_SETS` sets ``one_set(seed, k)`` finds something named in; set k
    draws from its own seed (seed, k), so the count does not depend on the number of jobs."""
    with parallel_config(backend="loky", inner_max_num_threads=1):
        named = Parallel(n_jobs=2)(delayed(one_set)(seed, k) for k in range(NULL_SETS))
    return sum(named)


def our_stabilization_null_set(seed: int, k: int) -> bool:
    """One recording of our simulator without candidate effects (20 s at 50 Hz, angles of 0.2°
    to 1° either sign, random rocking phases and gyro biases, the k-th of 8 variants of mount,
    gyro sampling and a 0 or 300 px target); whether its diagnosis names anything."""
    g = np.random.default_rng([seed, k])
    deg = math.radians(1.0)
    mount, sampling, offset = [(m, s, o) for m in kin.MOUNTS for s in sim.GYRO_SAMPLINGS
                               for o in (0.0, 300.0)][k % 8]
    angles = g.uniform(0.2, 1.0, 6) * g.choice([-1, 1], 6) * deg
    rock = kin.Rocking(np.full(3, 5 * deg), [0.25, 0.4, 0.32], g.uniform(0, 2 * np.pi, 3))
    a = g.uniform(0, 2 * np.pi)
    setup = sim.Setup(duration=20.0, rate=50.0, aim_azimuth=20 * deg, aim_pitch=10 * deg,
                      image_noise=0.1, gyro_noise=math.radians(0.01) / 60.0, mount=mount,
                      gyro_sampling=sampling, target_px=(offset * np.cos(a), offset * np.sin(a)))
    run = sim.simulate(rock, setup, angles[:3], angles[3:], g.normal(size=3) * deg / 3600,
                       rng=g)
    d = diagnose(ste.stabilization_problem(run, setup.camera, setup.image_noise,
                                           setup.gyro_noise, mount, sampling))
    return bool(d.named)


def second_stabilization_null_set(seed: int, k: int) -> bool:
    """One recording of the second simulator (its scenario, 20 s at 50 Hz, installation angles
    within ±0.6°, gimbal start within ±40° azimuth and 0-30° elevation), written to CSV and
    diagnosed by ``montecarlo diagnose stabilization`` with the options a user would take from
    its truth file; whether an effect or a convention is named (or the command failed)."""
    from tests.independent import stabilization_second as second
    from tests.test_stabilization_independent import FAST, _options

    g = np.random.default_rng([seed, k])
    deg = math.radians(1.0)
    dg, dp = tuple(g.uniform(-0.6, 0.6, 3) * deg), tuple(g.uniform(-0.6, 0.6, 3) * deg)
    with tempfile.TemporaryDirectory() as folder:
        csv, truth, out = (Path(folder) / n for n in ("run.csv", "truth.json", "d.json"))
        second.simulate_recording(csv, truth, dg, dp, seed=int(g.integers(2**31)),
                                  eta0_rad=g.uniform(-40.0, 40.0) * deg,
                                  eps0_rad=g.uniform(0.0, 30.0) * deg, **FAST)
        args = ["diagnose", "stabilization", str(csv), *_options(json.loads(truth.read_text())),
                "--json", str(out)]
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            if main(args) != 0:
                return True
        d = json.loads(out.read_text())
    return bool(d["named_effects"] or d["conventions"]["named"])


def test_null_sets_of_our_stabilization_simulator(figures):
    _null_share(figures, "stabilization_null_named",
                _sets_named(our_stabilization_null_set, 9600), NULL_SETS)


def test_null_sets_of_the_second_stabilization_simulator(figures):
    _null_share(figures, "stabilization_second_null_named",
                _sets_named(second_stabilization_null_set, 9700), NULL_SETS)
