"""Error sources, random streams, corners and the pixel relation between targets."""

import numpy as np
import pytest
from scipy import stats

from montecarlo.engine.distributions import Distribution, Streams, corner_signs, fill_pair

N = 200_000
UNIFORM = Distribution("uniform", 0.0, 1.0)


def correlated_pair(dist, relation, streams, source, n):
    a, b = np.empty(n), np.empty(n)
    fill_pair(dist, relation, streams, source, a, b)
    return a, b


def draw(streams, source, n=100):
    return streams.fill(UNIFORM, source, np.empty(n))


def test_streams_are_common_across_points_only_when_asked():
    a = draw(Streams(1, point=0, block=3), "dx_m")
    b = draw(Streams(1, point=7, block=3), "dx_m")
    assert np.array_equal(a, b)
    c = draw(Streams(1, point=7, block=3, common=False), "dx_m")
    d = draw(Streams(1, point=0, block=3, common=False), "dx_m")
    assert not np.array_equal(c, d)
    assert not np.array_equal(a, draw(Streams(1, point=0, block=4), "dx_m"))
    assert not np.array_equal(a, draw(Streams(1, point=0, block=3), "dy_m"))


def test_streams_match_seedsequence_spawn():
    """Spawn keys equal nested SeedSequence.spawn: key (block, source) = child of child."""
    from montecarlo.engine.distributions import source_key

    root = np.random.SeedSequence(42)
    child = root.spawn(6)[5]
    ref = np.random.Generator(np.random.PCG64(np.random.SeedSequence(
        42, spawn_key=(5, source_key("x")))))
    assert child.spawn_key == (5,)
    assert np.array_equal(Streams(42, 0, 5).generator("x").random(5), ref.random(5))


def test_corner_signs_enumerate_every_corner_once():
    s = corner_signs(0, 64, 6)
    assert s.shape == (6, 64)
    assert len({tuple(c) for c in s.T}) == 64
    np.testing.assert_array_equal(corner_signs(64, 64, 6), s)  # periodic in the trial index


@pytest.mark.parametrize("rho", [-0.6, 0.3, 0.9])
@pytest.mark.parametrize("kind", ["uniform", "normal"])
def test_correlated_pair_has_the_requested_correlation_and_marginals(kind, rho):
    """Pearson correlation rho within 4 standard errors ((1 - rho^2)/sqrt(N) for large N)."""
    dist = Distribution(kind, 0.0, 1.0)
    za, zb = correlated_pair(dist, rho, Streams(5, 0, 0), "pixel_x", N)
    r = np.corrcoef(za, zb)[0, 1]
    assert abs(r - rho) < 4 * (1 - rho**2) / np.sqrt(N) + 1e-3
    ref = stats.uniform(-1, 2) if kind == "uniform" else stats.norm()
    for z in (za, zb):
        assert stats.kstest(z, ref.cdf).pvalue > 1e-3


def test_relation_limits_and_common_a_draws():
    dist = Distribution("uniform", 0.0, 1.0)
    a1, b1 = correlated_pair(dist, "common", Streams(5, 0, 0), "p", 1000)
    a0, b0 = correlated_pair(dist, "independent", Streams(5, 0, 0), "p", 1000)
    a5, _ = correlated_pair(dist, 0.5, Streams(5, 0, 0), "p", 1000)
    assert np.array_equal(a1, b1)
    assert np.array_equal(a1, a0) and np.array_equal(a1, a5)  # A's draws never change
    assert not np.array_equal(a0, b0)


def test_worst_case_of_a_normal_source_is_refused():
    with pytest.raises(ValueError, match="no worst case"):
        Distribution("normal", 0.0, 1.0).worst_case()
    assert Distribution("uniform", 1.0, 2.0).worst_case() == Distribution("corners", 1.0, 2.0)


SHAPES = [
    (Distribution("triangular", 0.3, 2.0), stats.triang(c=0.5, loc=-1.7, scale=4.0)),
    (Distribution("arcsine", -1.0, 0.5), stats.arcsine(loc=-1.5, scale=1.0)),
    (Distribution("truncnormal", 2.0, 0.5, 1.5), stats.truncnorm(-1.5, 1.5, loc=2.0, scale=0.5)),
    (Distribution("truncnormal", 0.0, 1.0, 0.2), stats.truncnorm(-0.2, 0.2)),
    (Distribution("lognormal", 0.0, 3.0, 0.4), stats.lognorm(s=0.4, scale=3.0)),
]


@pytest.mark.parametrize(("dist", "reference"), SHAPES, ids=lambda v: getattr(v, "kind", ""))
def test_shapes_follow_scipy_distributions(dist, reference):
    x = Streams(3, 0, 0).fill(dist, "dx_m", np.empty(N))
    assert stats.kstest(x, reference.cdf).pvalue > 1e-3
    np.testing.assert_allclose([x.mean(), x.std()], [reference.mean(), reference.std()],
                               rtol=0.02, atol=0.01 * reference.std())
    if dist.half_width is not None:
        assert np.abs(x - dist.location).max() <= dist.half_width
        assert dist.worst_case() == Distribution("corners", dist.location, dist.half_width)


