"""Systems built on run_trials hooks: unit conversion at the edge, streams, invalid trials."""

import math
import textwrap

import numpy as np
import pytest

from montecarlo.engine.runner import RunOptions, run_study
from montecarlo.errors import InputError
from montecarlo.systems import load_study
from montecarlo.systems.collimation import COLLIMATION
from montecarlo.units import ARCSEC
from montecarlo.units import SUFFIXES as UNITS

AIR = """
[study]
system = "air"
trials = 3000
seed = 5
block_size = 1000

[params]
heading_sigma_arcmin = 3.0
level_sigma_arcmin = 5.0
install_bound_arcmin = 0.0
"""


def test_units_convert_to_si(tmp_path):
    p = tmp_path / "air.toml"
    p.write_text(textwrap.dedent(AIR))
    params = load_study(p).points[0].prepared.params
    assert params["heading_sigma"] == pytest.approx(3.0 * math.pi / (180 * 60))
    assert params["install_bound"] == 0.0
    assert params["gyro_drift"] == pytest.approx(0.05 * UNITS["deg_per_h"])
    assert UNITS["deg_per_h"] == pytest.approx(math.radians(1) / 3600)


def test_air_study_reproduces_the_rss_of_inputs(tmp_path):
    """rms of phi = sqrt(3'^2 + 5'^2) = 1.696 mrad with no installation error
    (docs/reference/air.md);
    the standard error of an rms from n trials of a 3-D spread is about rms / sqrt(2 n)."""
    p = tmp_path / "air.toml"
    p.write_text(textwrap.dedent(AIR))
    result = run_study(load_study(p), RunOptions(progress=False, checkpoint_dir=tmp_path / "c"))
    row = result.to_frame().query("metric == 'rotation_angle'").iloc[0]
    rms = math.sqrt(row["mean"] ** 2 + row["std"] ** 2 * (row["count"] - 1) / row["count"])
    expected = math.hypot(3, 5) * math.pi / (180 * 60) * 1e3
    assert rms == pytest.approx(expected, rel=4 / math.sqrt(2 * 3000))


def test_unknown_param_is_one_line(tmp_path):
    p = tmp_path / "air.toml"
    p.write_text(textwrap.dedent(AIR).replace("heading_sigma_arcmin", "heading_sigma_deg"))
    with pytest.raises(InputError, match=r"params.heading_sigma_deg: unknown key"):
        load_study(p)


def test_collimation_block_is_deterministic():
    """Same streams, same trials: a block's values depend only on (seed, block)."""
    from montecarlo.engine.distributions import Streams

    prepared = COLLIMATION.prepare(COLLIMATION.config_model.model_validate(
        {"params": {"theodolite_sigma_arcsec": 2.0}}))
    assert prepared.params["theodolite_sigma"] == pytest.approx(2.0 * ARCSEC)
    a, _ = COLLIMATION.simulate_block(prepared, Streams(1, 0, 0), 0, 4)
    b, _ = COLLIMATION.simulate_block(prepared, Streams(1, 3, 0), 0, 4)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
