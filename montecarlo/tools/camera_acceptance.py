"""Acceptance of ``diagnose camera`` on synthetic views (our own generator).

The design imitates Zhang's data set: a target grid (``grid`` x ``grid`` points over 14 cm)
in five views (:func:`montecarlo.camera_calibration.simulate.standard_poses`), f = 830 px on a
640 x 480 image, independent normal pixel noise ``sigma`` per coordinate. Scenarios:

* ``null``: the ideal pinhole (nothing to find);
* ``radial``: ``k1`` at ``multiple`` times its minimal detectable bias (MDB) against the pinhole;
* ``tangential``: ``p1 = p2`` at ``multiple`` times the MDB along (1, 1);
* ``bad_corner``: one corner (a different one in each set) shifted along (1, 1) by ``multiple``
  times its own MDB (data snooping).

MDBs are those of the engine on the noise-free design (:func:`design_mdb`). Per scenario: the
share of sets that name the right effect, that name it and nothing else, that name anything
(null), and (bad corner) that flag the right corner and that flag any other.
``python -m montecarlo.tools.camera_acceptance --sets 200`` prints the table.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from montecarlo.camera_calibration.simulate import (
    DEFAULT_CAMERA,
    simulate,
    standard_poses,
    target_grid,
)
from montecarlo.discrepancy import camera_effects as ce
from montecarlo.discrepancy.candidate_tests import ALPHA, analyse_candidates, family_levels
from montecarlo.discrepancy.design import design_mdb
from montecarlo.discrepancy.engine import diagnose
from montecarlo.discrepancy.fit import fit_model
from montecarlo.discrepancy.problem import OUTLIER, with_outliers
from montecarlo.io.camera_csv import CameraData

SCENARIOS = ("null", "radial", "tangential", "bad_corner")
RIGHT = {"radial": "radial_k1", "tangential": "tangential"}


def design(grid: int = 8, n_views: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Target points [m] and the views' poses (rvec, tvec)."""
    r, t = standard_poses(n_views)
    return target_grid(grid, 0.14 / (grid - 1)), r, t


def views_data(truth: Mapping[str, float], sigma: float, seed: int | None, grid: int = 8,
               corner: tuple[int, tuple[float, float]] | None = None) -> CameraData:
    """One synthetic data set; ``corner`` = (observation index, pixel shift) adds a bad
    corner."""
    points, r, t = design(grid)
    pts, pix, view = simulate(points, truth, r, t, sigma, seed)
    if corner is not None:
        pix = pix.copy()
        pix[corner[0]] += corner[1]
    per = points.shape[0]
    ids = tuple(str(i % per + 1) for i in range(len(pts)))
    views = tuple(str(v + 1) for v in range(r.shape[0]))
    return CameraData(views, ids, view, pts, pix, np.arange(len(pts)) + 2)


def injections(sigma: float, grid: int = 8, multiple: float = 3.0) -> dict[str, Any]:
    """Each scenario's injection at ``multiple`` MDB on the noise-free design."""
    exact = ce.camera_problem(views_data(DEFAULT_CAMERA, 0.0, 0, grid), sigma)
    out: dict[str, Any] = {"null": {}}
    out["radial"] = {k: multiple * v
                     for k, v in design_mdb(exact, exact.start, (), "radial_k1").items()}
    out["tangential"] = {k: multiple * v
                         for k, v in design_mdb(exact, exact.start, (), "tangential").items()}
    # each corner's MDB along (1, 1), as design_mdb computes it, from one fit
    full = with_outliers(exact)
    fit = fit_model(full, (), exact.start)
    effects = analyse_candidates(replace(full, candidates=exact.candidates), fit)
    share = family_levels(ALPHA, sum(math.isfinite(t.statistic) for t in effects), True)[1]
    snoop = analyse_candidates(replace(full, candidates=full.candidates[len(
        exact.candidates):]), fit, level=lambda k: share / k)
    mdb = {}
    for i, t in enumerate(snoop):
        v = t.projected @ np.ones(t.projected.shape[1])
        size = multiple * sigma * math.sqrt(t.lambda0 / float(v @ v))  # [sigma] -> [px]
        mdb[i] = (size, size)
    out["bad_corner"] = mdb
    return out


