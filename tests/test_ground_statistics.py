"""The fast ground path's streaming statistics against the literal reference path's, histogram
bin by histogram bin.

The fast path (``GroundSystem.accumulate_block``: fused kernel, numpy metrics, compiled
accumulation) and the reference path (``simulate_block``: the literal equations of seed 000,
aggregated by ``MetricStats.add_block`` in numpy) compute every trial's metrics in different
algebra, agreeing to 1e-12 rad per trial (tests/test_ground_kernel.py), or to
``4 ulp(3) / sin(value)`` for the two metrics that are an arccos of a number near 1. Their
histograms can therefore differ only where a trial's two values straddle a bin edge; a bin is
2**-10 of its value wide, so with per-trial differences of ~1e-16 relative (1e-8 for the
arccos metrics) among 4 10^4 trials, at most a trial or two per metric may cross, each into the
neighbouring bin.
"""

import numpy as np
import pytest

from montecarlo.engine import aggregate as agg
from montecarlo.engine.distributions import Streams
from montecarlo.systems import study_from_dict

TOL = 1e-12  # [rad], the per-trial agreement of the two paths
ARCCOS_METRICS = ("eq18_angle", "table1_angle")
BLOCKS = [(0, 32768), (32768, 9000)]  # two blocks, one not a multiple of SUB_CHUNK

TABLE1 = {  # seed 000, section 1.4, sampled (the workload of `montecarlo bench`)
    "mounting": {"psi_deg": 30.0, "theta_deg": 20.0, "gamma_deg": 10.0},
    "errors": {"dx_m": {"dist": "uniform", "bound": 0.1},
               "dy_m": {"dist": "uniform", "bound": 0.1},
               "dh1_m": {"dist": "uniform", "bound": 0.1},
               "dh_m": {"dist": "uniform", "bound": 0.001},
               "pixel_px": {"dist": "uniform", "bound": 0.5},
               "pixel_relation": "common"}}
DRAWN = {  # a mounting drawn per trial (the kernel's other loop), independent pixel errors
    "mounting": {"psi_deg": {"dist": "normal", "sigma": 3.0}, "theta_deg": 5.0},
    "errors": {"dx_m": {"dist": "normal", "sigma": 0.05},
               "dh_m": {"dist": "uniform", "bound": 0.002},
               "pixel_px": {"dist": "normal", "sigma": 0.3},
               "pixel_relation": "independent"}}


def _both_paths(case: dict, blocks: list[tuple[int, int]]
                ) -> tuple[agg.PointStats, agg.PointStats]:
    raw = {"study": {"system": "ground", "trials": 1, "seed": 7},
           "sensor": {"fov_deg": [90.0, 90.0], "pixels": [512, 512]},
           "geometry": {"L_m": 100.0, "H_m": 1.0}, **case}
    study = study_from_dict(raw)
    system, p = study.system, study.points[0].prepared
    fast, ref = agg.PointStats(), agg.PointStats()
    for b, (first, n) in enumerate(blocks):
        system.accumulate_block(p, Streams(7, 0, b), first, n, b, fast)
        ref.add_block(b, *system.simulate_block(p, Streams(7, 0, b), first, n), n)
    return fast, ref


@pytest.mark.parametrize(("case", "blocks"), [(TABLE1, BLOCKS), (DRAWN, BLOCKS)],
                         ids=["table1", "drawn_mounting"])
def test_fast_path_histograms_and_moments_equal_the_reference(case, blocks):
    fast, ref = _both_paths(case, blocks)
    assert fast.invalid == ref.invalid
    assert fast.trials == ref.trials == sum(n for _, n in blocks)
    assert set(fast.metrics) == set(ref.metrics) and len(ref.metrics) == 12
    for key, r in ref.metrics.items():
        f = fast.metrics[key]
        arccos = key[1] in ARCCOS_METRICS
        # counts: every trial with a value is in both, and the histograms are equal bin by bin
        # but for trials moved into a neighbouring bin (a nonzero cumulative difference marks
        # the edge each crossed)
        assert f.count == r.count == f.hist.sum() == r.hist.sum(), key
        crossed = np.cumsum(f.hist - r.hist)
        assert np.abs(crossed).max() <= 1 and np.count_nonzero(crossed) <= 2, \
            (key, np.flatnonzero(f.hist != r.hist))
        # moments, minimum and maximum: within the per-trial agreement of the two paths
        tol = TOL
        if arccos:  # 4 ulp(3) / sin(value) at the smallest value bounds every trial's
            tol += 4 * np.spacing(3.0) / np.sin(r.minimum)
        (mean_f, std_f), (mean_r, std_r) = f.mean_std(), r.mean_std()
        assert abs(mean_f - mean_r) <= tol, key
        assert abs(std_f - std_r) <= 2 * tol, key  # |std(a) - std(b)| <= rms(a - b) <= tol
        assert abs(f.minimum - r.minimum) <= tol and abs(f.maximum - r.maximum) <= tol, key
