"""How seed 003's open conventions are decided from chi-squares, by hand: the rejection level,
ties, stated and forced options, the warning a user reads, and which fits are compared.

The fits are replaced by a table of chi-squares (``fit_with_conventions`` takes the fitting
function as an argument), so each rule is checked on numbers chosen around its threshold.
"""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from montecarlo.seed003 import conventions as cv
from montecarlo.seed003.procedure import NotDetermined, ProcedureData
from montecarlo.units import ARCSEC

LEVEL = 6.634896601021214  # chi2(1) quantile 0.99 (scipy.stats.chi2.isf(0.01, 1))


def test_rejection_level_is_the_99_percent_quantile_of_chi2_1():
    assert stats.chi2.isf(cv.REJECT_ALPHA, 1) == pytest.approx(LEVEL, rel=1e-12)
    below = cv.decide("roll_mirror", {"right": 10.0, "left": 10.0 + 0.999 * LEVEL}, "right",
                      None, 1.0, "equal")
    above = cv.decide("roll_mirror", {"right": 10.0, "left": 10.0 + 1.001 * LEVEL}, "right",
                      None, 1.0, "equal")
    assert not below.decided and above.decided
    assert below.reason == ("chi2 differs by 6.63 (variance units), less than the 99% quantile "
                            "of chi2(1)")
    assert above.reason == "" and above.chosen == "right" and not above.rejects_stated
    assert above.warning() is None


def test_the_gap_is_counted_in_units_of_the_variance_factor():
    """A gap of 20 with a variance factor of 4 is 5 variance units: not decided."""
    c = cv.decide("roll_mirror", {"right": 30.0, "left": 10.0}, "right", None, 4.0, "equal")
    assert not c.decided and c.chosen == "left" and not c.rejects_stated
    assert c.reason.startswith("chi2 differs by 5 (variance units)")
    assert c.chi2 == {"right": 30.0, "left": 10.0}


def test_a_rejected_stated_option_warns_and_is_replaced_unless_forced():
    chi2 = {"right": 40.0, "left": 10.0}
    c = cv.decide("roll_mirror", chi2, "right", None, 1.0, "equal")
    assert c.decided and c.rejects_stated and c.chosen == "left"
    assert c.warning() == ("warning: the data reject the roll mirror on the right (chi2 40 "
                           "against 10 for left); using left")
    forced = cv.decide("roll_mirror", chi2, "right", "right", 1.0, "equal")
    assert forced.chosen == "right" and forced.rejects_stated
    assert forced.warning() == ("warning: the data reject the roll mirror on the right (chi2 40 "
                                "against 10 for left); kept as asked (right)")
    sense = cv.decide("azimuth_sense", {"same": 100.0, "opposite": 1.5}, "same", None, 1.0, "")
    assert sense.warning() == ("warning: the data reject the theodolite azimuth turning the same "
                               "way as the INS heading (chi2 100 against 1.5 for opposite); "
                               "using opposite")
    assert sense.to_json() == {"chosen": "opposite", "stated": "same", "chi2_same": 100.0,
                               "chi2_opposite": 1.5, "weights": "the given sigmas",
                               "decided": True, "rejects_stated": True, "reason": ""}


def test_a_tie_keeps_the_stated_option_with_the_reason_given():
    """Equal chi-squares (to 1e-9 of the larger of 1 and chi2/scale) cannot decide."""
    c = cv.decide("roll_mirror", {"right": 12.0, "left": 12.0 * (1 + 5e-10)}, "left", None, 1.0,
                  "the readings do not depend on the side")
    assert c.chosen == "left" and not c.decided
    assert c.reason == "the readings do not depend on the side"
    # a gap just above the tie tolerance is no tie: the best is chosen
    c = cv.decide("roll_mirror", {"right": 12.0, "left": 12.0 * (1 + 2e-9)}, "left", None, 1.0,
                  "tie")
    assert c.chosen == "right" and c.reason.startswith("chi2 differs")
    # an infinite chi-square (no solution under that convention) is written as null
    c = cv.decide("roll_mirror", {"right": 12.0, "left": math.inf}, "right", None, 1.0, "tie")
    assert c.to_json()["chi2_left"] is None and c.decided


