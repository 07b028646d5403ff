"""The fused ground kernel equals the literal reference (montecarlo.seed000.ground) to 1e-12 rad."""

import textwrap

import numpy as np
import pandas as pd
import pytest

from montecarlo.engine import aggregate as agg
from montecarlo.engine import runner
from montecarlo.engine.runner import RunOptions, run_study
from montecarlo.geometry.camera import Camera
from montecarlo.geometry.rotations import mounting_matrix
from montecarlo.seed000 import ground
from montecarlo.seed000 import ground_kernel as gk
from montecarlo.systems import load_study

TOL = 1e-12  # [rad]
ARCCOS_METRICS = ("eq18_angle", "table1_angle")


def _tolerance(metric, value, rotation):
    """Agreement required per trial [rad].

    1e-12 for every calibration whose error is below 0.1 rad. The two metrics that are arccos
    of a number near 1 (eq. (18) and the Table 1 metric) amplify the round-off of tr D (a few
    ulp of 3) by 1/(4 sin(value)), in the reference as much as in the kernel: their bound adds
    4 ulp(3) / sin(value). Beyond 0.1 rad the solution has failed anyway and the
    L/H-amplified round-off of eq. (11) dominates: 1e-11.
    """
    tol = np.where(rotation < 0.1, TOL, 10 * TOL)
    if metric in ARCCOS_METRICS:
        tol = tol + 4 * np.spacing(3.0) / np.maximum(np.sin(np.abs(value)), 1e-300)
    return tol


def _kernel(camera, true, L, H, e):
    n = e.shape[1]
    C = mounting_matrix(*true).reshape(-1, 9).T.copy()
    C = C[:, 0].copy() if C.shape[1] == 1 else C  # one matrix (9,) or one per trial (9, n)
    flags = np.empty((2, n), np.uint16)
    fields = np.empty((2 * gk.N_FIELDS, n))
    identity = np.array([np.ones(8), np.zeros(8)])  # the errors given as they are
    gk.solve_chunk(C, L, H, float(camera.k_x), float(camera.k_z), camera.n_x / 2,
                   camera.n_z / 2, list(e), identity, flags, fields)
    gk.metrics_in_place(fields)
    return flags, fields[gk.METRIC_ROWS]


def _compare(camera, true, L, H, e):
    flags, values = _kernel(camera, true, L, H, e)
    sols = ground.simulate(camera, true, L, H, dx=e[0], dy=e[1], dh1=e[2], dh=e[3],
                           pixel_error_a=e[4:6].T, pixel_error_b=e[6:8].T)
    for v, name in enumerate(ground.SOLVERS):
        np.testing.assert_array_equal(flags[v], sols[name].invalid)
        ref = ground.solution_metrics(sols[name], true)
        rot = ref["rotation_angle"]
        for row, (variant, metric) in enumerate(gk.VALUE_ROWS):
            if variant != v:
                continue
            got = values[row]
            np.testing.assert_array_equal(np.isnan(got), np.isnan(ref[metric]))
            ok = ~np.isnan(got)
            diff = np.abs(got - ref[metric])[ok]
            bad = diff > _tolerance(metric, ref[metric], rot)[ok]
            assert not bad.any(), (metric, diff[bad][:5], ref[metric][ok][bad][:5])
    return flags


@pytest.mark.parametrize("seed", range(12))
def test_kernel_equals_reference_on_random_configurations(seed):
    """Random cameras, angles, L (20-500 m), H (0.5-10 m) and error sizes."""
    rng = np.random.default_rng(seed)
    n = 20000
    camera = Camera.from_degrees(*rng.uniform(20, 120, 2), *rng.integers(256, 4096, 2))
    true = tuple(np.radians(rng.uniform(-25, 25, 3)))
    L, H = rng.uniform(20, 500), rng.uniform(0.5, 10)
    scale = np.array([0.2, 0.2, 0.2, 0.01, 1, 1, 1, 1]) * rng.uniform(0.1, 3)
    e = rng.uniform(-1, 1, (8, n)) * scale[:, None]
    _compare(camera, true, L, H, e)