def one_set(scenario: str, injection: Any, sigma: float, seed: int, grid: int = 8,
            alpha: float = ALPHA) -> dict[str, Any]:
    """Diagnose one data set of ``scenario`` drawn with ``seed``."""
    rng = np.random.default_rng(seed)
    corner = None
    truth = dict(DEFAULT_CAMERA)
    if scenario == "bad_corner":
        i = int(rng.integers(len(injection)))
        corner = (i, injection[i])
    else:
        truth.update(injection)
    data = views_data(truth, sigma, rng, grid, corner)
    d = diagnose(ce.camera_problem(data, sigma), alpha)
    flagged = [t.name[len(OUTLIER):] for t in d.outliers]
    right_corner = None if corner is None else \
        f"{data.views[data.view[corner[0]]]}/{data.point_id[corner[0]]}"
    return {"scenario": scenario, "seed": seed, "named": list(d.named), "flagged": flagged,
            "right_corner": right_corner}


def summarise(rows: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    for s in SCENARIOS:
        sets = [r for r in rows if r["scenario"] == s]
        if not sets:
            continue
        n = len(sets)
        entry: dict[str, float] = {"sets": n,
                                   "anything_named": sum(bool(r["named"]) for r in sets) / n,
                                   "any_corner_flagged": sum(bool(r["flagged"])
                                                             for r in sets) / n}
        if s in RIGHT:
            entry["right_named"] = sum(RIGHT[s] in r["named"] for r in sets) / n
            entry["only_right"] = sum(r["named"] == [RIGHT[s]] and not r["flagged"]
                                      for r in sets) / n
        if s == "bad_corner":
            entry["right_corner_flagged"] = sum(r["right_corner"] in r["flagged"]
                                                for r in sets) / n
            entry["other_corner_flagged"] = sum(any(f != r["right_corner"]
                                                    for f in r["flagged"]) for r in sets) / n
        out[s] = entry
    return out


def run(sets: int, seed: int = 2026, sigma: float = 0.2, grid: int = 8,
        multiple: float = 3.0, n_jobs: int = 1,
        scenarios: tuple[str, ...] = SCENARIOS) -> dict[str, dict[str, float]]:
    """``sets`` data sets per scenario, seeds ``seed + k`` (the same noise in each scenario)."""
    inj = injections(sigma, grid, multiple)
    tasks = [(s, inj[s], sigma, seed + k, grid) for s in scenarios for k in range(sets)]
    if n_jobs == 1:
        rows = [one_set(*task) for task in tasks]
    else:
        from joblib import Parallel, delayed

        rows = Parallel(n_jobs=n_jobs)(delayed(one_set)(*task) for task in tasks)
    return summarise(rows)


def format_table(table: dict[str, dict[str, float]]) -> str:
    """The acceptance rates per scenario as a Markdown table (``sets`` as a count)."""
    keys = ("sets", "anything_named", "right_named", "only_right", "any_corner_flagged",
            "right_corner_flagged", "other_corner_flagged")
    lines = ["| scenario | " + " | ".join(keys) + " |", "|---" * (len(keys) + 1) + "|"]
    for s, e in table.items():
        lines.append(f"| {s} | " + " | ".join(
            "" if k not in e else (f"{e[k]:.0f}" if k == "sets" else f"{e[k]:.3f}")
            for k in keys) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sets", type=int, default=200)
    p.add_argument("--seed", type=int, default=2026)
    p.add_argument("--sigma", type=float, default=0.2)
    p.add_argument("--grid", type=int, default=8)
    p.add_argument("--multiple", type=float, default=3.0)
    p.add_argument("--n-jobs", type=int, default=1)
    args = p.parse_args(argv)
    table = run(args.sets, args.seed, args.sigma, args.grid, args.multiple, args.n_jobs)
    print(format_table(table))


if __name__ == "__main__":
    main()