DATA = ProcedureData(np.array([0.1, -0.2, 0.3]), np.array([0.0, 0.2, 0.4]),
                     np.array([1.0, 2.0, 3.0]), np.array([0.01, 0.02, 0.03]),
                     np.array([0.001, -0.002, 0.003]))


def test_sense_and_mirror_image():
    assert cv.with_sense(DATA, "same") is DATA
    opposite = cv.with_sense(DATA, "opposite")
    np.testing.assert_array_equal(opposite.theodolite_az, -DATA.theodolite_az)
    np.testing.assert_array_equal(opposite.ins_az, DATA.ins_az)
    image = cv.mirror_image(DATA)
    for key, sign in (("theodolite_az", -1), ("theodolite_el", 1), ("ins_az", -1),
                      ("ins_el", 1), ("ins_roll", -1)):
        np.testing.assert_array_equal(getattr(image, key), sign * getattr(DATA, key))
    no_roll = ProcedureData(DATA.theodolite_az, DATA.theodolite_el, DATA.ins_az, DATA.ins_el)
    assert cv.mirror_image(no_roll).ins_roll is None


class Table:
    """A fitting function returning chi2 from a table keyed by (side, sense, free_roll)."""

    def __init__(self, chi2, dof=10, fail=()):
        self.chi2, self.dof, self.fail, self.calls = chi2, dof, fail, []

    def __call__(self, data, *, side, sigma_ins, sigma_theodolite, before=True, **kw):
        sense = "same" if data.theodolite_az[0] == DATA.theodolite_az[0] else "opposite"
        side_name = "right" if side > 0 else "left"
        free = bool(kw.get("free_roll", False))
        self.calls.append((side_name, sense, free, sigma_ins, sigma_theodolite, before))
        if (side_name, sense) in self.fail:
            raise ValueError("no solution")
        return SimpleNamespace(chi2=self.chi2[side_name, sense, free], dof=self.dof,
                               side=side, sigma_ins=sigma_ins)


def _table(base):
    """chi2 for every (side, sense, free) from a dict over (side, sense); free fits +1."""
    return {(sd, sn, fr): v + fr for (sd, sn), v in base.items() for fr in (False, True)}


def test_the_sense_from_level_fits_and_the_side_from_fits_of_the_kind_asked():
    """chi2 (variance factor 2 = 20 / 10 dof): the opposite sense is 100 worse (rejected); the
    sides differ by 30, 15 variance units (decided). With free rolls the side is compared on
    free-roll fits; the comparisons use 1″ for both sigmas (a posteriori asked), the final fit
    the sigmas as asked."""
    table = Table(_table({("right", "same"): 20.0, ("left", "same"): 50.0,
                          ("right", "opposite"): 120.0, ("left", "opposite"): 150.0}))
    fit, data, choices = cv.fit_with_conventions(DATA, fit=table, free_roll=True)
    assert data is DATA and fit.side == 1.0 and fit.sigma_ins is None
    assert choices["azimuth_sense"].chosen == "same" and choices["azimuth_sense"].decided
    assert choices["azimuth_sense"].chi2 == {"same": 20.0, "opposite": 120.0}
    side = choices["roll_mirror"]
    assert side.chosen == "right" and side.decided and side.chi2 == {"right": 21.0, "left": 51.0}
    level = [c for c in table.calls if not c[2]]
    assert sorted(c[:2] for c in level) == sorted(
        (sd, sn) for sd in ("right", "left") for sn in ("same", "opposite"))
    assert all(c[3:] == (ARCSEC, ARCSEC, False) for c in table.calls[:-1])
    assert table.calls[-1] == ("right", "same", True, None, None, True)


def test_the_variance_factor_of_free_roll_fits_scales_the_side_gap():
    """The side fits with free rolls have chi2 121 and 101 (dof 10): variance factor 10.1, so the
    gap of 20 is 1.98 units, not decided (with the level fits' factor, 2, it would be)."""
    base = {("right", "same"): 20.0, ("left", "same"): 40.0, ("right", "opposite"): 500.0,
            ("left", "opposite"): 500.0}
    chi2 = _table(base)
    chi2["right", "same", True], chi2["left", "same", True] = 121.0, 101.0
    _, _, choices = cv.fit_with_conventions(DATA, fit=Table(chi2), free_roll=True)
    side = choices["roll_mirror"]
    assert not side.decided and side.chosen == "left"
    assert side.reason.startswith("chi2 differs by 1.98 ")