def test_kernel_with_per_trial_mounting_angles():
    rng = np.random.default_rng(9)
    n = 5000
    true = tuple(rng.uniform(-0.3, 0.3, (3, n)))
    e = rng.normal(0, 0.3, (8, n)) * np.array([0.3, 0.3, 0.3, 0.01, 1, 1, 1, 1])[:, None]
    _compare(Camera.from_degrees(90, 90, 512, 512), true, 100.0, 2.0, e)


def test_kernel_invalid_paths_match_reference():
    """Targets behind, outside the field of view, and eq. (14) out of range: same reasons."""
    rng = np.random.default_rng(3)
    n = 40000
    true = tuple(rng.uniform(-1.5, 1.5, (3, n)))
    e = rng.normal(0, 1, (8, n)) * np.array([2, 2, 2, 1, 50, 50, 50, 50])[:, None]
    flags = _compare(Camera.from_degrees(60, 60, 512, 512), true, 30.0, 0.5, e)
    seen = set(np.unique(flags))
    assert {0, 8, 16} <= seen and seen & {32, 64, 96, 128}  # several reasons exercised


def test_runner_fast_path_agrees_with_reference_path(tmp_path, monkeypatch):
    p = tmp_path / "s.toml"
    p.write_text(textwrap.dedent("""
        [study]
        system = "ground"
        trials = 20000
        seed = 4
        block_size = 8192
        [sensor]
        fov_deg = [60.0, 50.0]
        pixels = [1024, 1024]
        [mounting]
        psi_deg = { dist = "uniform", bound = 20.0 }
        theta_deg = 10.0
        [geometry]
        L_m = 80.0
        H_m = 1.5
        [errors]
        dx_m = { dist = "uniform", bound = 0.1 }
        dy_m = { dist = "normal", sigma = 0.1 }
        dh1_m = { dist = "uniform", bound = 0.1 }
        dh_m = { dist = "uniform", bound = 0.003 }
        pixel_px = { dist = "normal", sigma = 0.7 }
        pixel_relation = 0.3
        [[sweep]]
        "errors.pixel_relation" = ["common", "independent", 0.3]
    """))
    study = load_study(p)
    monkeypatch.setattr(runner, "REFERENCE_BELOW", 0.0)  # the kernel even for a small study
    fast = run_study(study, RunOptions(progress=False, checkpoint_dir=tmp_path / "a"))
    ref = run_study(study, RunOptions(progress=False, checkpoint_dir=tmp_path / "b",
                                      reference=True))
    assert (fast.kernel, ref.kernel) == ("fast", "reference")
    a, b = fast.to_frame(), ref.to_frame()
    counts = [c for c in a.columns if c == "count" or c.startswith("invalid")]
    pd.testing.assert_frame_equal(a[counts], b[counts])
    for col in agg.VALUE_COLUMNS:
        np.testing.assert_allclose(a[col], b[col], rtol=1e-9, atol=1e-12, err_msg=col)


@pytest.mark.parametrize("relation", ["common", "independent", 0.4])
def test_block_drawn_in_pieces_equals_block_drawn_at_once(tmp_path, relation):
    """Each source's generator gives the same numbers whether a block is drawn in pieces or
    at once, which lets the fast path draw whole blocks and solve them in chunks of any size."""
    from montecarlo.engine.distributions import Streams
    from montecarlo.systems import study_from_dict

    raw = {"study": {"system": "ground", "trials": 10000, "seed": 3},
           "sensor": {"fov_deg": [60.0, 60.0], "pixels": [512, 512]},
           "mounting": {"psi_deg": {"dist": "normal", "sigma": 3.0}},
           "geometry": {"L_m": 50.0, "H_m": 1.0},
           "errors": {"dx_m": {"dist": "uniform", "bound": 0.1},
                      "dy_m": {"dist": "normal", "sigma": 0.1},
                      "dh_m": {"dist": "corners", "bound": 0.002},
                      "pixel_px": {"dist": "uniform", "bound": 0.5},
                      "pixel_relation": relation}}
    study = study_from_dict(raw)
    system, p = study.system, study.points[0].prepared
    true, whole = system.draws(p, Streams(3, 0, 5), 1000, 5000)
    s = Streams(3, 0, 5)
    pieces = [system.draws(p, s, 1000 + a, b - a) for a, b in [(0, 1234), (1234, 4096),
                                                               (4096, 5000)]]
    np.testing.assert_array_equal(np.concatenate([e for _, e in pieces], axis=1), whole)
    np.testing.assert_array_equal(np.concatenate([t[0] for t, _ in pieces]), true[0])


