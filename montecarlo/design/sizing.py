"""Requirement sizing: the search for the cheapest design that meets a spec.

The problem (requirement, knobs, cost) is :mod:`montecarlo.design.sizing_problem`.

Search (every evaluation is a run of the study runner on a study built with
:func:`montecarlo.systems.study_from_dict`, one seed, common random numbers across points, so the
statistic is a smooth deterministic function of the knobs and monotone searches are stable):

1. **grid**: ``levels`` geometric levels per free knob, full product, one verdict per point;
2. **corners**: the Pareto-minimal points among those that meet (no other meeting point is at
   least as cheap in every knob and cheaper in one);
3. **bisection**, coordinate-wise: each knob of a corner that is not at its cheap bound is
   bisected (geometrically, to a bracket narrower than ``tolerance``) between its current value,
   which passes, and the next cheaper grid level, which does not (else the corner would not be
   Pareto-minimal; the statistic is taken to be monotone in each knob). The knobs whose
   cheapening costs least statistic per unit of cost go first. Afterwards every refined knob is
   tight: cheapening any of them by more than ``tolerance`` fails the criterion;
4. *passes* means "meets", and with the **replication margin** (default) also
   ``hi + sqrt(2) (hi - value) <= limit``: an independent run of the same size then meets the
   spec with probability about (1 + c) / 2, because the difference of two independent estimates
   has sqrt(2) times the spread of one. Without it a point on the boundary of "meets" is
   confirmed by an independent run only about half the time;
5. **limiting knob**: each refined corner is evaluated 10 % cheaper in each refined knob; the
   knob whose cheapening raises the statistic most is the limiting one (the spec binds hardest
   there). The corners are filtered to the Pareto-minimal ones again and the cheapest by cost is
   the answer;
6. **confirmation**: an independent run (another seed) at the answer, which should meet, and at
   the point 10 % cheaper in the limiting knob, which should fail. At a cost-balanced optimum
   several knobs bind at once and each carries only part of the statistic's sensitivity; the
   cheaper point may then be "undecided" unless the trials resolve a rise of a few per cent.

Everything is done separately for pixel noise common to both targets and independent between
them (the two behave oppositely with range; docs/reference/conventions.md).
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from montecarlo.design.sizing_problem import (
    RELATIONS,
    Knob,
    SizingOptions,
    SizingProblem,
    build_study,
    evaluate,
)
from montecarlo.errors import InputError


def pareto_minimal(doublings: np.ndarray, feasible: np.ndarray) -> np.ndarray:
    """Mask of feasible points that no other feasible point dominates.

    ``a`` dominates ``b`` if it costs at most as much in every knob and less in one.
    """
    d = np.asarray(doublings, float)
    feasible = np.asarray(feasible, bool)
    out = np.zeros(len(d), bool)
    idx = np.flatnonzero(feasible)
    f = d[idx]
    eps = 1e-9
    for j, i in enumerate(idx):
        le = np.all(f <= d[i] + eps, axis=1)
        lt = np.any(f < d[i] - eps, axis=1)
        out[i] = not np.any(le & lt & (np.arange(len(idx)) != j))
    return out


def cheapest(problem: SizingProblem, points: pd.DataFrame, order: Sequence[str] | None
             ) -> int:
    """Position (0-based) of the cheapest of ``points``: by ``order`` lexicographically, else
    by weighted doublings (ties broken by the knobs in their given order)."""
    d = problem.doublings(points)
    names = problem.names
    keys = [d[:, names.index(n)] for n in order] if order else [problem.cost(points)]
    keys += [d[:, i] for i in range(len(names))]
    return int(np.lexsort(list(reversed([np.round(k, 9) for k in keys])))[0])


@dataclass
class RelationSizing:
    """Sizing under one pixel-noise relation.

    Attributes
    ----------
    grid : DataFrame
        Every grid point: knob values, ``steps_<knob>`` (levels from the cheap end), value, lo,
        hi, count, invalid, verdict, margin_ok, cost, pareto.
    corners : DataFrame
        Refined, certified Pareto-minimal corners: knob values; value, lo, hi, count, invalid,
        verdict of the certification run (``search_value``, ``search_hi``: the search seed's);
        ``limiting`` knob (None if every knob is at its cheap bound); ``refined`` knobs and
        ``bad_<knob>``, the cheaper end of each final bisection bracket (did not pass in the
        search); ``cheaper_<knob>``, the statistic 10 % cheaper in that knob; ``bracket_bad``
        (``bad_`` of the limiting knob); ``grid_index`` of the originating grid corner;
        ``status``; ``cost``; ``cheapest`` (True for the answer).
    confirmation : DataFrame or None
        Independent runs at the answer and at a point 10 % cheaper in its limiting knob.
    """

    relation: str
    grid: pd.DataFrame
    corners: pd.DataFrame
    evaluations: int
    uncertified: int = 0
    """Corners of the search that did not pass with the certification seed (dropped)."""
    slice: pd.DataFrame | None = None
    """Evaluations on a plane (or line) of the plotted knobs through the answer."""
    confirmation: pd.DataFrame | None = None
    best: pd.Series | None = None
    """If nothing meets: the design with the lowest upper bound found by :func:`best_design`
    (knobs; value, lo, hi, ... of the certification seed's run; ``search_hi``)."""

    @property
    def answer(self) -> pd.Series | None:
        """The cheapest refined corner, or None if nothing within the bounds meets the spec."""
        sel = self.corners[self.corners["cheapest"]] if len(self.corners) else self.corners
        return sel.iloc[0] if len(sel) else None


@dataclass
class SizingResult:
    problem: SizingProblem
    options: SizingOptions
    relations: dict[str, RelationSizing] = field(default_factory=dict)
    unit: str = "mrad"

    def answers(self) -> pd.DataFrame:
        """One row per relation: the cheapest corner, its limiting knob and confirmation."""
        rows = []
        for rel, rs in self.relations.items():
            row: dict[str, Any] = {"pixel_relation": rel}
            a = rs.answer
            if a is None:
                row["status"] = "no design within the bounds meets the spec"
                if rs.best is not None:
                    row.update({f"best_{k}": rs.best[k]
                                for k in (*self.problem.names, "value", "lo", "hi")})
            else:
                row.update({k: a[k] for k in (*self.problem.names, "value", "lo", "hi",
                                              "verdict", "cost", "limiting", "status")})
            if rs.confirmation is not None:
                for _, c in rs.confirmation.iterrows():
                    row.update({f"{c['role']}_confirm_{k}": c[k]
                                for k in ("seed", "value", "lo", "hi", "verdict")})
            rows.append(row)
        return pd.DataFrame(rows)


def _grid_points(problem: SizingProblem, levels: int) -> pd.DataFrame:
    per_knob = [k.levels(levels) for k in problem.knobs]
    rows = []
    for steps in itertools.product(*(range(len(v)) for v in per_knob)):
        row = {k.name: float(v[s]) for k, v, s in zip(problem.knobs, per_knob, steps,
                                                       strict=True)}
        row.update({f"steps_{k.name}": s for k, s in zip(problem.knobs, steps, strict=True)})
        rows.append(row)
    return pd.DataFrame(rows)


def _refine_order(problem: SizingProblem, grid: pd.DataFrame, lookup: dict, i: int
                  ) -> list[str]:
    """Knobs of grid corner ``i`` to refine, the limiting one last.

    A knob not at its cheap bound has a cheaper grid neighbour; its *rate* is the rise of
    log(statistic) per doubling saved towards that neighbour (infinite if the neighbour has no
    valid statistic). Knobs are refined in decreasing weight / rate (slack goes first where it
    saves the most cost per unit of statistic); the last, most binding one is the limiting knob.
    """
    row = grid.loc[i]
    steps = tuple(int(row[f"steps_{n}"]) for n in problem.names)
    keyed = []
    for j, k in enumerate(problem.knobs):
        if steps[j] == 0:
            continue
        nb = grid.loc[lookup[(*steps[:j], steps[j] - 1, *steps[j + 1:])]]
        step = float(k.doublings(row[k.name]) - k.doublings(nb[k.name]))
        v0, v1 = float(row["value"]), float(nb["value"])
        rate = math.log(v1 / v0) / step if v0 > 0 and v1 > 0 and math.isfinite(v1) else math.inf
        keyed.append((k.weight / rate if rate > 0 else math.inf, -j, k.name))
    return [name for *_, name in sorted(keyed, reverse=True)]


STAT_COLUMNS = ("value", "lo", "hi", "count", "invalid", "verdict")


def _level_below(knob: Knob, value: float, levels: int) -> float:
    """The grid level one step cheaper than the grid level nearest ``value``."""
    grid = knob.levels(levels)
    s = int(np.argmin(np.abs(np.log(grid / value))))
    return float(grid[s - 1])


def _refine(problem: SizingProblem, relation: str, grid: pd.DataFrame, options: SizingOptions,
            ) -> tuple[pd.DataFrame, int]:
    """Coordinate-wise bisection of every Pareto corner; returns the corners and #evaluations.

    Each knob of a corner that is not at its cheap bound is bisected in turn (order of
    :func:`_refine_order`) between its current value, which passes, and the next cheaper grid
    level, which did not pass at the corner and (statistic monotone in each knob) cannot pass
    after other knobs became cheaper. *Passes* means meets, and with the replication margin if
    asked; a corner that meets without the margin first moves its limiting knob up the grid to
    the first level that passes. After the pass every refined knob is tight to ``tolerance``.
    """
    names = problem.names
    lookup = {tuple(int(r[f"steps_{n}"]) for n in names): i for i, r in grid.iterrows()}
    passes = grid["margin_ok"] if options.replication_margin else grid["verdict"] == "meets"
    log_tol = math.log1p(options.tolerance)
    corners: list[dict[str, Any]] = []
    active = []
    for i in np.flatnonzero(grid["pareto"].to_numpy()):
        row = grid.loc[i]
        queue = _refine_order(problem, grid, lookup, i)
        e: dict[str, Any] = {**{n: float(row[n]) for n in names},
                             **{k: row[k] for k in STAT_COLUMNS}, "grid_index": int(i),
                             "limiting": None, "bracket_bad": np.nan,
                             "status": "", "queue": queue, "bad": {}}
        corners.append(e)
        if not queue:
            e["status"] = "every knob at its cheap bound"
            continue
        if not passes[i]:
            lim = queue[-1]
            j = names.index(lim)
            steps = [int(row[f"steps_{n}"]) for n in names]
            n_levels = len(problem.knob(lim).levels(options.levels))
            up = next((lookup[key] for s in range(steps[j] + 1, n_levels)
                       if passes[lookup[key := (*steps[:j], s, *steps[j + 1:])]]), None)
            if up is None:
                e["status"] = "replication margin not reached within the bounds"
                continue
            e.update({lim: float(grid.loc[up, lim]), **{k: grid.loc[up, k] for k in STAT_COLUMNS},
                      "status": f"{lim} moved up the grid for the replication margin"})
        e["bad"] = {queue[0]: _level_below(problem.knob(queue[0]), e[queue[0]], options.levels)}
        active.append(e)

    def current(e: dict[str, Any]) -> str | None:
        """The knob being bisected, after moving past knobs whose bracket is tight."""
        while e["queue"]:
            knob = e["queue"][0]
            if abs(math.log(e[knob] / e["bad"][knob])) > log_tol:
                return knob
            e["queue"].pop(0)
            if e["queue"]:
                nxt = e["queue"][0]
                e["bad"][nxt] = _level_below(problem.knob(nxt), e[nxt], options.levels)
        return None

    evaluations = 0
    for round_ in itertools.count():
        todo = [(e, knob) for e in active if (knob := current(e)) is not None]
        if not todo:
            break
        mids = []
        for e, knob in todo:
            mid = {n: e[n] for n in names}
            mid[knob] = math.sqrt(e[knob] * e["bad"][knob])
            mids.append(mid)
        res = evaluate(problem, mids, relation, trials=options.trials, seed=options.seed,
                       block_size=options.block_size, n_jobs=options.n_jobs,
                       name=f"sizing-{relation}-bisect{round_}")
        evaluations += len(mids)
        ok = res["margin_ok"] if options.replication_margin else res["verdict"] == "meets"
        for (e, knob), mid, (_, r), good in zip(todo, mids, res.iterrows(), ok, strict=True):
            if good:
                e.update({knob: mid[knob], **{k: r[k] for k in STAT_COLUMNS}})
            else:
                e["bad"][knob] = mid[knob]
    for e in corners:
        e["refined"] = ",".join(e["bad"])
        if e["bad"]:
            e["status"] = "; ".join(filter(None, [
                e["status"], f"bisected to {options.tolerance:.0%}: " + ", ".join(e["bad"])]))
        e.update({f"bad_{n}": e["bad"].get(n, np.nan) for n in names})
        del e["queue"], e["bad"]
    return pd.DataFrame(corners), evaluations


def _probe(problem: SizingProblem, relation: str, corners: pd.DataFrame, options: SizingOptions
           ) -> tuple[pd.DataFrame, int]:
    """Evaluate each corner 10 % cheaper in each refined knob; the knob whose cheapening raises
    the statistic most is the corner's limiting knob (columns ``cheaper_<knob>``)."""
    corners = corners.copy()
    jobs = [(i, knob) for i, c in corners.iterrows() if c["verdict"] == "meets"
            for knob in filter(None, c["refined"].split(","))]
    for n in problem.names:
        corners[f"cheaper_{n}"] = np.nan
    if not jobs:
        return corners, 0
    points = []
    for i, knob in jobs:
        point = {n: float(corners.loc[i, n]) for n in problem.names}
        point[knob] = problem.knob(knob).cheaper_by(point[knob])
        points.append(point)
    res = evaluate(problem, points, relation, trials=options.trials, seed=options.seed,
                   block_size=options.block_size, n_jobs=options.n_jobs,
                   name=f"sizing-{relation}-probe")
    for (i, knob), v in zip(jobs, res["value"].fillna(np.inf), strict=True):
        corners.loc[i, f"cheaper_{knob}"] = v
    for i in {i for i, _ in jobs}:
        rises = corners.loc[i, [f"cheaper_{n}" for n in problem.names]].astype(float)
        knob = rises.idxmax().removeprefix("cheaper_")
        corners.loc[i, "limiting"] = knob
        corners.loc[i, "bracket_bad"] = corners.loc[i, f"bad_{knob}"]
    return corners, len(points)


MAX_CERTIFY_STEPS = 25


def _certify(problem: SizingProblem, relation: str, corners: pd.DataFrame,
             options: SizingOptions) -> tuple[pd.DataFrame, int]:
    """Re-evaluate every corner with the independent certification seed.

    The search picks the cheapest of many noisy evaluations, so its own estimates at the picked
    points are biased low (the winner's curse). A corner that does not pass with fresh random
    numbers moves its limiting knob dearer in steps of ``tolerance`` until it does (at most
    :data:`MAX_CERTIFY_STEPS`, within the bounds). The statistic columns then hold the
    certification's numbers; ``search_value``/``search_hi`` keep the search's.
    """
    if not len(corners):
        return corners, 0
    seed = options.certification_seed
    corners = corners.copy()
    corners["search_value"] = corners["value"]
    corners["search_hi"] = corners["hi"]
    corners["certified"] = False
    steps = {i: 0 for i, c in corners.iterrows() if c["verdict"] == "meets"}
    todo = list(steps)
    evaluations = 0
    while todo:
        points = [{n: float(corners.loc[i, n]) for n in problem.names} for i in todo]
        res = evaluate(problem, points, relation, trials=options.trials, seed=seed,
                       block_size=options.block_size, n_jobs=options.n_jobs,
                       name=f"sizing-{relation}-certify")
        evaluations += len(points)
        ok = res["margin_ok"] if options.replication_margin else res["verdict"] == "meets"
        nxt = []
        for i, (_, r), good in zip(todo, res.iterrows(), ok, strict=True):
            for k in STAT_COLUMNS:
                corners.at[i, k] = r[k]
            knob = corners.at[i, "limiting"]
            if good:
                corners.at[i, "certified"] = True
                moved = f", {knob} moved {steps[i]} step(s) dearer" if steps[i] else ""
                corners.at[i, "status"] += f"; certified with seed {seed}{moved}"
                continue
            dearer = problem.knob(knob).dearer_by(corners.at[i, knob], options.tolerance) \
                if isinstance(knob, str) else None
            if dearer is None or dearer == corners.at[i, knob] or steps[i] >= MAX_CERTIFY_STEPS:
                corners.at[i, "status"] += f"; not certified with seed {seed}"
                continue
            corners.at[i, knob] = dearer
            steps[i] += 1
            nxt.append(i)
        todo = nxt
    return corners, evaluations


def size_relation(problem: SizingProblem, relation: str, options: SizingOptions
                  ) -> RelationSizing:
    """Grid, Pareto corners, bisection and the cheapest corner for one pixel relation."""
    grid = _grid_points(problem, options.levels)
    knob_cols = problem.names
    res = evaluate(problem, grid[knob_cols].to_dict("records"), relation,
                   trials=options.trials, seed=options.seed, block_size=options.block_size,
                   n_jobs=options.n_jobs, name=f"sizing-{relation}-grid")
    grid = pd.concat([grid, res.drop(columns=knob_cols)], axis=1)
    grid["cost"] = problem.cost(grid)
    grid["pareto"] = pareto_minimal(problem.doublings(grid), grid["verdict"] == "meets")
    corners, n_bisect = _refine(problem, relation, grid, options)
    corners, n_probe = _probe(problem, relation, corners, options)
    corners, n_cert = _certify(problem, relation, corners, options)
    uncertified = int((~corners["certified"]).sum()) if len(corners) else 0
    if len(corners):
        corners["cost"] = problem.cost(corners)
        keep = pareto_minimal(problem.doublings(corners), corners["certified"].to_numpy(bool))
        corners = corners[keep].reset_index(drop=True)
    if not len(corners):
        names = problem.names
        corners = pd.DataFrame(columns=[
            *names, *STAT_COLUMNS, "grid_index", "limiting", "bracket_bad", "status", "refined",
            *(f"bad_{n}" for n in names), *(f"cheaper_{n}" for n in names), "search_value",
            "search_hi", "certified", "cost", "cheapest"])
    else:
        corners["cheapest"] = False
        corners.loc[cheapest(problem, corners, options.order), "cheapest"] = True
    rs = RelationSizing(relation, grid, corners, len(grid) + n_bisect + n_probe + n_cert,
                        uncertified=uncertified)
    if rs.answer is None:
        rs.best, n_best = best_design(problem, rs, options)
        rs.evaluations += n_best
    if options.slice_levels:
        rs.slice = _evaluate_slice(problem, rs, options)
        rs.evaluations += len(rs.slice)
    return rs


def best_design(problem: SizingProblem, rs: RelationSizing, options: SizingOptions,
                cycles: int = 2, line_points: int = 9) -> tuple[pd.Series, int]:
    """The design with the lowest upper bound of the statistic, when none meets the spec.

    The statistic need not be monotone in a knob (with independent pixel noise the error
    grows with range at long range and with the geometry's leverage at short range), so the
    best grid point can lie far from the best design. From it, a coordinate search: each free
    knob in turn on ``line_points`` geometric levels over its bounds, then on five levels
    between the neighbours of the best, the others held; ``cycles`` rounds or until nothing
    improves. The search seed's values are biased low by the selection, so the result is run
    again with the certification seed, whose values are reported (``search_hi`` keeps the
    search's).

    Returns the best design's row and the number of evaluations.
    """
    run = functools.partial(evaluate, problem, relation=rs.relation, trials=options.trials,
                            block_size=options.block_size, n_jobs=options.n_jobs)
    start = rs.grid.loc[rs.grid["hi"].fillna(np.inf).idxmin()]
    current = {n: float(start[n]) for n in problem.names}
    best_hi, evaluations = float(start["hi"]), 0
    for _ in range(cycles):
        improved = False
        for knob in (k for k in problem.knobs if k.free):
            lo, hi, n = knob.lo, knob.hi, line_points
            for _refine in range(2):
                values = np.geomspace(lo, hi, n)
                res = run([{**current, knob.name: float(v)} for v in values], seed=options.seed,
                          name=f"sizing-{rs.relation}-best")
                evaluations += n
                i = int(res["hi"].fillna(np.inf).to_numpy().argmin())
                if float(res["hi"].iloc[i]) < best_hi:
                    best_hi, current[knob.name], improved = float(res["hi"].iloc[i]), \
                        float(values[i]), True
                lo, hi, n = values[max(i - 1, 0)], values[min(i + 1, len(values) - 1)], 5
        if not improved:
            break
    final = run([current], seed=options.certification_seed,
                name=f"sizing-{rs.relation}-best-certify").iloc[0].copy()
    final["search_hi"] = best_hi
    return final, evaluations + 1


def plotted_knobs(problem: SizingProblem, answer: pd.Series | None) -> list[Knob]:
    """The knobs of the frontier plot's slice through the answer.

    The answer's limiting knob against the first other free knob not at its cheap bound (the
    trade-off the answer sits on), falling back to L x H, or the first two free knobs.
    """
    free = [k for k in problem.knobs if k.free]
    if answer is not None and isinstance(answer["limiting"], str):
        lim = problem.knob(answer["limiting"])
        rest = [k for k in free if k is not lim]
        loose = [k for k in rest if k.doublings(answer[k.name]) > 1e-9]
        return [lim, *(loose or rest)[:1]]
    names = {k.name for k in free}
    return [problem.knob("L_m"), problem.knob("H_m")] if {"L_m", "H_m"} <= names else free[:2]


def _evaluate_slice(problem: SizingProblem, rs: RelationSizing, options: SizingOptions
                    ) -> pd.DataFrame:
    """The plotted knobs on a geometric grid over their bounds, every other knob at the answer
    (or, if nothing meets, at the grid point with the lowest upper bound)."""
    a = rs.answer
    anchor = a if a is not None else rs.best if rs.best is not None \
        else rs.grid.loc[rs.grid["hi"].fillna(np.inf).idxmin()]
    axes = plotted_knobs(problem, a)
    n = options.slice_levels if len(axes) == 2 else 2 * options.slice_levels
    values = [np.geomspace(k.lo, k.hi, n) for k in axes]
    points = []
    for combo in itertools.product(*values):
        point = {name: float(anchor[name]) for name in problem.names}
        point.update({k.name: float(v) for k, v in zip(axes, combo, strict=True)})
        points.append(point)
    return evaluate(problem, points, rs.relation, trials=options.trials, seed=options.seed,
                    block_size=options.block_size, n_jobs=options.n_jobs,
                    name=f"sizing-{rs.relation}-slice")


def confirm(problem: SizingProblem, relation: str, answer: Mapping[str, Any], *, trials: int,
            seed: int, block_size: int = 2048, n_jobs: int | None = None) -> pd.DataFrame:
    """Independent run (``seed``) at the answer and 10 % cheaper in its limiting knob.

    Returns rows ``role`` = "answer" (should meet) and "cheaper" (should fail), with the
    statistic, its bounds and verdict.
    """
    point = {n: float(answer[n]) for n in problem.names}
    points = [point]
    limiting = answer.get("limiting")
    if isinstance(limiting, str):
        cheaper = dict(point)
        cheaper[limiting] = problem.knob(limiting).cheaper_by(point[limiting])
        points.append(cheaper)
    res = evaluate(problem, points, relation, trials=trials, seed=seed, block_size=block_size,
                   n_jobs=n_jobs, name=f"sizing-{relation}-confirm")
    res.insert(0, "role", ["answer", "cheaper"][:len(points)])
    res.insert(1, "seed", seed)
    return res


def size(problem: SizingProblem, options: SizingOptions | None = None,
         relations: Sequence[str] = RELATIONS, confirm_seed: int | None = None
         ) -> SizingResult:
    """Size ``problem`` for each pixel relation; confirm each answer with ``confirm_seed``
    (skipped if None). ``options`` defaults to :class:`SizingOptions`'s defaults."""
    options = options or SizingOptions()
    if confirm_seed is not None and confirm_seed in (options.seed, options.certification_seed):
        raise InputError(f"confirm seed: must differ from the search seed {options.seed} and "
                         f"the certification seed {options.certification_seed}")
    for r in relations:
        if r not in RELATIONS:
            raise InputError(f"pixel relation: {r!r} is not one of {', '.join(RELATIONS)}")
    if options.order is not None:
        unknown = set(options.order) - set(problem.names)
        if unknown:
            raise InputError(f"order: {', '.join(sorted(unknown))} not among the knobs "
                             f"({', '.join(problem.names)})")
    study = build_study(problem, [], RELATIONS[0], trials=1, seed=0, block_size=1)
    result = SizingResult(problem, options, unit=study.metric(problem.requirement.metric).unit)
    for rel in relations:
        rs = size_relation(problem, rel, options)
        a = rs.answer
        if confirm_seed is not None and a is not None:
            rs.confirmation = confirm(problem, rel, a, trials=options.confirm_trials
                                      or 4 * options.trials, seed=confirm_seed,
                                      block_size=options.block_size, n_jobs=options.n_jobs)
        result.relations[rel] = rs
    return result
