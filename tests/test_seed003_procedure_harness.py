"""Seed 003's procedure: the acceptance harness and the pitch-reach search, against their
docstrings (docs/validation/collimation.md, "Acceptance of the procedure's fit").

The harness tests record what ``acceptance_trials`` hands the simulator and the fit (a spy that
calls the real simulator and stands in for the fit), so they check every option passed on
without fitting; the fit itself is tested in ``tests/test_seed003_procedure_gls.py``.
"""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from montecarlo.seed003 import procedure as pr
from montecarlo.seed003.model import Noise
from montecarlo.units import ARCSEC

A = ARCSEC
AZ, EL, SETS = pr.procedure_layout()


def _spy(monkeypatch):
    calls = []
    real = pr.simulate_procedure

    def simulate(g, lam, az, el, noise, rng, **kw):
        calls.append({"truth": (g, lam), "az": az, "el": el, "noise": noise, "rng": rng, **kw})
        return real(g, lam, az, el, noise, rng, **kw)

    def fit(data, **kw):
        calls[-1]["data"], calls[-1]["fit"] = data, kw
        g, lam = calls[-1]["truth"]
        # a stand-in result 1″ and -2″ off the truth drawn, sigmas 3″ and 4″, chi2_red 1.5
        return SimpleNamespace(params={"axis_az": g + A, "axis_el": lam - 2 * A},
                               stderr={"axis_az": 3 * A, "axis_el": 4 * A}, chi2_red=1.5)

    monkeypatch.setattr(pr, "simulate_procedure", simulate)
    monkeypatch.setattr(pr, "fit_procedure", fit)
    return calls


@pytest.mark.parametrize(("rows", "roll", "side"), [(True, "recorded", -1.0),
                                                    (False, "level", 1.0),
                                                    (False, "free", -1.0)])
def test_acceptance_trials_pass_each_option_on(monkeypatch, rows, roll, side):
    """Per trial (docstring): gamma, lambda uniform in ``offsets``, each with a random sign, a frame
    heading in [-pi, pi), readings with errors ``noise_sigma`` each and the mount roll unless the
    case is "level", fitted with the known sigmas, free rolls for "free", no residuals before;
    the errors reported are the fit's values minus the truth drawn."""
    calls = _spy(monkeypatch)
    rng = np.random.default_rng(11)
    n, sigma, mount, offsets = 16, 3 * A, 0.01, (20 * A, 500 * A)
    out = pr.acceptance_trials(n, rng, AZ, EL, side=side, reference_rows=rows, roll=roll,
                               mount_roll=mount, noise_sigma=sigma, offsets=offsets,
                               roll_sigma=0.07)
    assert len(calls) == n
    truth = np.array([c["truth"] for c in calls])
    assert np.all((np.abs(truth) >= offsets[0]) & (np.abs(truth) <= offsets[1]))
    assert np.all(np.abs(truth[:, 0]) != np.abs(truth[:, 1]))  # two draws, not one
    # 32 signs and 16 headings of a fair draw: every sign appears (chance 2^-31 otherwise);
    # a heading above 1 and one below -1 (chance (1 - (pi - 1) / (2 pi))^16 < 1e-3 each)
    assert (truth > 0).any(axis=0).all() and (truth < 0).any(axis=0).all()
    assert (np.sign(truth[:, 0]) != np.sign(truth[:, 1])).any()  # one sign each (2^-15)
    heading = np.array([c["frame_heading"] for c in calls])
    assert np.all((heading >= -math.pi) & (heading < math.pi))
    assert heading.max() > 1 and heading.min() < -1
    for c in calls:
        assert c["rng"] is rng
        assert c["noise"] == Noise(sigma, sigma, sigma, sigma, 0.0 if roll == "level" else mount)
        assert (c["side"], c["reference_rows"], c["with_roll"]) == (side, rows, roll == "recorded")
        assert (c["data"].center is not None) == rows
        assert c["fit"] == {"side": side, "free_roll": roll == "free", "roll_sigma": 0.07,
                            "sigma_ins": sigma, "sigma_theodolite": sigma, "before": False}
    np.testing.assert_allclose(out["axis_az_error"], A, rtol=1e-6)
    np.testing.assert_allclose(out["axis_el_error"], -2 * A, rtol=1e-6)
    assert set(out["axis_az_sigma"]) == {3 * A} and set(out["axis_el_sigma"]) == {4 * A}
    assert set(out["chi2_red"]) == {1.5}


def test_acceptance_trials_defaults(monkeypatch):
    """Defaults: reference rows, recorded roll, right side, mount roll 1 deg, errors 2″,
    offsets 10″ to 600″, roll prior 2 deg."""
    calls = _spy(monkeypatch)
    pr.acceptance_trials(2, np.random.default_rng(1), AZ, EL)
    for c in calls:
        assert c["noise"] == Noise(2 * A, 2 * A, 2 * A, 2 * A, math.radians(1.0))
        assert (c["side"], c["reference_rows"], c["with_roll"]) == (1.0, True, True)
        assert c["fit"]["roll_sigma"] == pytest.approx(math.radians(2.0), rel=1e-15)
        assert c["fit"]["free_roll"] is False
        assert np.all((np.abs(c["truth"]) >= 10 * A) & (np.abs(c["truth"]) <= 600 * A))


