"""Acceptance of ``diagnose camera`` on synthetic views (our own generator).

The design imitates Zhang's data set: a target grid (``grid`` x ``grid`` points over 14 cm)
in five views (:func:`montecarlo.camera_calibration.simulate.standard_poses`), f = 830 px on a
640 x 480 image, independent normal pixel noise ``sigma`` per coordinate. Scenarios:

* ``null``: the ideal pinhole (nothing to find);
* ``radial``: ``k1`` at ``multiple`` times its minimal detectable bias (MDB) against the pinhole;
* ``tangential``: ``p1 = p2`` at ``multiple`` times the MDB along (1, 1);
* ``bad_corner``: one corner (a different one in each set) shifted along (1, 1) by ``multiple``
  times its own MDB (data snooping);
* ``radial_k2``: ``k1`` at ``K1`` and ``k2`` at ``multiple`` times its MDB against the model
  with ``k1`` (k2 is tested only with k1 in the model);
* ``view_offset``: every corner of view 3 shifted along (1, 1) by ``multiple`` times the MDB
  of the shift test of the residuals' clustering by view (an error of that view, not of the
  lens; :func:`offset_mdb`);
* ``view_noise``: view 3's noise ``VIEW_NOISE`` times the stated sigma (a sigma model too
  optimistic for one view).

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
from scipy.stats import norm

from montecarlo.camera_calibration.simulate import (
    DEFAULT_CAMERA,
    simulate,
    standard_poses,
    target_grid,
)
from montecarlo.discrepancy import camera_effects as ce
from montecarlo.discrepancy.candidate_tests import (
    ALPHA,
    POWER,
    analyse_candidates,
    family_levels,
)
from montecarlo.discrepancy.design import design_mdb
from montecarlo.discrepancy.engine import diagnose
from montecarlo.discrepancy.estimated_sigma import noncentrality_f
from montecarlo.discrepancy.fit import fit_model
from montecarlo.discrepancy.groups import clustering_by, group_cells, left_shifts
from montecarlo.discrepancy.problem import OUTLIER, Problem, with_outliers
from montecarlo.io.camera_csv import CameraData
from montecarlo.lsq import LeastSquaresFit

SCENARIOS = ("null", "radial", "tangential", "bad_corner")
MORE_SCENARIOS = ("radial_k2", "view_offset", "view_noise")
RIGHT = {"radial": "radial_k1", "tangential": "tangential", "radial_k2": "radial_k2"}
K1 = -0.2
"""k1 of the ``radial_k2`` scenario (Zhang's camera has -0.23)."""
VIEW = 2
"""The view (0-based) the view scenarios change."""
VIEW_OFFSET = 1.0
"""An offset of that view's corners [px] along each axis: the size :func:`offset_noncentrality`
takes by default (5 sigma per coordinate at 0.2 px)."""
VIEW_NOISE = 2.0
"""Noise of that view in ``view_noise`` [stated sigma]."""


def design(grid: int = 8, n_views: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Target points [m] and the views' poses (rvec, tvec)."""
    r, t = standard_poses(n_views)
    return target_grid(grid, 0.14 / (grid - 1)), r, t


def views_data(truth: Mapping[str, float], sigma: float, seed: Any, grid: int = 8,
               corner: tuple[int, tuple[float, float]] | None = None,
               view_error: tuple[float, float] = (0.0, 1.0)) -> CameraData:
    """One synthetic data set; ``corner`` = (observation index, pixel shift) adds a bad
    corner; ``view_error`` = (offset [px], noise [sigma]) of view :data:`VIEW`."""
    points, r, t = design(grid)
    rng = np.random.default_rng(seed)
    pts, pix, view = simulate(points, truth, r, t, sigma, rng)
    if corner is not None or view_error != (0.0, 1.0):
        pix = pix.copy()
    if corner is not None:
        pix[corner[0]] += corner[1]
    one = view == VIEW
    pix[one] += view_error[0]
    pix[one] += math.sqrt(view_error[1] ** 2 - 1.0) * sigma * rng.standard_normal(
        (int(one.sum()), 2))
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
    k1 = {**DEFAULT_CAMERA, "k1": K1}
    with_k1 = ce.camera_problem(views_data(k1, 0.0, 0, grid), sigma)
    out["radial_k2"] = {"k1": K1, **{k: multiple * v for k, v in design_mdb(
        with_k1, {**with_k1.start, "k1": K1}, ("radial_k1",), "radial_k2").items()}}
    out["view_offset"] = (multiple * offset_mdb(sigma, grid), 1.0)
    out["view_noise"] = (0.0, VIEW_NOISE)
    return out


def _pinhole(sigma: float, grid: int) -> tuple[CameraData, Problem, LeastSquaresFit]:
    """The noise-free design, its problem and the pinhole's fit."""
    data = views_data(DEFAULT_CAMERA, 0.0, 0, grid)
    problem = ce.camera_problem(data, sigma)
    return data, problem, fit_model(problem, (), problem.start)


def offset_noncentrality(sigma: float = 0.2, grid: int = 16, view: int = VIEW,
                         offset: float = VIEW_OFFSET) -> float:
    """Noncentrality lambda [1] that every corner of ``view`` shifted by ``offset`` [px] along
    (1, 1) leaves once the pinhole (focal length, principal point, every view's pose) is
    refitted: ``|(I - P_A) s|^2``, ``s`` the whitened shift and ``A`` the whitened Jacobian of
    the noise-free design. What a view's pose takes up of the shift is in the column space
    of ``A``: no test sees it."""
    data, _, fit = _pinhole(sigma, grid)
    q = fit.column_basis
    shift = np.repeat(data.view == view, 2) * offset / sigma
    left = shift - q @ (q.T @ shift)
    return float(left @ left)


def offset_mdb(sigma: float = 0.2, grid: int = 16, view: int = VIEW) -> float:
    """Minimal detectable offset [px] of every corner of ``view`` along (1, 1) for the shift
    test of the residuals' clustering by view (:func:`~montecarlo.discrepancy.groups.
    group_shift` beside the pinhole, at alpha / 2 beside the scatter test, power
    :data:`~montecarlo.discrepancy.candidate_tests.POWER`): ``sqrt(lambda0 / lambda_1px)``,
    ``lambda0`` that of its F test and ``lambda_1px`` :func:`offset_noncentrality` of 1 px
    (the shift lies in the test's columns, so the test sees all the pinhole leaves of it)."""
    data, problem, fit = _pinhole(sigma, grid)
    rank = left_shifts(fit, list(group_cells(problem, ce.view_groups(data), set()).values())
                       )[1].size
    lam0 = noncentrality_f(ALPHA / 2, rank, fit.dof - rank, POWER)
    return math.sqrt(lam0 / offset_noncentrality(sigma, grid, view, 1.0))


def most_powerful_rate(lam: float, alpha: float = ALPHA) -> float:
    """The largest probability with which a test at level ``alpha`` (whatever the model's
    parameters: the poses are unknown) rejects "no shift" when the data carry a shift that
    leaves noncentrality ``lam`` beside the model: that of the Neyman-Pearson test of this very
    shift (known direction and size), ``Phi(sqrt(lam) - z_{1-alpha})``."""
    return float(norm.cdf(math.sqrt(lam) - norm.isf(alpha)))


def one_set(scenario: str, injection: Any, sigma: float, seed: int, grid: int = 8,
            alpha: float = ALPHA) -> dict[str, Any]:
    """Diagnose one data set of ``scenario`` drawn with ``seed``."""
    rng = np.random.default_rng(seed)
    corner = None
    truth = dict(DEFAULT_CAMERA)
    view_error = (0.0, 1.0)
    if scenario == "bad_corner":
        i = int(rng.integers(len(injection)))
        corner = (i, injection[i])
    elif scenario.startswith("view_"):
        view_error = injection
    else:
        truth.update(injection)
    data = views_data(truth, sigma, rng, grid, corner, view_error)
    d = diagnose(ce.camera_problem(data, sigma), alpha)
    flagged = [t.name[len(OUTLIER):] for t in d.outliers]
    right_corner = None if corner is None else \
        f"{data.views[data.view[corner[0]]]}/{data.point_id[corner[0]]}"
    views = clustering_by(d, "view", [data.views[v] for v in data.view])
    return {"scenario": scenario, "seed": seed, "named": list(d.named), "flagged": flagged,
            "right_corner": right_corner,
            "clustered": bool(views is not None and views["rejected"]),
            "view_flagged": sum(f.split("/")[0] == data.views[VIEW] for f in flagged)}


def summarise(rows: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    for s in (*SCENARIOS, *MORE_SCENARIOS):
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
        if all("clustered" in r for r in sets):  # a generator's rows may not say
            entry["clustered"] = sum(r["clustered"] for r in sets) / n
        if s.startswith("view_"):
            entry["clustered_no_lens_term"] = sum(r["clustered"] and not r["named"]
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
            "right_corner_flagged", "other_corner_flagged", "clustered",
            "clustered_no_lens_term")
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
    p.add_argument("--scenarios", nargs="+", default=list(SCENARIOS),
                   choices=[*SCENARIOS, *MORE_SCENARIOS])
    args = p.parse_args(argv)
    table = run(args.sets, args.seed, args.sigma, args.grid, args.multiple, args.n_jobs,
                tuple(args.scenarios))
    print(format_table(table))


if __name__ == "__main__":
    main()
