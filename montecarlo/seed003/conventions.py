"""The conventions seed 003's text leaves open, decided by the data where the data can tell.

Section 3.1 puts the roll reference mirror "on the right of the device" (该装置右侧) without
saying whose right, and the text never says which way the theodolite's and the INS's azimuths
turn. The procedure's fit (:func:`montecarlo.seed003.procedure.fit_procedure`) is run under each
candidate convention and the one with the smallest chi-square is taken
(docs/reference/collimation.md,
"Conventions decided by the data"):

* **roll-mirror side** (``right``/``left``): readings relative to the INS's reference turn with
  the side through the roll mirror's pitch (``s lambda_r`` in the first-order form), so files
  without reference rows tell the sides apart by about ``|lambda|``. With reference rows the
  relative readings are computed from absolute ones under the same side as the model, so the
  side does not change the fit at all (identical chi-square): it is reported as undecidable.
* **relative azimuth sense** (``same``/``opposite``): whether the theodolite's azimuth turns
  the same way as the INS heading. Opposite senses read the azimuth mirrors at ``-alpha``
  instead of ``alpha``, which any spread of azimuth mirrors shows.

What the data cannot tell, and why (tested in ``tests/test_collimation_conventions.py``):

* **the common azimuth sense**: turning both azimuths the other way is the mirror image of the
  whole set-up (x -> -x in every frame), which maps a roll mirror on the right to one on the left,
  gamma to -gamma and every roll to its negative, and leaves pitch and lambda unchanged. Data of
  counter-clockwise instruments with the mirror on the right are exactly data of clockwise ones
  with the mirror on the left; the side chosen is therefore "the side, if the azimuths turn
  clockwise".
* **the INS's rotation order** (heading, pitch, roll: Z-X-Y about the INS's up, right and
  forward axes, the order of Chinese INS practice): another order changes absolute readings
  only through the roll, ``R_z R_x R_y(0) = R_z R_y(0) R_x``, so on a level mount absolute
  readings cannot tell the orders apart. It is not fitted: relative readings are the INS's
  attitude relative to its reference, whose roll is of the order of lambda even on a level mount,
  and a recorded roll enters directly, so data of another order show as a misfit.

References
----------
seed 003, section 3.1 (fixture: roll mirror on the right) and section 3.2 (procedure).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
from scipy import stats

from montecarlo.seed003.procedure import NotDetermined, ProcedureData, ProcedureFit, fit_procedure
from montecarlo.seed003.reference import SIDES
from montecarlo.units import ARCSEC

STATED_SIDE = "right"
"""The side the text states (seed 003, section 3.1: 该装置右侧安装一块基准镜)."""

SENSES = {"same": 1.0, "opposite": -1.0}
"""Theodolite azimuth sense relative to the INS heading (surveying instruments and INS headings
both read clockwise seen from above: ``same``)."""

STATED_SENSE = "same"

REJECT_ALPHA = 0.01
"""The data reject a convention when its chi-square exceeds the best one's by more than the
``1 - REJECT_ALPHA`` quantile of chi2(1), in units of the best fit's variance factor."""


@dataclass(frozen=True)
class Choice:
    """One convention decided by the data.

    Attributes
    ----------
    name : ``"roll_mirror"`` or ``"azimuth_sense"``.
    chosen, stated : the option used, and the one the user (or the text) stated.
    chi2 : option -> chi-square of the fit under it, all with the same reading sigmas.
    decided : the data tell the options apart (the worse one is rejected).
    reason : why not, when not decided.
    """

    name: str
    chosen: str
    stated: str
    chi2: dict[str, float]
    decided: bool
    reason: str = ""
    chi2_weights: str = "the given sigmas"
    """The reading sigmas the chi-squares are at (``"1 arcsec per reading"`` when the fit's
    sigmas are estimated a posteriori, so that the options compare)."""

    @property
    def rejects_stated(self) -> bool:
        """The data reject the stated option (a warning when it is not the one used)."""
        return self.decided and self.stated != min(self.chi2, key=self.chi2.__getitem__)

    def to_json(self) -> dict[str, object]:
        return {"chosen": self.chosen, "stated": self.stated,
                **{f"chi2_{k}": (v if math.isfinite(v) else None)
                   for k, v in self.chi2.items()},
                "weights": self.chi2_weights, "decided": self.decided,
                "rejects_stated": self.rejects_stated, "reason": self.reason}

    def warning(self) -> str | None:
        """One line when the data reject the stated option, else None."""
        if not self.rejects_stated:
            return None
        best = min(self.chi2, key=self.chi2.__getitem__)
        label = {"roll_mirror": "roll mirror on the {}",
                 "azimuth_sense": "theodolite azimuth turning the {} way as the INS heading"}
        used = (f"using {best}" if self.chosen == best
                else f"kept as asked ({self.chosen})")
        return (f"warning: the data reject the {label[self.name].format(self.stated)} "
                f"(chi2 {self.chi2[self.stated]:.4g} against {self.chi2[best]:.4g} for "
                f"{best}); {used}")


def with_sense(data: ProcedureData, sense: str) -> ProcedureData:
    """The data with the theodolite's azimuths turned to the INS heading's sense."""
    if SENSES[sense] > 0:
        return data
    return dataclasses.replace(data, theodolite_az=-np.asarray(data.theodolite_az))


def mirror_image(data: ProcedureData) -> ProcedureData:
    """The mirror image of a calibration (x -> -x): every azimuth, heading and roll negated.

    Used to show that the common azimuth sense cannot be told from the roll-mirror side.
    """
    roll = None if data.ins_roll is None else -np.asarray(data.ins_roll)
    return dataclasses.replace(data, theodolite_az=-np.asarray(data.theodolite_az),
                               ins_az=-np.asarray(data.ins_az), ins_roll=roll)