@pytest.mark.parametrize(("name", "pitches", "rows", "roll", "side"), [
    ("paper-like, reference rows, recorded, left", [4, 7.5, 11, 14.5, 18], True, "recorded", -1.0),
    ("pitch to 60°, relative, free, left", [12, 24, 36, 48, 60], False, "free", -1.0),
    ("pitch to 60°, reference rows, level, right", [12, 24, 36, 48, 60], True, "level", 1.0),
])
def test_acceptance_case_runs_the_named_case(monkeypatch, name, pitches, rows, roll, side):
    """The case's name gives the layout (azimuth mirrors at -30 ... 45 deg, pitch mirrors at
    azimuth 0 and the elevations named), the rows, the roll and the side; the generator is
    seeded with the seed given; the other options are acceptance_trials' defaults."""
    seen = {}

    def trials(n, rng, az, el, **kw):
        seen.update(n=n, rng=rng, az=az, el=el, **kw)
        return "result"

    monkeypatch.setattr(pr, "acceptance_trials", trials)
    assert pr.acceptance_case(name, 7, 2031) == "result"
    assert seen.pop("n") == 7
    np.testing.assert_allclose(np.degrees(seen.pop("az")), [-30, -15, 15, 30, 45, 0, 0, 0, 0, 0],
                               atol=1e-12)
    np.testing.assert_allclose(np.degrees(seen.pop("el")), [0] * 5 + pitches, atol=1e-12)
    assert seen.pop("rng").random() == np.random.default_rng(2031).random()
    assert seen == {"side": side, "reference_rows": rows, "roll": roll}


def _reach_data(rows, with_roll=True):
    """Reference rows or relative readings, roll recorded or not, roll mirror on the left, central
    mirror at azimuth 0.3: every input pitch_reach hands its simulation differs from the
    simulator's defaults."""
    return pr.simulate_procedure(100 * A, 400 * A, AZ + 0.3, EL, Noise(0, 0, 0, 0, 0), 0,
                                 side=-1.0, az_center=0.3, reference_rows=rows,
                                 with_roll=with_roll)


@pytest.mark.parametrize(("rows", "with_roll"), [(True, True), (False, True), (False, False)])
def test_pitch_reach_stops_at_the_first_whole_degree_meeting_the_target(rows, with_roll):
    """The docstring's search, written out: the pitch mirrors' elevations scaled to a top of
    20 deg, readings simulated without error at the fitted offsets, fitted: the fit's sigma of
    gamma there (s20; without reference rows the rolls at the reference pointings are fitted
    with the prior 0.03 rad, handed to both) is the target. Just above s20 the reach is 20 deg,
    just below it 21 deg (sigma_gamma falls as the top rises: checked at 19 and 21 deg); with
    free rolls, just above the free-roll fit's s20, 20 deg. The fit's covariance and the
    search's agree to 3e-9 on noise-free readings (1e-7 with free rolls); the margins are
    1e-6."""
    d = _reach_data(rows, with_roll)
    f = pr.fit_procedure(d, side=-1.0, sigma_ins=2 * A, sigma_theodolite=2 * A, before=False)
    pitch = np.array([s == "pitch" for s in SETS])

    def sigma_gamma(top_deg, free_roll=False):
        el = np.where(pitch, EL * math.radians(top_deg) / EL.max(), EL)
        sim = pr.simulate_procedure(f.params["axis_az"], f.params["axis_el"], AZ + 0.3, el,
                                    Noise(0, 0, 0, 0, 0), 0, side=-1.0, az_center=0.3,
                                    reference_rows=rows, with_roll=with_roll)
        return pr.fit_procedure(sim, side=-1.0, free_roll=free_roll, roll_sigma=0.03,
                                sigma_ins=2 * A, sigma_theodolite=2 * A,
                                before=False).stderr["axis_az"]

    s19, s20, s21 = (sigma_gamma(t) for t in (19, 20, 21))
    assert s19 > s20 * (1 + 1e-6) and s20 > s21 * (1 + 1e-6)
    assert pr.pitch_reach(d, f, pitch, False, 0.03, target=s20 * (1 + 1e-6)) == pytest.approx(
        math.radians(20.0), rel=1e-12)
    assert pr.pitch_reach(d, f, pitch, False, 0.03, target=s20 * (1 - 1e-6)) == pytest.approx(
        math.radians(21.0), rel=1e-12)
    # free rolls: sigma_gamma about three times larger (the fitted rolls turn the offset)
    free = sigma_gamma(20, free_roll=True)
    assert free > 2 * s19
    assert pr.pitch_reach(d, f, pitch, True, 0.03, target=free * (1 + 1e-6)) == pytest.approx(
        math.radians(20.0), rel=1e-12)


def test_pitch_reach_ends_at_highest_inclusive():
    """Candidates are the whole degrees from the top mirror's (18 deg) up to ``highest``
    inclusive: a target the layout meets gives 18 deg with highest = 18 deg, None with
    highest = 17 deg; a 0/1 integer mask is a mask; pitch mirrors all horizontal give None."""
    d = _reach_data(False)
    f = pr.fit_procedure(d, side=-1.0, sigma_ins=2 * A, sigma_theodolite=2 * A, before=False)
    pitch = [0] * 5 + [1] * 5
    easy = 2 * f.stderr["axis_az"]
    assert pr.pitch_reach(d, f, pitch, False, 1.0, target=easy,
                          highest=math.radians(18.0)) == pytest.approx(math.radians(18.0))
    assert pr.pitch_reach(d, f, pitch, False, 1.0, target=easy,
                          highest=math.radians(17.0)) is None
    assert pr.pitch_reach(d, f, [1] * 5 + [0] * 5, False, 1.0, target=easy) is None
