"""Acceptance of the discrepancy workflow, run through the study runner.

For each system, one study whose grid points are scenarios on a realistic layout:

* ``null``: no missing effect (ground: earth curvature and refraction at their physical values,
  c = 1, k = 0.13, which the base model leaves out);
* one point per candidate the design can test (status ``testable`` at the base model), that
  effect injected at 1.5 times its minimal detectable bias along its default direction;
* collimation only: ``paper``, the axis offsets of a coarsely corrected instrument (0.05 deg
  each), and ``paper+<effect>``, another effect (testable once the offsets are in the model) at
  1.5 MDB on top of them.

Per scenario: how often something (the right thing) is named, the parameter coverage, and
chi2_red after adaptation inside its 99 % band. ``python -m montecarlo.tools.acceptance``
prints the table (markdown).
"""

from __future__ import annotations

import argparse
import math
from typing import Any

import numpy as np
import pandas as pd

from montecarlo.discrepancy import collimation_effects as ce
from montecarlo.discrepancy import ground_effects as ge
from montecarlo.discrepancy.design import inject_at_mdb
from montecarlo.discrepancy.engine import analyse_candidates
from montecarlo.discrepancy.fit import fit_model
from montecarlo.engine.runner import RunOptions, run_study
from montecarlo.geometry.camera import Camera
from montecarlo.systems import discrepancy as sd
from montecarlo.systems import study_from_dict
from montecarlo.systems.params import study_params

MULTIPLE = 1.5
"""Injections are at this multiple of the MDB."""
PAPER_AXIS = math.radians(0.05)
"""Axis offsets of the collimation ``paper`` scenarios [rad] (seed 003: 0.02-0.1 deg)."""


def testable_effects(system: str, model: tuple[str, ...] = ()) -> list[str]:
    """Candidates with status ``testable`` against base + ``model`` in the default design."""
    if system == "ground":
        p = sd.GROUND_DEFAULTS
        camera = Camera(p["fov_yaw"], p["fov_pitch"], p["n_x"], p["n_z"])
        truth = {k: float(p[k]) for k in ("psi", "theta", "gamma")}
        problem = ge.exact_problem(sd.default_layout(camera, truth), camera, truth,
                                   float(p["pixel_sigma"]), float(p["survey_sigma"]))
    else:
        p = sd.COLLIMATION_DEFAULTS
        sigma = math.hypot(p["theodolite_sigma"], p["ins_sigma"])
        truth = {"frame_heading": float(p["frame_heading"])}
        problem = ce.exact_problem(ce.paper_mirrors(), truth, sigma)
    fit = fit_model(problem, model)
    return [t.name for t in analyse_candidates(problem, fit) if t.status == "testable"]


def scenarios(system: str) -> list[dict[str, Any]]:
    """Scenarios: label, effects expected to be named, and run_trials parameters (SI)."""
    out = [{"label": "null", "named": 0, "expected": "", "inject_mdb": 0.0}]
    out += [{"label": e, "named": 1, "expected": e, "inject_mdb": MULTIPLE}
            for e in testable_effects(system)]
    if system == "collimation":
        paper = {"axis_az": PAPER_AXIS, "axis_el": PAPER_AXIS}
        out.append({"label": "paper", "named": 1, "expected": "axis_misalignment",
                    "inject_mdb": 0.0, **paper})
        out += [{"label": f"paper+{e}", "named": 2, "expected": e, "inject_mdb": MULTIPLE,
                 **paper} for e in testable_effects(system, ("axis_misalignment",))]
    return out


