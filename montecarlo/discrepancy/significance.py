"""Practical significance of the effects a diagnosis named: what each one changes.

A test says whether an effect is in the data; with many observations a tiny one is overwhelmingly
significant. For each named effect this module refits the final model without it and reports

- the residual RMS with and without it (per residual component, the view's unit) and the
  relative change ``(rms_without - rms_with) / rms_without``;
- the largest change it makes to any reported parameter, in that parameter's standard error
  in the final model: ``max_k |x_k(with) - x_k(without)| / sigma_k(with)``.

An effect that changes the RMS by less than :data:`RMS_NEGLIGIBLE` (2 %) and no parameter by
more than :data:`SHIFT_NEGLIGIBLE` (1 sigma) is labelled ``"significant, negligible"``; any other
named effect ``"significant, important"``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from montecarlo.discrepancy.engine import Diagnosis
from montecarlo.discrepancy.fit import FitError, fit_model
from montecarlo.discrepancy.problem import is_outlier, with_outliers
from montecarlo.discrepancy.view import SystemView, residual_rms

RMS_NEGLIGIBLE = 0.02
"""Relative RMS change below which an effect does not matter for the fit's residuals."""
SHIFT_NEGLIGIBLE = 1.0
"""Parameter change [its sigma] at or below which an effect does not matter for the values."""


def practical_significance(d: Diagnosis, view: SystemView,
                           reported: Callable[[str], bool] | Sequence[str] | None = None
                           ) -> list[dict[str, Any]]:
    """One entry per named effect (see the module docstring).

    ``reported`` selects the parameters whose changes count (names, or a predicate; default:
    every parameter of the final model except observation shifts).
    """
    keep: Callable[[str], bool]
    if reported is None:
        keep = lambda name: not is_outlier(name)  # noqa: E731
    elif callable(reported):
        keep = reported
    else:
        names = set(reported)
        keep = names.__contains__

    full = with_outliers(d.problem)
    after = d.after
    rms_with = residual_rms(view, after)
    out = []
    for name in d.named:
        effects = [e for e in after.effects[1:] if e != name]
        entry: dict[str, Any] = {"name": name, "rms_with": rms_with, "rms_unit": view.rms_unit}
        try:
            without = d.without.get(name)
            if without is None:
                without = fit_model(full, effects, {k: v for k, v in after.params.items()
                                                    if k not in d.problem.effect(name).parameters})
        except FitError as exc:
            out.append({**entry, "label": "significant", "reason": str(exc)})
            continue
        rms_without = residual_rms(view, without)
        change = (rms_without - rms_with) / rms_without if rms_without > 0 else 0.0
        shifts = {k: abs(after.params[k] - without.params[k]) / after.stderr[k]
                  for k in without.names if keep(k) and after.stderr.get(k, 0.0) > 0}
        worst = max(shifts, key=lambda k: shifts[k]) if shifts else None
        largest = shifts[worst] if worst else 0.0
        negligible = change < RMS_NEGLIGIBLE and largest <= SHIFT_NEGLIGIBLE
        unit, scale = view.display_unit(worst) if worst else ("", 1.0)
        out.append({**entry, "rms_without": rms_without, "rms_change": change,
                    "largest_shift_sigma": largest, "largest_shift_parameter": worst,
                    "largest_shift": (None if worst is None else
                                      (after.params[worst] - without.params[worst]) / scale),
                    "largest_shift_unit": unit,
                    "label": "significant, negligible" if negligible else
                    "significant, important"})
    return out


def format_significance(entries: Sequence[dict[str, Any]]) -> str:
    """Text lines of :func:`practical_significance`."""
    lines = ["practical significance of each named effect (final model without it refitted):"]
    for e in entries:
        if "rms_without" not in e:
            lines.append(f"  {e['name']:<16} {e['label']} (cannot refit without it: "
                         f"{e['reason']})")
            continue
        unit = "" if e["largest_shift_unit"] in ("1", "") else f" {e['largest_shift_unit']}"
        shift = "" if e["largest_shift_parameter"] is None else (
            f"; largest parameter change {e['largest_shift_parameter']} "
            f"{e['largest_shift']:+.3g}{unit} = {e['largest_shift_sigma']:.2g} sigma")
        lines.append(f"  {e['name']:<16} {e['label']}: rms {e['rms_without']:.4g} -> "
                     f"{e['rms_with']:.4g} {e['rms_unit']} ({100 * e['rms_change']:.2f} %)"
                     f"{shift}")
    lines.append(f"  (negligible: rms change < {100 * RMS_NEGLIGIBLE:g} % and no parameter "
                 f"change > {SHIFT_NEGLIGIBLE:g} sigma)")
    return "\n".join(lines)