def test_given_sigmas_compare_chi2_directly_and_a_stated_sense_is_not_compared():
    table = Table(_table({("right", "same"): 20.0, ("left", "same"): 25.0,
                          ("right", "opposite"): 0.0, ("left", "opposite"): 0.0}))
    fit, _, choices = cv.fit_with_conventions(DATA, fit=table, sense="same", side="left",
                                              sigma_ins=2 * ARCSEC, sigma_theodolite=3 * ARCSEC)
    sense = choices["azimuth_sense"]
    assert (sense.chosen, sense.decided, sense.reason) == ("same", False, "stated, not compared")
    assert sense.chi2 == {"same": 20.0}
    assert all(c[1] == "same" for c in table.calls)
    assert all(c[3:5] == (2 * ARCSEC, 3 * ARCSEC) for c in table.calls)
    side = choices["roll_mirror"]  # a gap of 5 with scale 1: not decided; forced left anyway
    assert side.chosen == "left" and side.stated == "left" and not side.decided
    assert fit.side == -1.0


def test_opposite_sense_turns_the_data_and_failures_count_as_infinite():
    table = Table(_table({("right", "same"): 900.0, ("left", "same"): 0.0,
                          ("right", "opposite"): 10.0, ("left", "opposite"): 0.0}),
                  fail={("left", "same"), ("left", "opposite")})
    _, data, choices = cv.fit_with_conventions(DATA, fit=table)
    assert choices["azimuth_sense"].chosen == "opposite"
    np.testing.assert_array_equal(data.theodolite_az, -DATA.theodolite_az)
    assert choices["roll_mirror"].chi2 == {"right": 10.0, "left": math.inf}
    assert choices["roll_mirror"].chosen == "right"
    with pytest.raises(NotDetermined, match=r"^the mirrors do not determine the offsets under "
                                            r"any convention$"):
        cv.fit_with_conventions(DATA, fit=Table({}, fail={(sd, sn) for sd in ("right", "left")
                                                           for sn in ("same", "opposite")}))


def test_the_reason_a_tie_gives_depends_on_reference_rows():
    table = Table(_table({("right", "same"): 20.0, ("left", "same"): 20.0,
                          ("right", "opposite"): 90.0, ("left", "opposite"): 90.0}))
    _, _, choices = cv.fit_with_conventions(DATA, fit=table)
    assert choices["roll_mirror"].reason == "the readings do not depend on the side"
    with_rows = ProcedureData(DATA.theodolite_az, DATA.theodolite_el, DATA.ins_az, DATA.ins_el,
                              None, center=0, roll_mirror=1)
    _, _, choices = cv.fit_with_conventions(with_rows, fit=table)
    assert choices["roll_mirror"].reason == "with reference rows the side does not change the fit"
    assert choices["roll_mirror"].chosen == cv.STATED_SIDE == "right"


def test_one_sigma_given_counts_as_given():
    """Only the INS sigma given: the comparisons use it and None for the theodolite (as
    ``fit_procedure`` reads it: 0), and the chi2 gap is not scaled (a gap of 5: undecided)."""
    table = Table(_table({("right", "same"): 20.0, ("left", "same"): 25.0,
                          ("right", "opposite"): 90.0, ("left", "opposite"): 95.0}))
    _, _, choices = cv.fit_with_conventions(DATA, fit=table, sigma_ins=2 * ARCSEC)
    assert all(c[3:5] == (2 * ARCSEC, None) for c in table.calls)
    assert not choices["roll_mirror"].decided
    assert choices["roll_mirror"].reason.startswith("chi2 differs by 5 ")
    assert choices["azimuth_sense"].decided  # 70 in chi2 units