def decide(name: str, chi2: Mapping[str, float], stated: str, forced: str | None,
            scale: float, reason_if_equal: str) -> Choice:
    best = min(chi2, key=chi2.__getitem__)
    worst = max(chi2, key=chi2.__getitem__)
    gap = (chi2[worst] - chi2[best]) / scale
    tie = gap <= 1e-9 * max(1.0, chi2[best] / scale)
    decided = gap > stats.chi2.isf(REJECT_ALPHA, 1)
    reason = ""
    if tie:
        reason = reason_if_equal
    elif not decided:
        reason = (f"chi2 differs by {gap:.3g} (variance units), less than the "
                  f"{1 - REJECT_ALPHA:.0%} quantile of chi2(1)")
    chosen = forced or (stated if tie else best)
    return Choice(name, chosen, stated, dict(chi2), bool(decided), reason)


def fit_with_conventions(data: ProcedureData, *, side: str = "auto", sense: str = "auto",
                         sigma_ins: float | None = None, sigma_theodolite: float | None = None,
                         fit: Callable[..., ProcedureFit] = fit_procedure, **kwargs
                         ) -> tuple[ProcedureFit, ProcedureData, dict[str, Choice]]:
    """Fit under every roll-mirror side and azimuth sense; use the one the data support.

    The sense is decided on level-mount fits (an opposite sense misreads every azimuth mirror,
    by far more than any roll), the side on fits of the kind asked (``free_roll``). All are
    fitted with the same reading sigmas (the given ones, or 1″ each when
    they are to be estimated a posteriori, so that the chi-squares compare). The side and the
    sense with the smallest chi-square are taken under ``"auto"``; a stated option
    (``side="right"`` ...) is used as stated and only compared. The returned fit is then redone
    with the sigmas as asked.

    Parameters
    ----------
    data : ProcedureData as read from the file.
    side : ``"auto"``, ``"right"`` or ``"left"``.
    sense : ``"auto"``, ``"same"`` or ``"opposite"``.
    sigma_ins, sigma_theodolite : as :func:`fit_procedure` (None, None: a posteriori).
    fit : the fitting function (:func:`fit_procedure`).
    kwargs : passed on to ``fit`` (``free_roll``, ``roll_sigma``, ``before``).

    Returns
    -------
    fit, data : the fit under the chosen conventions and the data it was fitted to (the
        theodolite azimuths turned when the sense is ``opposite``).
    choices : ``{"roll_mirror": Choice, "azimuth_sense": Choice}``.
    """
    given = sigma_ins is not None or sigma_theodolite is not None
    s_ins, s_theo = (sigma_ins, sigma_theodolite) if given else (ARCSEC, ARCSEC)

    def chi2_under(sd: str, sn: str, options: Mapping[str, object]) -> tuple[float, int]:
        try:
            f = fit(with_sense(data, sn), side=SIDES[sd], sigma_ins=s_ins,
                    sigma_theodolite=s_theo, **{**options, "before": False})
        except (ValueError, np.linalg.LinAlgError):  # no solution under this convention
            return math.inf, 1
        return f.chi2, f.dof

    # the sense, from the level-mount fit (an opposite sense misreads every azimuth mirror)
    level = {k: v for k, v in kwargs.items() if k != "free_roll"}
    senses = list(SENSES) if sense == "auto" else [sense]
    by_sense = {(sd, sn): chi2_under(sd, sn, level) for sn in senses for sd in SIDES}
    finite = [v for v in by_sense.values() if math.isfinite(v[0])]
    if not finite:
        raise NotDetermined("the mirrors do not determine the offsets under any convention")
    chi2_best, dof_best = min(finite)
    scale = 1.0 if given else max(chi2_best / max(dof_best, 1), 1e-300)
    sense_chi2 = {sn: min(by_sense[sd, sn][0] for sd in SIDES) for sn in senses}
    if len(senses) == 1:
        sense_choice = Choice("azimuth_sense", sense, sense, sense_chi2, False,
                              "stated, not compared")
    else:
        sense_choice = decide("azimuth_sense", sense_chi2, STATED_SENSE, None, scale,
                               "the azimuth mirrors cannot tell the senses apart")
    sn = sense_choice.chosen
    if kwargs.get("free_roll"):
        side_fits = {sd: chi2_under(sd, sn, kwargs) for sd in SIDES}
        finite = [v for v in side_fits.values() if math.isfinite(v[0])]
        if finite and not given:
            chi2_best, dof_best = min(finite)
            scale = max(chi2_best / max(dof_best, 1), 1e-300)
    else:
        side_fits = {sd: by_sense[sd, sn] for sd in SIDES}
    side_chi2 = {sd: side_fits[sd][0] for sd in SIDES}
    side_choice = decide("roll_mirror", side_chi2,
                          STATED_SIDE if side == "auto" else side,
                          None if side == "auto" else side, scale,
                          "with reference rows the side does not change the fit" if
                          data.has_reference else "the readings do not depend on the side")
    chosen = with_sense(data, sn)
    result = fit(chosen, side=SIDES[side_choice.chosen], sigma_ins=sigma_ins,
                 sigma_theodolite=sigma_theodolite, **kwargs)
    weights = "the given sigmas" if given else "1 arcsec per reading"
    return result, chosen, {k: dataclasses.replace(c, chi2_weights=weights) for k, c in
                            (("roll_mirror", side_choice), ("azimuth_sense", sense_choice))}
