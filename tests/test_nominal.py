"""The nominal case: every error source at its centre, one trial, no sampling."""

from __future__ import annotations

import math

import numpy as np
import pytest

import montecarlo
from montecarlo.engine.distributions import Distribution
from montecarlo.engine.nominal import CentredGenerator, NoCentre, NominalStreams, nominal_values
from montecarlo.geometry.metrics import ROTATION_METRICS
from montecarlo.seed000 import ground
from montecarlo.systems import load_study


def test_table1_nominal_row_is_the_noise_free_solution():
    """Seed 000, Table 1 study: the nominal row of every grid point and variant equals the
    noise-free solution computed directly by the literal reference (ground.simulate with every
    error 0), and that solution recovers the mounting: 0 within 1e-12 rad."""
    result = montecarlo.run("studies/table1.toml", trials=64)
    s = result.summary
    assert s["nominal"].notna().all()
    study = load_study("studies/table1.toml", trials=64)
    for gp in study.points:
        p = gp.prepared
        true = tuple(d.location for d in p.mounting)
        zero = np.zeros(1)
        sols = ground.simulate(p.camera, true, p.L, p.H, dx=zero, dy=zero, dh1=zero, dh=zero,
                               pixel_error_a=np.zeros((1, 2)), pixel_error_b=np.zeros((1, 2)),
                               solvers=p.variants)
        for variant, sol in sols.items():
            direct = ground.solution_metrics(sol, true)
            rows = s[(s["point"] == gp.index) & (s["variant"] == variant)]
            for _, row in rows.iterrows():
                scale = study.metric(row["metric"]).scale
                value_rad = row["nominal"] / scale
                assert abs(value_rad) < 1e-12, (gp.index, variant, row["metric"])
                assert value_rad == pytest.approx(float(direct[row["metric"]][0]), abs=1e-15)
    assert set(ROTATION_METRICS) <= set(s["metric"])


def test_nominal_of_an_offset_source_is_its_centre(tmp_path):
    """A placement error with a non-zero centre (dy centred on 0.05 m) moves the nominal case
    away from zero by exactly what a fixed 0.05 m error gives."""
    base = {"study": {"name": "n", "system": "ground", "trials": 64, "seed": 1},
            "sensor": {"fov_deg": [90.0, 90.0], "pixels": [512, 512]},
            "mounting": {"psi_deg": 30.0, "theta_deg": 20.0, "gamma_deg": 10.0},
            "geometry": {"L_m": 50.0, "H_m": 1.0},
            "errors": {"dy_m": {"dist": "uniform", "bound": 0.1, "center": 0.05},
                       "pixel_px": {"dist": "normal", "sigma": 0.3},
                       "pixel_relation": "common"}}
    fixed = {**base, "errors": {"dy_m": {"dist": "fixed", "value": 0.05},
                                "pixel_relation": "common"}}
    a = montecarlo.run(base).summary.set_index(["variant", "metric"])["nominal"]
    b = montecarlo.run(fixed).summary.set_index(["variant", "metric"])["nominal"]
    assert a.loc[("raw", "rotation_angle")] > 1e-3  # [mrad]: visibly off zero
    np.testing.assert_allclose(a.to_numpy(), b.to_numpy(), rtol=1e-12, atol=1e-15)


def test_centred_draws():
    g = CentredGenerator()
    assert g.standard_normal() == 0.0
    np.testing.assert_array_equal(g.uniform(-1.0, 3.0, (2, 3)), np.ones((2, 3)))
    assert g.normal(5.0, 2.0) == 5.0 and g.random() == 0.5
    with pytest.raises(NoCentre):
        g.choice([-1.0, 1.0])
    out = np.empty(4)
    for dist, centre in [(Distribution("uniform", 2.0, 1.0), 2.0),
                         (Distribution("triangular", -1.0, 1.0), -1.0),
                         (Distribution("arcsine", 0.5, 2.0), 0.5),
                         (Distribution("normal", 3.0, 1.0), 3.0),
                         (Distribution("truncnormal", 1.0, 1.0, 2.0), 1.0),
                         (Distribution("lognormal", 0.0, 4.0, 0.5), 4.0)]:  # the median
        np.testing.assert_allclose(NominalStreams().fill(dist, "s", out), centre, atol=1e-15)


@pytest.mark.slow
def test_a_system_without_a_centre_has_nan_nominal():
    """The stabilisation system draws random signs of the installation angles: no centre."""
    study = load_study("studies/stabilization.toml", trials=1)
    values = nominal_values(study.system, study.points[0].prepared)
    assert len(values) == len(study.metrics) and all(math.isnan(v) for v in values.values())