@pytest.mark.parametrize(("dof", "right", "left", "decided"), [
    (1, 4.0, 24.0, False),   # variance factor 4/1: a gap of 20 is 5 units
    (10, 5.0, 9.0, True),    # variance factor 0.5 (below 1 is allowed): 4 is 8 units
])
def test_the_variance_factor_is_the_best_chi2_per_degree_of_freedom(dof, right, left, decided):
    table = Table(_table({("right", "same"): right, ("left", "same"): left,
                          ("right", "opposite"): 900.0, ("left", "opposite"): 900.0}), dof=dof)
    _, _, choices = cv.fit_with_conventions(DATA, fit=table)
    assert choices["roll_mirror"].decided is decided and choices["roll_mirror"].chosen == "right"


def test_given_sigmas_are_not_rescaled_by_free_roll_fits():
    """sigma given, free rolls: the side fits' gap of 10 is counted in chi2 units (decided),
    not divided by their variance factor (2.1)."""
    chi2 = _table({("right", "same"): 20.0, ("left", "same"): 30.0,
                   ("right", "opposite"): 900.0, ("left", "opposite"): 900.0})
    _, _, choices = cv.fit_with_conventions(DATA, fit=Table(chi2), free_roll=True,
                                            sigma_ins=ARCSEC, sigma_theodolite=ARCSEC)
    assert choices["roll_mirror"].decided and choices["roll_mirror"].chi2 == {
        "right": 21.0, "left": 31.0}


def test_tie_tolerances_and_the_warning_names_the_best_option():
    """The tie tolerance is 1e-9 of the larger of 1 and chi2/scale: for chi2 0.5, 1e-9; for
    chi2 40 with scale 4, 1e-8 (in variance units)."""
    c = cv.decide("roll_mirror", {"right": 0.5, "left": 0.5 + 1.5e-9}, "left", None, 1.0, "tie")
    assert c.reason != "tie" and c.chosen == "right"
    c = cv.decide("roll_mirror", {"right": 40.0, "left": 40.0 + 2e-7}, "left", None, 4.0, "tie")
    assert c.reason != "tie" and c.chosen == "right"
    c = cv.decide("roll_mirror", {"right": 10.0, "left": 40.0}, "left", "left", 1.0, "tie")
    assert c.warning() == ("warning: the data reject the roll mirror on the left (chi2 40 "
                           "against 10 for right); kept as asked (left)")


def test_the_sense_choice_is_named_and_a_sense_tie_says_why():
    table = Table(_table({("right", "same"): 20.0, ("left", "same"): 20.0,
                          ("right", "opposite"): 20.0, ("left", "opposite"): 20.0}))
    _, _, choices = cv.fit_with_conventions(DATA, fit=table)
    sense = choices["azimuth_sense"]
    assert (sense.name, sense.stated, sense.chosen) == ("azimuth_sense", "same", "same")
    assert sense.reason == "the azimuth mirrors cannot tell the senses apart"
    _, _, choices = cv.fit_with_conventions(DATA, fit=table, sense="opposite")
    sense = choices["azimuth_sense"]
    assert (sense.name, sense.stated, sense.chosen) == ("azimuth_sense", "opposite", "opposite")
    table = Table(_table({("right", "same"): 900.0, ("left", "same"): 900.0,
                          ("right", "opposite"): 10.0, ("left", "opposite"): 10.0}))
    _, _, choices = cv.fit_with_conventions(DATA, fit=table)
    assert choices["azimuth_sense"].warning().startswith(
        "warning: the data reject the theodolite azimuth turning the same way as the INS "
        "heading (chi2 900 against 10 for opposite)")


@pytest.mark.parametrize(("dof", "right", "left", "decided"), [(1, 3.0, 23.0, False),
                                                                (10, 4.0, 8.0, True)])
def test_free_roll_side_fits_have_their_own_variance_factor(dof, right, left, decided):
    """Free-roll side fits (chi2 + 1 in the table): 4 and 24 with 1 dof, factor 4, a gap of 5
    units; 5 and 9 with 10 dof, factor 0.5, a gap of 8 units."""
    table = Table(_table({("right", "same"): right, ("left", "same"): left,
                          ("right", "opposite"): 900.0, ("left", "opposite"): 900.0}), dof=dof)
    _, _, choices = cv.fit_with_conventions(DATA, fit=table, free_roll=True)
    assert choices["roll_mirror"].decided is decided
