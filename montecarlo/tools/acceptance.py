"""Acceptance of the discrepancy workflow, run through the study runner.

For each system, one study whose grid points are scenarios on a realistic layout:

* ``null``: no missing effect (ground: earth curvature and standard refraction, k = 0.13, as
  in the base model);
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
import json
import math
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from montecarlo.discrepancy import collimation_effects as ce
from montecarlo.discrepancy import ground_effects as ge
from montecarlo.discrepancy.candidate_tests import ALPHA, analyse_candidates
from montecarlo.discrepancy.design import design_mdb, inject_at_mdb
from montecarlo.discrepancy.fit import fit_model
from montecarlo.engine.runner import RunOptions, run_study
from montecarlo.geometry.camera import Camera
from montecarlo.systems import discrepancy as sd
from montecarlo.systems import study_from_dict
from montecarlo.systems.params import study_params
from montecarlo.units import ARCSEC

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


def scenarios(system: str, multiple: float = MULTIPLE) -> list[dict[str, Any]]:
    """Scenarios: label, effects expected to be named, and run_trials parameters (SI); the
    effects injected at ``multiple`` times their MDB."""
    out = [{"label": "null", "named": 0, "expected": "", "inject_mdb": 0.0}]
    out += [{"label": e, "named": 1, "expected": e, "inject_mdb": multiple}
            for e in testable_effects(system)]
    if system == "collimation":
        paper = {"axis_az": PAPER_AXIS, "axis_el": PAPER_AXIS}
        out.append({"label": "paper", "named": 1, "expected": "axis_misalignment",
                    "inject_mdb": 0.0, **paper})
        out += [{"label": f"paper+{e}", "named": 2, "expected": e, "inject_mdb": multiple,
                 **paper} for e in testable_effects(system, ("axis_misalignment",))]
    return out


OTHER_DESIGNS: dict[str, dict[str, Any]] = {
    "ground": {"fov_yaw": math.radians(60.0), "fov_pitch": math.radians(45.0), "n_x": 1280,
               "n_z": 960, "pixel_sigma": 0.2, "survey_sigma": 0.005,
               "psi": math.radians(-20.0), "theta": math.radians(10.0),
               "gamma": math.radians(-5.0)},
    "collimation": {"n_azimuth": 5, "n_pitch": 6, "azimuth_span": math.radians(120.0),
                    "pitch_span": math.radians(40.0), "theodolite_sigma": 1.0 * ARCSEC,
                    "ins_sigma": 3.0 * ARCSEC, "frame_heading": math.radians(-75.0)},
}
"""Designs the diagnosis was not developed on: another camera, field, noise and mounting;
another mirror layout and noise split."""
OUTLIER_SIZE = 10.0
"""Size of an injected wrong observation [multiples of its stated noise] (about 1.5 times
the outlier MDB of both designs, 6-7 sigma)."""
SEVERAL = {"ground": ("radial_distortion", "target_height_scale", "drift"),
           "collimation": ("frame_misalignment", "ins_scale_factor", "ins_bias")}
CONFOUNDED_PAIR = ("focal_scale", "target_range_bias")
"""Two ground effects of which one (the range bias) has a confounded partner (a lever arm)."""


def power_given(effect: str, given: tuple[str, ...], multiple: float = 2.0,
                alpha: float = ALPHA) -> dict[str, float]:
    """How detectable ``effect``, injected first at ``multiple`` times its MDB of the base
    model (as the robust ground rows inject it), stays once the ``given`` effects are in the
    model, on the ground design of :data:`OTHER_DESIGNS` (noise-free data).

    Returns ``injected`` (its first parameter [SI]), ``mdb`` (that parameter's MDB given
    ``given``, :func:`montecarlo.discrepancy.design.design_mdb`), ``lambda`` (noncentrality
    of the injection given ``given``), ``lambda0`` (its own test's, there) and ``power``: the
    probability that its own test, at its first-step size in the detection family, rejects
    once ``given`` is fitted.
    """
    p = {**sd.GROUND_DEFAULTS, **OTHER_DESIGNS["ground"]}
    camera = Camera(p["fov_yaw"], p["fov_pitch"], p["n_x"], p["n_z"])
    truth = {k: float(p[k]) for k in ("psi", "theta", "gamma")}
    layout = sd.default_layout(camera, truth)

    def exact(tr: dict[str, float]) -> Any:
        return ge.exact_problem(layout, camera, tr, float(p["pixel_sigma"]),
                                float(p["survey_sigma"]))

    problem = exact(truth)
    injection = inject_at_mdb(exact, truth, effect, multiple, alpha)
    name = problem.effect(effect).parameters[0]
    fit = fit_model(problem, given, truth)
    test = next(t for t in analyse_candidates(problem, fit, alpha) if t.name == effect)
    lam = float(np.sum((test.projected @ np.array([injection[q] for q in test.active])) ** 2))
    return {"injected": injection[name],
            "mdb": design_mdb(problem, truth, given, effect, alpha=alpha)[name],
            "lambda": lam, "lambda0": test.lambda0,
            "power": float(stats.ncx2.sf(stats.chi2.isf(test.level, test.dof), test.dof,
                                         lam))}


def robust_scenarios(system: str) -> list[dict[str, Any]]:
    """Wrong observations and several effects at once, on the other design."""
    design = OTHER_DESIGNS[system]
    one, two, three = SEVERAL[system][:1], SEVERAL[system][:2], SEVERAL[system]
    cases = [
        {"label": "null", "named": 0, "expected": "", "inject_mdb": 0.0},
        {"label": "1 outlier", "named": 0, "expected": "", "inject_mdb": 0.0,
         "n_outliers": 1, "outlier_size": OUTLIER_SIZE},
        {"label": "2 outliers", "named": 0, "expected": "", "inject_mdb": 0.0,
         "n_outliers": 2, "outlier_size": OUTLIER_SIZE},
        {"label": f"outlier + {one[0]}", "named": 1, "expected": one[0],
         "inject_mdb": MULTIPLE, "n_outliers": 1, "outlier_size": OUTLIER_SIZE},
        {"label": " + ".join(two), "named": 2, "expected": ",".join(two), "inject_mdb": 2.0},
        {"label": " + ".join(three), "named": 3, "expected": ",".join(three),
         "inject_mdb": 2.0},
        *([{"label": " + ".join(CONFOUNDED_PAIR), "named": 2,
            "expected": ",".join(CONFOUNDED_PAIR), "inject_mdb": 2.0}]
          if system == "ground" else []),
    ]
    return [{**design, **c} for c in cases]


LONG_RANGES = {"0.5-3 km": (500.0, 1000.0, 2000.0, 3000.0),
               "300-1200 m": (300.0, 600.0, 900.0, 1200.0)}
"""Target ranges [m] at which earth curvature and refraction matter."""
LONG_RANGE_DESIGN: dict[str, Any] = {
    **OTHER_DESIGNS["ground"], "fov_yaw": math.radians(30.0), "fov_pitch": math.radians(22.5),
    "n_x": 1920, "n_z": 1440}
"""A narrower camera (30 deg x 22.5 deg, 1920 x 1440 px, 0.2 px, 5 mm survey) on which a
missing curvature (1 - k = 0.87) is about one MDB of the refraction candidate at 0.5-3 km."""


def physics_scenarios() -> list[dict[str, Any]]:
    """Ground data at long ranges on :data:`LONG_RANGE_DESIGN`: null data (curvature and
    standard refraction only) at 0.5-3 km and 300-1200 m, a refraction off the standard at
    1.5 MDB at 0.5-3 km, and an aspect ratio at 1.5 MDB at 300-1200 m."""
    design = LONG_RANGE_DESIGN
    camera = Camera(design["fov_yaw"], design["fov_pitch"], design["n_x"], design["n_z"])
    mounting = {k: design[k] for k in ("psi", "theta", "gamma")}
    out = []
    for label, ranges in LONG_RANGES.items():
        layout = json.dumps(ge.field_layout(camera, mounting, ranges, (6, 6), 0.8, 3600.0, 1,
                                            rng=2024).layout())
        out.append({**design, "label": f"null, {label}", "named": 0, "expected": "",
                    "inject_mdb": 0.0, "layout": layout})
        extra = ({"label": f"refraction, {label}", "named": 1, "expected": "refraction",
                  "inject_mdb": MULTIPLE} if label == "0.5-3 km" else
                 {"label": f"aspect_ratio, {label}", "named": 1, "expected": "aspect_ratio",
                  "inject_mdb": MULTIPLE})
        out.append({**design, **extra, "layout": layout})
    return out


def run(system: str, trials: int = 500, seed: int = 2024,
        n_jobs: int | None = None, cases: list[dict[str, Any]] | None = None) -> pd.DataFrame:
    """Run the acceptance study of ``system`` and summarise each scenario (one row each);
    ``cases`` default to :func:`scenarios`."""
    study_system, defaults = ((sd.GROUND, sd.GROUND_DEFAULTS) if system == "ground"
                              else (sd.COLLIMATION, sd.COLLIMATION_DEFAULTS))
    cases = scenarios(system) if cases is None else cases
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
            "injected": (injected_text(system, case)
                         if not set(case) & set(OTHER_DESIGNS[system]) else ""),
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
            "wrong_named": np.nanmean(col("n_wrong_named") > 0),
            "flagged_any": np.nanmean(col("n_flagged") > 0),
            "outliers_found": _mean(col("outliers_found")),
            "clean_flagged": _mean(col("clean_flagged")),
            "chi2_red_before": _mean(col("chi2_red")),
            "chi2_red_after": _mean(col("chi2_red_after")),
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
        truth = {k: float(p[k]) for k in ("psi", "theta", "gamma")}
        layout = sd.default_layout(camera, truth)

        def exact(tr):
            return ge.exact_problem(layout, camera, tr, float(p["pixel_sigma"]),
                                    float(p["survey_sigma"]))
        unit = ge.display_unit
        shown_base = set()
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


def robust_markdown(table: pd.DataFrame) -> str:
    """The table of wrong observations and several effects (rates in percent)."""
    def pct(v: float) -> str:
        return "–" if not np.isfinite(v) else f"{100 * v:.1f} %"

    lines = ["| system | scenario | data sets | named or flagged (any) | right names | right "
             "names or group | wrong names | outliers flagged | clean flagged | mean χ²_red "
             "before → after |", "|" + "---|" * 10]
    for r in table.itertuples():
        lines.append(f"| {r.system} | {r.scenario} | {r.trials} | "
                     f"{pct(max(r.named_any, r.flagged_any))} | {pct(r.named_expected)} | "
                     f"{pct(r.named_or_group)} | "
                     f"{pct(r.wrong_named)} | {pct(r.outliers_found)} | "
                     f"{pct(r.clean_flagged)} | {r.chi2_red_before:.2f} → "
                     f"{r.chi2_red_after:.2f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=500)
    parser.add_argument("--seed", type=int, default=2024)
    parser.add_argument("--n-jobs", type=int, default=2)
    parser.add_argument("--system", choices=("ground", "collimation", "both"), default="both")
    parser.add_argument("--robust", action="store_true",
                        help="wrong observations and several effects, on other designs")
    parser.add_argument("--physics", action="store_true",
                        help="ground data at long ranges (earth curvature and refraction)")
    args = parser.parse_args(argv)
    if args.physics:
        print(to_markdown(run("ground", args.trials, args.seed, args.n_jobs,
                              physics_scenarios())))
        return
    systems = ("ground", "collimation") if args.system == "both" else (args.system,)
    if args.robust:
        table = pd.concat([run(s, args.trials, args.seed, args.n_jobs, robust_scenarios(s))
                           for s in systems], ignore_index=True)
        print(robust_markdown(table))
        return
    table = pd.concat([run(s, args.trials, args.seed, args.n_jobs) for s in systems],
                      ignore_index=True)
    print(to_markdown(table))


if __name__ == "__main__":
    main()