def test_shapes_share_unit_draws_with_uniform_or_normal():
    """Common random numbers: a shape's draws are a monotone map of the same unit draws."""
    n = 5000
    streams = Streams(9, 0, 2)
    for base, kinds in ((UNIFORM, ("triangular", "arcsine")),
                        (Distribution("normal", 0.0, 1.0), ("truncnormal", "lognormal"))):
        ref = Streams(9, 4, 2).fill(base, "dh_m", np.empty(n))
        for kind in kinds:
            x = streams.fill(Distribution(kind, 0.0, 1.0, 2.0), "dh_m", np.empty(n))
            assert stats.spearmanr(ref, x).statistic == pytest.approx(1.0)
            streams = Streams(9, 0, 2)


def test_a_wide_truncnormal_is_the_normal():
    s = Streams(5, 0, 0)
    wide = s.fill(Distribution("truncnormal", 1.0, 2.0, 12.0), "x", np.empty(10000))
    normal = Streams(5, 0, 0).fill(Distribution("normal", 1.0, 2.0), "x", np.empty(10000))
    np.testing.assert_allclose(wide, normal, rtol=0, atol=1e-9)


@pytest.mark.parametrize("kind", ["triangular", "arcsine", "truncnormal", "lognormal"])
def test_a_block_drawn_in_pieces_equals_the_block_at_once(kind):
    dist = Distribution(kind, 0.5, 2.0, 1.0)
    whole = Streams(1, 0, 0).fill(dist, "dy_m", np.empty(1000))
    pieces = Streams(1, 0, 0)
    parts = [pieces.fill(dist, "dy_m", np.empty(m)) for m in (1, 299, 700)]
    np.testing.assert_array_equal(np.concatenate(parts), whole)


def test_unbounded_shapes_have_no_worst_case_and_no_correlated_pair():
    with pytest.raises(ValueError, match="lognormal source has no worst case"):
        Distribution("lognormal", 0.0, 1.0, 0.3).worst_case()
    with pytest.raises(ValueError, match="needs a uniform or normal source"):
        correlated_pair(Distribution("triangular", 0.0, 1.0), 0.5, Streams(1, 0, 0), "p", 10)


SHAPE_STUDY = """
[study]
name = "shapes"
system = "ground"
trials = 20000
seed = 4
per_trial = true

[sensor]
fov_deg = [90.0, 90.0]
pixels = [512, 512]

[mounting]
psi_deg = 30.0
theta_deg = 20.0
gamma_deg = 10.0

[geometry]
L_m = 100.0
H_m = 2.0

[errors]
dx_m = {dx}
pixel_px = 0.0
pixel_relation = "common"

[solver]
variants = ["normalised"]
"""


@pytest.mark.parametrize("source, spread", [
    ('{dist = "triangular", bound = 0.2}', 0.2 / np.sqrt(6)),
    ('{dist = "arcsine", bound = 0.2}', 0.2 / np.sqrt(2)),
    ('{dist = "truncnormal", sigma = 0.1, bound = 0.1}', stats.truncnorm(-1, 1, scale=0.1).std()),
    ('{dist = "lognormal", median = 0.1, sigma_ln = 0.3}', stats.lognorm(0.3, scale=0.1).std()),
])
def test_each_shape_runs_from_a_study_file(tmp_path, source, spread):
    """Through the command line (a process forked from one with the libraries imported; a
    fresh process refusing a bad shape is the next test): the only error source is dx of the
    shape, so the spread of the yaw error across trials follows the source's standard
    deviation."""
    import pandas as pd

    from tests.forked_cli import montecarlo_cli

    def spread_of(text: str, name: str) -> float:
        path = tmp_path / f"{name}.toml"
        path.write_text(SHAPE_STUDY.format(dx=text))
        done = montecarlo_cli("-q", "run", path, "--out", tmp_path / name)
        assert done.returncode == 0, done.stderr
        trials = pd.read_parquet(tmp_path / name / "trials.parquet")
        return float(trials["normalised/delta_psi_mrad"].std())

    # the yaw error is linear in dx at these sizes: its spread scales with the source's
    ratio = spread_of(source, "shape") / spread_of(f'{{dist = "normal", sigma = {spread}}}',
                                                   "normal")
    assert ratio == pytest.approx(1.0, rel=0.05)


def test_a_bad_shape_parameter_is_one_line(tmp_path):
    import subprocess
    import sys

    path = tmp_path / "bad.toml"
    path.write_text(SHAPE_STUDY.format(dx='{dist = "lognormal", median = -1.0, sigma_ln = 0.3}'))
    done = subprocess.run([sys.executable, "-m", "montecarlo", "run", str(path), "--out",
                           str(tmp_path / "out")], capture_output=True, text=True)
    assert done.returncode == 2 and done.stderr.count("\n") == 1
    assert "dx_m" in done.stderr and "median" in done.stderr
    assert not (tmp_path / "out").exists()
