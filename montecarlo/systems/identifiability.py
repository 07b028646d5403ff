"""Identifiability beside detectability: PCI and MIB of a diagnosis's candidates.

The minimal detectable bias (MDB) of a candidate says how large its effect must be for its own
test to *detect* it (power 0.8). With several candidates, the size at which the diagnosis
*names the right one* is larger: the probability of correct identification (PCI) at a size,
and the minimal identifiable bias (MIB), the size at which the PCI reaches a target
(Imparato, Teunissen & Tiberius, Survey Review 2019).

Two estimates, on a design (a study system's parameters: layout, noise, the effects present):

- **linear** (:func:`linear_pci`, :func:`linear_mib_multiple`; the numbers ``diagnose
  --identifiability`` reports): the first step of the diagnosis on the linearised model,
  simulated whitened misclosures, thousands of sets a second
  (:mod:`montecarlo.discrepancy.identification_rates`);
- **nonlinear** (:func:`pci`, :func:`mib_multiple`; its check, ``--check-sets``): data sets of
  the study system (``discrepancy_ground``, ``discrepancy_collimation``) drawn from the
  design's model with the candidate's effect at a size (``inject_mdb`` times its design MDB
  along its default direction, given the other effects present, or at stated parameter
  values) and diagnosed by the whole DIA engine through
  :func:`montecarlo.engine.runner.run_study`; the PCI is the share of sets in which the
  candidate is among the named effects (``named_expected``).

Every evaluation uses the same seed, so every size sees the same noise (common random
numbers): the simulated PCI is then a monotone step function of the size in nearly every set,
and the MIB is searched by bisection on the multiple of the MDB (:func:`search_mib`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

from montecarlo.discrepancy.candidate_tests import ALPHA
from montecarlo.discrepancy.design import design_mdb, mdb_context
from montecarlo.discrepancy.fit import fit_model
from montecarlo.discrepancy.identification_rates import (
    FirstStep,
    FloatArray,
    LinearRates,
    first_step,
    signal,
)
from montecarlo.discrepancy.problem import Problem
from montecarlo.engine.runner import RunOptions, run_study
from montecarlo.lsq import LeastSquaresFit
from montecarlo.systems import discrepancy as sd
from montecarlo.systems.discrepancy import exact_design
from montecarlo.systems.params import ParamSystem, study_params

PCI_TARGET = 0.8
"""Default PCI at which the MIB is stated."""
MULTIPLE_RANGE = (1.0 / 16.0, 64.0)
"""Multiples of the MDB the MIB search explores; beyond them the MIB is reported as absent."""

SYSTEMS: dict[str, ParamSystem] = {s.name: s for s in (sd.GROUND, sd.COLLIMATION)}


def pci(system: str, design: Mapping[str, Any], effect: str,
        sizes: Sequence[float | Mapping[str, float]], sets: int, seed: int,
        n_jobs: int | None = 1, parameters: Sequence[str] = ()) -> list[float]:
    """PCI of ``effect`` at each of ``sizes`` on ``design``, over ``sets`` simulated sets.

    Parameters
    ----------
    system : study system name (:data:`SYSTEMS`).
    design : that system's ``run_trials`` parameters (SI), e.g. a view's ``study_params``;
        ``effect``'s ``parameters`` are set to zero in it before each size is applied.
    sizes : a float is a multiple of the design MDB (``inject_mdb``); a mapping gives the
        effect's parameter values [SI] (e.g. the fitted ones).
    sets, seed : data sets per size and the study seed (the same seed for every size: common
        random numbers).

    Returns
    -------
    The share of sets, per size, in which ``effect`` is named [1] (failed fits left out).
    """
    study_system = SYSTEMS[system]
    stated = {k for s in sizes if isinstance(s, Mapping) for k in s}
    base = {**design, **dict.fromkeys((*parameters, *stated), 0.0), "diagnose": 1,
            "expected": effect, "inject_mdb": 0.0}
    cases = []
    for s in sizes:
        if isinstance(s, Mapping):
            cases.append({**base, **{k: float(v) for k, v in s.items()}})
        else:
            cases.append({**base, "inject_mdb": float(s)})
    converted = [study_params(study_system, c) for c in cases]
    common = {k: v for k, v in converted[0].items() if all(c[k] == v for c in converted)}
    raw: dict[str, Any] = {
        "study": {"name": f"identifiability_{effect}", "system": study_system.name,
                  "trials": int(sets), "seed": int(seed), "per_trial": True},
        "params": common}
    varying = [k for k in converted[0] if k not in common]
    if varying:
        raw["sweep"] = {"mode": "zip", **{f"params.{k}": [c[k] for c in converted]
                                          for k in varying}}
    from montecarlo.systems import study_from_dict

    study = study_from_dict(raw, f"<identifiability {effect}>")
    result = run_study(study, RunOptions(n_jobs=n_jobs, progress=False))
    out = []
    for point in study.points:
        named = result.trials[point.index]["default/named_expected"].to_numpy(float)
        named = named[~(named != named)]  # drop NaN (a fit that failed)
        out.append(float(named.mean()) if named.size else math.nan)
    return out


def mib_multiple(system: str, design: Mapping[str, Any], effect: str,
                 target: float = PCI_TARGET, sets: int = 200, seed: int = 0,
                 n_jobs: int | None = 1, tol: float = 0.02, parameters: Sequence[str] = ()
                 ) -> tuple[float, dict[float, float]]:
    """The MIB of ``effect`` as a multiple of its design MDB by the nonlinear Monte Carlo
    (:func:`pci`, ``sets`` diagnoses per evaluation), and every PCI evaluated
    (:func:`search_mib`)."""
    return search_mib(lambda m: pci(system, design, effect, [m], sets, seed, n_jobs,
                                    parameters)[0], target, tol)


def search_mib(pci_at: Callable[[float], float], target: float = PCI_TARGET,
               tol: float = 0.02) -> tuple[float, dict[float, float]]:
    """The multiple of the MDB at which ``pci_at(multiple)`` reaches ``target``, and every
    PCI evaluated.

    Bracket: start at [1, 2] MDB, double the upper end while its PCI is below ``target``,
    halve the lower end while its PCI reaches it (within :data:`MULTIPLE_RANGE`); then
    bisect at geometric midpoints until ``upper / lower - 1 <= tol``. Returns the multiple
    where the PCI, linear in log(multiple) between the bracket's ends, reaches ``target``
    (the upper end if the lower one already reaches it), ``inf`` if no multiple in the range
    does. ``pci_at`` should use the same noise at every multiple (common random numbers).
    """
    seen: dict[float, float] = {}

    def at(m: float) -> float:
        if m not in seen:
            seen[m] = pci_at(m)
        return seen[m]

    lo, hi = 1.0, 2.0
    while at(hi) < target:
        if hi >= MULTIPLE_RANGE[1]:
            return math.inf, seen
        lo, hi = hi, 2.0 * hi
    while lo > MULTIPLE_RANGE[0] and at(lo) >= target:
        lo, hi = lo / 2.0, lo
    while hi / lo - 1.0 > tol:
        mid = math.sqrt(lo * hi)
        if at(mid) >= target:
            hi = mid
        else:
            lo = mid
    if lo >= MULTIPLE_RANGE[0] and at(lo) < target <= at(hi):
        # linear in log(multiple) between the bracket's ends
        w = (target - at(lo)) / (at(hi) - at(lo))
        return lo * (hi / lo) ** w, seen
    return hi, seen


@dataclass(frozen=True)
class LinearDesign:
    """One candidate's linearised first step on a design.

    Attributes
    ----------
    effect : the candidate.
    problem, fit : the noise-free problem of the design (the candidate's parameters at zero)
        and the fit of the model the candidate's MDB is stated against (base + the effects
        present that the design detects: :func:`montecarlo.discrepancy.design.mdb_context`),
        the linearisation point.
    step : the detection family there
        (:class:`~montecarlo.discrepancy.identification_rates.FirstStep`).
    unit : whitened signal (n,) of the candidate at 1 MDB along its default direction, the
        injection of ``inject_mdb = 1``.
    """

    effect: str
    problem: Problem
    fit: LeastSquaresFit
    step: FirstStep
    unit: FloatArray

    def signal(self, size: float | Mapping[str, float]) -> FloatArray:
        """Whitened signal of a multiple of the MDB or of stated parameter values [SI]."""
        if isinstance(size, Mapping):
            return signal(self.problem, self.fit, size)
        return float(size) * self.unit


def linear_design(system: str, design: Mapping[str, Any], effect: str,
                  parameters: Sequence[str] = ()) -> LinearDesign:
    """:class:`LinearDesign` of ``effect`` on ``design`` (as :func:`pci`: ``parameters`` set to
    zero first).

    Raises
    ------
    ValueError
        ``effect`` is absorbed, unavailable or without effect given the model it is tested
        against (it cannot be injected at a multiple of its MDB).
    """
    alpha = float(design.get("alpha", ALPHA))
    exact, truth = exact_design(SYSTEMS[system].name,
                                {**design, **dict.fromkeys(parameters, 0.0)})
    problem, base, context = mdb_context(exact, truth, effect, alpha)
    mdb = design_mdb(problem, base, context, effect, alpha=alpha)
    fit = fit_model(problem, context, base)
    step = first_step(problem, fit, alpha)
    return LinearDesign(effect, problem, fit, step, signal(problem, fit, mdb))


def linear_pci(system: str, design: Mapping[str, Any], effect: str,
               sizes: Sequence[float | Mapping[str, float]], sets: int, seed: int,
               batch: int = 5000, parameters: Sequence[str] = ()) -> list[float]:
    """:func:`pci` on the linearised first step: the share of ``sets`` simulated whitened
    misclosure vectors in which ``effect`` is named [1], at each of ``sizes`` (common random
    numbers; the same numbers whatever ``batch``)."""
    lin = linear_design(system, design, effect, parameters)
    rates = LinearRates(lin.step, sets, seed, batch)
    return [_named(rates, lin, lin.signal(s)) for s in sizes]


def _named(rates: LinearRates, lin: LinearDesign, shift: FloatArray) -> float:
    """PCI of ``lin``'s candidate; 0 where it is not a member of the family."""
    return rates.pci(lin.effect, shift) if lin.effect in lin.step.names else 0.0