def run(system: str, trials: int = 500, seed: int = 2024,
        n_jobs: int | None = None) -> pd.DataFrame:
    """Run the acceptance study of ``system`` and summarise each scenario (one row each)."""
    study_system, defaults = ((sd.GROUND, sd.GROUND_DEFAULTS) if system == "ground"
                              else (sd.COLLIMATION, sd.COLLIMATION_DEFAULTS))
    cases = scenarios(system)
    keys = sorted({k for c in cases for k in c} - {"label", "named"})
    converted = [study_params(study_system, {k: c.get(k, defaults[k]) for k in keys})
                 for c in cases]
    sweep = {f"params.{k}": [c[k] for c in converted] for k in converted[0]}
    raw = {"study": {"name": f"discrepancy_acceptance_{system}",
                     "system": study_system.name, "trials": trials, "seed": seed,
                     "per_trial": True},
           "params": {"diagnose": 1}, "sweep": {"mode": "zip", **sweep}}
    study = study_from_dict(raw, f"<acceptance {system}>")
    result = run_study(study, RunOptions(n_jobs=n_jobs, progress=False))
    rows = []
    for case, gp in zip(cases, study.points, strict=True):
        frame = result.trials[gp.index]

        def col(name: str, frame: pd.DataFrame = frame) -> np.ndarray:
            return frame[f"default/{name}"].to_numpy(float)

        expected = bool(case["expected"])
        rows.append({
            "system": system, "scenario": case["label"],
            "trials": int(np.isfinite(col("chi2")).sum()),
            "injected": injected_text(system, case),
            "detected": np.nanmean(col("detected")),
            "named_any": np.nanmean(col("named_any")),
            "extra_named": np.nanmean(col("n_named") > case["named"]),
            "named_expected": np.nanmean(col("named_expected")) if expected else math.nan,
            "named_or_group": (np.nanmean(col("named_expected_or_group")) if expected
                               else math.nan),
            "within_2sigma": _mean(col("expected_within_2sigma")),
            "all_within_2sigma": _mean(col("expected_all_within_2sigma")),
            "after_in_band": np.nanmean(col("chi2_red_after_in_band")),
            "named_watched": np.nanmean(col("named_watched")),
        })
    return pd.DataFrame(rows)


def _mean(values: np.ndarray) -> float:
    finite = values[np.isfinite(values)]
    return float(finite.mean()) if finite.size else math.nan


def injected_text(system: str, case: dict[str, Any]) -> str:
    """The injected parameters of a scenario in display units (the design's MDB multiple)."""
    if system == "ground":
        p = sd.GROUND_DEFAULTS
        camera = Camera(p["fov_yaw"], p["fov_pitch"], p["n_x"], p["n_z"])
        truth = {k: float(p[k]) for k in ("psi", "theta", "gamma", "c", "k")}
        layout = sd.default_layout(camera, truth)

        def exact(tr):
            return ge.exact_problem(layout, camera, tr, float(p["pixel_sigma"]),
                                    float(p["survey_sigma"]))
        unit = ge.display_unit
        shown_base = set() if case["expected"] else {"c", "k"}
    else:
        p = sd.COLLIMATION_DEFAULTS
        sigma = math.hypot(p["theodolite_sigma"], p["ins_sigma"])
        truth = {"frame_heading": float(p["frame_heading"]),
                 **{k: case[k] for k in ("axis_az", "axis_el") if k in case}}
        layout = ce.paper_mirrors()

        def exact(tr):
            return ce.exact_problem(layout, tr, sigma)
        unit = ce.display_unit
        shown_base = {"axis_az", "axis_el"}
    if case["inject_mdb"] > 0:
        truth = inject_at_mdb(exact, truth, case["expected"], case["inject_mdb"])
    own = set(exact(truth).effect(case["expected"]).parameters) if case["expected"] else set()
    shown = {k: v for k, v in truth.items() if (k in own or k in shown_base) and v != 0.0}
    return ", ".join(f"{k} = {v / unit(k)[1]:.3g}{'' if unit(k)[0] == '1' else ' ' + unit(k)[0]}"
                     for k, v in shown.items())


def to_markdown(table: pd.DataFrame) -> str:
    """The acceptance table as markdown (rates in percent)."""
    head = ("| system | scenario | injected | data sets | misfit detected | named (any) | "
            "extra named | right name | right name or group | within 2σ (per parameter / all) "
            "| χ²_red after in 99 % band | watched named |")
    lines = [head, "|" + "---|" * 12]

    def pct(v: float) -> str:
        return "–" if not np.isfinite(v) else f"{100 * v:.1f} %"

    for r in table.itertuples():
        lines.append(f"| {r.system} | {r.scenario} | {r.injected or '–'} | {r.trials} | "
                     f"{pct(r.detected)} | {pct(r.named_any)} | {pct(r.extra_named)} | "
                     f"{pct(r.named_expected)} | "
                     f"{pct(r.named_or_group)} | {pct(r.within_2sigma)} / "
                     f"{pct(r.all_within_2sigma)} | {pct(r.after_in_band)} | "
                     f"{pct(r.named_watched)} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=500)
    parser.add_argument("--seed", type=int, default=2024)
    parser.add_argument("--n-jobs", type=int, default=2)
    parser.add_argument("--system", choices=("ground", "collimation", "both"), default="both")
    args = parser.parse_args(argv)
    systems = ("ground", "collimation") if args.system == "both" else (args.system,)
    table = pd.concat([run(s, args.trials, args.seed, args.n_jobs) for s in systems],
                      ignore_index=True)
    print(to_markdown(table))


if __name__ == "__main__":
    main()