@pytest.mark.parametrize("solve_chunk", [8192, 24576])
def test_fast_path_statistics_do_not_depend_on_the_solve_chunk(monkeypatch, solve_chunk):
    """Bitwise the same statistics whatever SOLVE_CHUNK (a speed setting) is; they are merged
    every SUB_CHUNK trials whatever it is."""
    from montecarlo.engine.distributions import Streams
    from montecarlo.systems import study_from_dict

    raw = {"study": {"system": "ground", "trials": 1, "seed": 2},
           "sensor": {"fov_deg": [60.0, 60.0], "pixels": [512, 512]},
           "mounting": {"psi_deg": {"dist": "normal", "sigma": 3.0}},
           "geometry": {"L_m": 50.0, "H_m": 1.0},
           "errors": {"dx_m": {"dist": "uniform", "bound": 0.1},
                      "dh_m": {"dist": "corners", "bound": 0.002},
                      "pixel_px": {"dist": "uniform", "bound": 0.5},
                      "pixel_relation": "independent"}}
    study = study_from_dict(raw)
    system, p = study.system, study.points[0].prepared

    def stats() -> agg.PointStats:
        out = agg.PointStats()
        for b, (first, n) in enumerate([(0, 65536), (65536, 30000)]):
            system.accumulate_block(p, Streams(2, 0, b), first, n, b, out)
        return out

    whole = stats()
    monkeypatch.setattr(gk, "SOLVE_CHUNK", solve_chunk)
    cut = stats()
    assert whole.hist_matrix.tobytes() == cut.hist_matrix.tobytes()
    assert whole.invalid == cut.invalid
    for key, m in whole.metrics.items():
        assert (m.moments(), m.minimum, m.maximum) == \
            (cut.metrics[key].moments(), cut.metrics[key].minimum, cut.metrics[key].maximum)


def test_every_distribution_shape_gives_the_same_statistics_on_both_paths(monkeypatch):
    from montecarlo.systems import study_from_dict

    raw = {"study": {"system": "ground", "trials": 20000, "seed": 11},
           "sensor": {"fov_deg": [60.0, 60.0], "pixels": [512, 512]},
           "mounting": {"psi_deg": {"dist": "arcsine", "bound": 2.0}},
           "geometry": {"L_m": 50.0, "H_m": 1.0},
           "errors": {"dx_m": {"dist": "triangular", "bound": 0.1},
                      "dy_m": {"dist": "truncnormal", "sigma": 0.05, "bound": 0.08},
                      "dh1_m": {"dist": "arcsine", "bound": 0.1},
                      "dh_m": {"dist": "lognormal", "median": 0.002, "sigma_ln": 0.5},
                      "pixel_px": {"dist": "triangular", "bound": 0.6},
                      "pixel_relation": "independent"}}
    study = study_from_dict(raw)
    monkeypatch.setattr(runner, "REFERENCE_BELOW", 0.0)
    fast = run_study(study, RunOptions(n_jobs=1, progress=False))
    ref = run_study(study, RunOptions(n_jobs=1, progress=False, reference=True))
    assert (fast.kernel, ref.kernel) == ("fast", "reference")
    a, b = fast.to_frame(), ref.to_frame()
    pd.testing.assert_series_equal(a["count"], b["count"])
    for col in agg.VALUE_COLUMNS:
        np.testing.assert_allclose(a[col], b[col], rtol=1e-9, atol=1e-12, err_msg=col)


def test_is_cached_asks_the_kernel_of_the_mounting_it_is_asked_about(monkeypatch):
    """``is_cached(varying)`` is about the per-trial-mounting kernel when ``varying`` and the
    fixed-mounting one otherwise (what the runner's first-use note says will compile)."""
    asked = []

    def cached(dispatcher):
        asked.append(dispatcher)
        return dispatcher is gk._solve_varying

    monkeypatch.setattr(gk, "cached", cached)
    assert gk.is_cached(True) is True and gk.is_cached(False) is False
    assert asked == [gk._solve_varying, gk._solve_fixed]