def _at_multiple(rates: LinearRates, lin: LinearDesign, multiple: float) -> float:
    return _named(rates, lin, lin.signal(multiple))


def linear_mib_multiple(system: str, design: Mapping[str, Any], effect: str,
                        target: float = PCI_TARGET, sets: int = 10_000, seed: int = 0,
                        tol: float = 0.02, batch: int = 5000, parameters: Sequence[str] = ()
                        ) -> tuple[float, dict[float, float]]:
    """:func:`mib_multiple` on the linearised first step (:func:`linear_pci`)."""
    lin = linear_design(system, design, effect, parameters)
    rates = LinearRates(lin.step, sets, seed, batch)
    return search_mib(partial(_at_multiple, rates, lin), target, tol)


SEARCH = ("bisection on the multiple of the MDB, common random numbers, relative width 0.02, "
          "interpolated in log(multiple)")


def annotate(report: dict[str, Any], d: Any, view: Any, target: float = PCI_TARGET,
             sets: int = 10_000, seed: int = 0, n_jobs: int | None = 1,
             check_sets: int = 0, batch: int = 5000) -> dict[str, Any]:
    """Add ``pci``, ``pci_size``, ``mib``, ``mib_mdb`` to each testable base-model candidate of
    a diagnosis's JSON ``report`` (:func:`montecarlo.discrepancy.view.to_json`), on the data's
    own design: its layout, noise and final model (``view.study_params(d.after)``), at the
    diagnosis's ``alpha``.

    The numbers are the linearised first step's (``mode: "linear"``, :func:`linear_pci` on
    ``sets`` sets). ``pci`` is at the fitted size for a named effect (``pci_size``
    "fitted"), at its MDB for the others ("1 MDB"); ``mib`` is ``mib_mdb`` times the
    candidate's MDB (display units, as ``mdb``): its MDB given the final model where it is
    testable there (``mib_of`` "final model MDB", the context of the injection), else its
    base-model MDB ("base model MDB", e.g. a named effect when others are named too: then
    approximate); ``None`` where no multiple up to :data:`MULTIPLE_RANGE` reaches ``target``.
    A candidate that cannot be injected given the final model's effects (absorbed or
    undetectable there) gets ``pci``, ``mib`` ``None`` and ``identifiability_reason``.

    With ``check_sets`` > 0, the nonlinear Monte Carlo of the whole diagnosis (:func:`pci`,
    ``check_sets`` sets, through the study runner) checks each candidate at its ``pci_size``
    and at its linear MIB: ``check: {mode: "nonlinear", sets, pci, pci_at_mib}``.
    """
    design = {**view.study_params(d.after), "alpha": d.alpha}  # the diagnosis's own alpha
    system = view.study_system
    noise: dict[tuple, LinearRates] = {}
    for c in report["candidates"]:
        if c["status"] != "testable":
            continue
        name = c["name"]
        parameters = d.problem.effect(name).parameters
        size: float | dict[str, float] = 1.0
        if name in d.named:
            size = {p: float(d.after.params[p]) for p in parameters}
        c["pci_size"] = "fitted" if name in d.named else "1 MDB"
        try:
            lin = linear_design(system, design, name, parameters)
        except ValueError as exc:  # not injectable given the final model's effects
            c.update(pci=None, mib=None, mib_mdb=None, identifiability_reason=str(exc))
            continue
        key = (lin.step.names, tuple(lin.fit.params.items()))
        if key not in noise:  # candidates tested against the same model share the noise
            noise[key] = LinearRates(lin.step, sets, seed, batch)
        rates = noise[key]
        m, seen = search_mib(partial(_at_multiple, rates, lin), target)
        c["pci"] = seen[size] if isinstance(size, float) and size in seen else \
            _named(rates, lin, lin.signal(size))
        after = next((a for a in report.get("candidates_after", ())
                      if a["name"] == name and a["status"] == "testable" and a["mdb"]), None)
        reference = c["mdb"] if after is None else after["mdb"]
        c["mib_mdb"] = m if math.isfinite(m) else None
        c["mib_of"] = "base model MDB" if after is None else "final model MDB"
        c["mib"] = ({k: m * v for k, v in reference.items()} if math.isfinite(m) else None)
        c["mode"] = "linear"
        if check_sets:
            sizes: list[float | dict[str, float]] = [size, *([m] if math.isfinite(m) else [])]
            checked = pci(system, design, name, sizes, check_sets, seed, n_jobs, parameters)
            c["check"] = {"mode": "nonlinear", "sets": check_sets, "pci": checked[0],
                          "pci_at_mib": checked[1] if len(checked) > 1 else None}
    report["identifiability"] = {
        "mode": "linear", "pci_target": target, "sets": sets, "seed": seed,
        "model": "linearised first step of the diagnosis at the design (whitened misclosures)",
        "search": SEARCH,
        "check": ({"mode": "nonlinear", "sets": check_sets, "seed": seed,
                   "model": "the whole diagnosis of simulated data sets (study runner)"}
                  if check_sets else None)}
    return report


