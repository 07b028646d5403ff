"""Identifiability beside detectability: PCI and MIB by Monte Carlo through the study runner.

The minimal detectable bias (MDB) of a candidate says how large its effect must be for the
global test to *detect* a misfit (power 0.8). With several candidates, the size at which the
diagnosis *names the right one* is larger: the probability of correct identification (PCI) at
a size, and the minimal identifiable bias (MIB), the size at which the PCI reaches a target
(Imparato, Teunissen & Tiberius, Survey Review 2019).

Both are estimated by simulation on a design: data sets of the study system
(``discrepancy_ground``, ``discrepancy_collimation``) are drawn from the design's model with
the candidate's effect at a size (``inject_mdb`` times its design MDB along its default
direction, given the other effects present, or at stated parameter values) and diagnosed by
the DIA engine; the PCI is the share of sets in which the candidate is among the named effects
(``named_expected``). Every evaluation is one :func:`montecarlo.engine.runner.run_study` with
the same seed, so every size sees the same noise (common random numbers): the simulated PCI
is then a monotone step function of the size in nearly every set, and the MIB is searched by
bisection on the multiple of the MDB (geometric midpoints, to a relative width ``tol``), then
interpolated in log(multiple) between the bracket's ends.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from montecarlo.engine.runner import RunOptions, run_study
from montecarlo.systems import discrepancy as sd
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
    """The MIB of ``effect`` as a multiple of its design MDB, and every PCI evaluated.

    Bracket: start at [1, 2] MDB, double the upper end while its PCI is below ``target``,
    halve the lower end while its PCI reaches it (within :data:`MULTIPLE_RANGE`); then
    bisect at geometric midpoints until ``upper / lower - 1 <= tol``. Returns the multiple
    where the PCI, linear in log(multiple) between the bracket's ends, reaches ``target``
    (the upper end if the lower one already reaches it), ``inf`` if no multiple in the range
    does. Every evaluation uses ``seed`` (common random numbers).
    """
    seen: dict[float, float] = {}

    def at(m: float) -> float:
        if m not in seen:
            seen[m] = pci(system, design, effect, [m], sets, seed, n_jobs, parameters)[0]
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


def annotate(report: dict[str, Any], d: Any, view: Any, target: float = PCI_TARGET,
             sets: int = 100, seed: int = 0, n_jobs: int | None = 1) -> dict[str, Any]:
    """Add ``pci``, ``pci_size``, ``mib``, ``mib_mdb`` to each testable base-model candidate of
    a diagnosis's JSON ``report`` (:func:`montecarlo.discrepancy.view.to_json`), on the data's
    own design: its layout, noise and final model (``view.study_params(d.after)``).

    ``pci`` is at the fitted size for a named effect (``pci_size`` "fitted"), at its MDB for
    the others ("1 MDB"); ``mib`` is ``mib_mdb`` times the candidate's MDB (display units, as
    ``mdb``): its MDB given the final model where it is testable there (``mib_of`` "final
    model MDB", the context of the injection), else its base-model MDB ("base model MDB",
    e.g. a named effect when others are named too: then approximate); ``None`` where no
    multiple up to :data:`MULTIPLE_RANGE` reaches ``target``.
    A candidate that cannot be injected given the final model's effects (absorbed or
    undetectable there) gets ``pci``, ``mib`` ``None`` and ``identifiability_reason``.
    """
    design = view.study_params(d.after)
    system = view.study_system
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
            m, _ = mib_multiple(system, design, name, target, sets, seed, n_jobs,
                                parameters=parameters)
            (c["pci"],) = pci(system, design, name, [size], sets, seed, n_jobs, parameters)
        except ValueError as exc:  # not injectable given the final model's effects
            c.update(pci=None, mib=None, mib_mdb=None, identifiability_reason=str(exc))
            continue
        after = next((a for a in report.get("candidates_after", ())
                      if a["name"] == name and a["status"] == "testable" and a["mdb"]), None)
        reference = c["mdb"] if after is None else after["mdb"]
        c["mib_mdb"] = m if math.isfinite(m) else None
        c["mib_of"] = "base model MDB" if after is None else "final model MDB"
        c["mib"] = ({k: m * v for k, v in reference.items()} if math.isfinite(m) else None)
    report["identifiability"] = {"pci_target": target, "sets": sets, "seed": seed,
                                 "search": "bisection on the multiple of the MDB, common "
                                           "random numbers, relative width 0.02, "
                                           "interpolated in log(multiple)"}
    return report


def format_table(report: Mapping[str, Any]) -> str:
    """The candidates' MDB, MIB and PCI as text lines."""
    info = report["identifiability"]
    lines = [f"identifiability ({info['sets']} simulated sets per size, MIB at PCI "
             f"{info['pci_target']:.2f}):",
             f"  {'candidate':<24} {'MDB':<28} {'MIB':<34} PCI"]
    for c in report["candidates"]:
        if "pci" not in c:
            continue
        def show(values: Mapping[str, float], c: Mapping[str, Any] = c) -> str:
            return ", ".join(f"{k} {v:.3g}" + ("" if c["units"][k] == "1" else
                                               f" {c['units'][k]}") for k, v in values.items())

        mdb = show(c["mdb"])
        mib = ("not reached" if c["mib"] is None else
               show(c["mib"]) + f" ({c['mib_mdb']:.2f} x {c['mib_of']})")
        if c["pci"] is None:
            lines.append(f"  {c['name']:<24} {mdb:<28} {c['identifiability_reason']}")
            continue
        lines.append(f"  {c['name']:<24} {mdb:<28} {mib:<34} {c['pci']:.2f} at "
                     f"{c['pci_size']}")
    return "\n".join(lines)