def format_table(report: Mapping[str, Any]) -> str:
    """The candidates' MDB, MIB and PCI as text lines, each figure's mode in the header; the
    columns as wide as their longest entry."""
    info = report["identifiability"]
    check = info.get("check")
    rows = []
    for c in report["candidates"]:
        if "pci" not in c:
            continue

        def show(values: Mapping[str, float], c: Mapping[str, Any] = c) -> str:
            return ", ".join(f"{k} {v:.3g}" + ("" if c["units"][k] == "1" else
                                               f" {c['units'][k]}") for k, v in values.items())

        if c["pci"] is None:
            rows.append((c["name"], show(c["mdb"]), c["identifiability_reason"], None))
            continue
        mib = ("not reached" if c["mib"] is None else
               show(c["mib"]) + f" ({c['mib_mdb']:.2f} x {c['mib_of']})")
        pci = f"{c['pci']:.3f} at {c['pci_size']}"
        if "check" in c:
            at_mib = c["check"]["pci_at_mib"]
            pci += f"   {c['check']['pci']:.3f}, " + ("-" if at_mib is None else
                                                       f"{at_mib:.3f}")
        rows.append((c["name"], show(c["mdb"]), mib, pci))
    wide = [max([len(head), *(len(r[k]) for r in rows if r[3] is not None or k < 2)])
            for k, head in ((0, "candidate"), (1, "MDB (base model)"), (2, "MIB (linear)"))]
    lines = [f"identifiability, linear (linearised first step, {info['sets']} simulated sets "
             f"per size; MIB at PCI {info['pci_target']:.2f})"
             + (f"; nonlinear check: the whole diagnosis on {check['sets']} sets per size"
                if check else "") + ":",
             f"  {'candidate':<{wide[0]}} {'MDB (base model)':<{wide[1]}} "
             f"{'MIB (linear)':<{wide[2]}} "
             "PCI (linear)" + ("   PCI (nonlinear): at size, at the linear MIB" if check else "")]
    for name, mdb, mib, pci in rows:
        head = f"  {name:<{wide[0]}} {mdb:<{wide[1]}} "
        lines.append(head + mib if pci is None else head + f"{mib:<{wide[2]}} {pci}")
    return "\n".join(lines)
