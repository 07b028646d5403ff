"""Requirement sizing: the cheapest ground-calibration set-up that meets an accuracy spec.

A *requirement* is "the ``statistic`` (a percentile) of ``metric`` is at most ``limit`` at
``confidence``", judged on the upper end of the order-statistic confidence interval that the study
runner computes (the ``<statistic>_hi`` column at ``[study] confidence``): a design *meets* the
spec only if that upper bound is at or below the limit, *fails* only if the lower bound is above
it, and is *undecided* otherwise. The upper end of a two-sided interval at level c bounds the true
percentile from above with probability at least (1 + c) / 2 >= c, so "meets" means "meets with
confidence c" (conservatively). A design with any invalid trial (no solution) does not meet.

*Knobs* are what the user may change, each within bounds and with a cheaper direction:

============  =====================================================  ===============
knob          what it sets in the ground study                       cheaper
============  =====================================================  ===============
``L_m``       range L, ``geometry.L_m`` [m]                          smaller
``H_m``       height difference H, ``geometry.H_m`` [m]              smaller (mast)
``pixel_px``  scale of ``errors.pixel_px`` (sigma or bound) [px]     larger (coarser)
``survey_m``  scale of ``errors.dx_m``, ``dy_m``, ``dh1_m`` [m]      larger (coarser)
``scale_m``   scale of ``errors.dh_m``, the height-scale error [m]   larger (coarser)
============  =====================================================  ===============

Cost is counted in *doublings* away from the cheap end of each knob's bounds (a range twice as
long, a centroid twice as fine: one doubling each), weighted per knob (default weight 1), or
ranked lexicographically by a user-given order of knobs.

Search (every evaluation is a run of the study runner on a study built with
:func:`montecarlo.study.study_from_dict`, one seed, common random numbers across points, so the
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
them (NOTES.md: the two behave oppositely with range).
"""

from __future__ import annotations

import copy
import itertools
import math
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from montecarlo.engine.runner import RunOptions, run_study
from montecarlo.errors import InputError
from montecarlo.output.report import markdown_table
from montecarlo.systems import study_from_dict

Cheaper = Literal["smaller", "larger"]
RELATIONS = ("common", "independent")
PERCENTILE_STATISTICS = ("p50", "p90", "p95", "p99")
CHEAPER_STEP = 0.10
"""The confirmation's "10 % cheaper": x * 0.9 for a smaller-is-cheaper knob, x * 1.1 else."""


@dataclass(frozen=True)
class KnobInfo:
    """What a knob sets in a ground study and which way is cheaper."""

    keys: tuple[str, ...]
    cheaper: Cheaper
    label: str
    is_source: bool
    """True: the knob sets the scale (sigma or bound) of error sources; False: a plain number."""


KNOBS: dict[str, KnobInfo] = {
    "L_m": KnobInfo(("geometry.L_m",), "smaller", "range L [m]", False),
    "H_m": KnobInfo(("geometry.H_m",), "smaller", "height difference H [m]", False),
    "pixel_px": KnobInfo(("errors.pixel_px",), "larger", "pixel error [px]", True),
    "survey_m": KnobInfo(("errors.dx_m", "errors.dy_m", "errors.dh1_m"), "larger",
                         "placement survey error [m]", True),
    "scale_m": KnobInfo(("errors.dh_m",), "larger", "height-scale error δb [m]", True),
}

DEFAULT_BOUNDS: dict[str, tuple[float, float]] = {
    "L_m": (25.0, 400.0),
    "H_m": (0.5, 10.0),
    "pixel_px": (0.05, 1.0),
    "survey_m": (0.01, 0.2),
    "scale_m": (0.0002, 0.005),
}
"""Bounds used when knobs are not given: the paper's L > 50 m bracketed, masts up to 10 m."""

DEFAULT_DESIGN: dict[str, Any] = {
    "study": {"name": "sizing", "system": "ground", "trials": 10000, "seed": 0},
    "sensor": {"fov_deg": [90.0, 90.0], "pixels": [512, 512]},
    "mounting": {"psi_deg": 30.0, "theta_deg": 20.0, "gamma_deg": 10.0},
    "geometry": {"L_m": 100.0, "H_m": 2.0},
    "errors": {
        "dx_m": {"dist": "uniform", "bound": 0.1},
        "dy_m": {"dist": "uniform", "bound": 0.1},
        "dh1_m": {"dist": "uniform", "bound": 0.1},
        "dh_m": {"dist": "uniform", "bound": 0.001},
        "pixel_px": {"dist": "normal", "sigma": 0.3},
        "pixel_relation": "common",
    },
}
"""Seed 000's Table 1 set-up with the distributions of ``studies/range_sizing.toml``."""


@dataclass(frozen=True)
class Requirement:
    """``statistic`` of ``metric`` (solver ``variant``) <= ``limit`` at ``confidence``.

    ``limit`` is in the metric's display unit (mrad for the ground angles).
    """

    limit: float
    metric: str = "rotation_angle"
    statistic: str = "p95"
    confidence: float = 0.90
    variant: str = "normalised"

    def __post_init__(self) -> None:
        if self.statistic not in PERCENTILE_STATISTICS:
            raise InputError(f"statistic: sizing needs a percentile with a confidence bound, "
                             f"one of {', '.join(PERCENTILE_STATISTICS)} (got {self.statistic!r})")
        if not 0.0 < self.confidence < 1.0:
            raise InputError(f"confidence: must lie in (0, 1) (got {self.confidence!r})")
        if not self.limit > 0.0:
            raise InputError(f"limit: must be positive (got {self.limit!r})")

    def describe(self, unit: str = "mrad") -> str:
        return (f"{self.statistic} of {self.metric} ({self.variant} solver) ≤ {self.limit:g} "
                f"{unit} at {self.confidence:.0%} confidence")


@dataclass(frozen=True)
class Knob:
    """A knob with its bounds ``lo <= hi`` (lo == hi: fixed) and its cost weight."""

    name: str
    lo: float
    hi: float
    weight: float = 1.0

    def __post_init__(self) -> None:
        if self.name not in KNOBS:
            raise InputError(f"knob {self.name!r}: unknown; choose from {', '.join(KNOBS)}")
        if not (0.0 < self.lo <= self.hi and math.isfinite(self.hi)):
            raise InputError(f"knob {self.name}: bounds must satisfy 0 < lo <= hi "
                             f"(got {self.lo:g}..{self.hi:g})")
        if not self.weight >= 0.0:
            raise InputError(f"knob {self.name}: weight must be >= 0 (got {self.weight!r})")

    @property
    def info(self) -> KnobInfo:
        return KNOBS[self.name]

    @property
    def free(self) -> bool:
        return self.hi > self.lo

    @property
    def cheap_end(self) -> float:
        return self.lo if self.info.cheaper == "smaller" else self.hi

    def doublings(self, x: Any) -> np.ndarray:
        """Cost of value(s) ``x``: doublings away from the cheap end (>= 0 inside the bounds)."""
        ratio = np.asarray(x, float) / self.cheap_end
        return np.log2(ratio) if self.info.cheaper == "smaller" else -np.log2(ratio)

    def levels(self, n: int) -> np.ndarray:
        """Grid levels ordered from the cheap end to the expensive end (geometric)."""
        if not self.free:
            return np.array([self.lo])
        values = np.geomspace(self.lo, self.hi, n)
        return values if self.info.cheaper == "smaller" else values[::-1]

    def cheaper_by(self, x: float, fraction: float = CHEAPER_STEP) -> float:
        """``x`` moved ``fraction`` towards the cheap direction (0.9 x or 1.1 x)."""
        return x * (1.0 - fraction) if self.info.cheaper == "smaller" else x * (1.0 + fraction)

    def dearer_by(self, x: float, fraction: float) -> float:
        """``x`` moved by a factor ``1 + fraction`` towards the expensive direction, clipped to
        the bounds."""
        y = x * (1.0 + fraction) if self.info.cheaper == "smaller" else x / (1.0 + fraction)
        return float(np.clip(y, self.lo, self.hi))


def default_knobs(names: Sequence[str] = tuple(KNOBS)) -> tuple[Knob, ...]:
    return tuple(Knob(n, *DEFAULT_BOUNDS[n]) for n in names)


@dataclass(frozen=True)
class SizingOptions:
    """How to search (the answer depends on these; all are reported)."""

    levels: int = 4
    trials: int = 10000
    seed: int = 0
    tolerance: float = 0.02
    """Bisection stops when the bracket's ratio is at most 1 + tolerance."""
    replication_margin: bool = True
    order: tuple[str, ...] | None = None
    """Lexicographic cost: minimise the doublings of these knobs in this order (else weights)."""
    block_size: int = 2048
    n_jobs: int = 2
    slice_levels: int = 6
    """Levels per axis of the plotted slice through the answer (0: no slice)."""
    confirm_trials: int | None = None
    """Trials of the confirmation runs (default 4 x trials: half the search's noise)."""

    @property
    def certification_seed(self) -> int:
        """Seed of the certification runs: a stream independent of the search seed's (and of
        small seeds such as seed + 1), derived from it by ``SeedSequence``."""
        return int(np.random.SeedSequence([self.seed, 0x5EED]).generate_state(1)[0])

    def __post_init__(self) -> None:
        if self.levels < 2:
            raise InputError(f"levels: need at least 2 levels per knob (got {self.levels})")
        if self.trials < 1:
            raise InputError(f"trials: must be positive (got {self.trials})")
        if not 0.0 < self.tolerance < 1.0:
            raise InputError(f"tolerance: must lie in (0, 1) (got {self.tolerance!r})")


@dataclass(frozen=True)
class SizingProblem:
    """A base ground design, the requirement and the knobs that may change."""

    base: dict[str, Any]
    requirement: Requirement
    knobs: tuple[Knob, ...]

    def __post_init__(self) -> None:
        names = [k.name for k in self.knobs]
        if not names:
            raise InputError("knobs: give at least one knob to vary")
        if len(set(names)) != len(names):
            raise InputError(f"knobs: a knob appears twice ({', '.join(names)})")
        system = self.base.get("study", {}).get("system", "ground")
        if system != "ground":
            raise InputError(f"study.system: sizing works on the ground system (got {system!r})")
        for k in self.knobs:
            if k.info.is_source:
                _scaled_sources(self.base, k.name, k.lo)  # raises if nothing to scale

    @property
    def names(self) -> list[str]:
        return [k.name for k in self.knobs]

    def knob(self, name: str) -> Knob:
        return next(k for k in self.knobs if k.name == name)

    def doublings(self, points: pd.DataFrame) -> np.ndarray:
        """(n, k) doublings of each point in each knob."""
        return np.stack([k.doublings(points[k.name].to_numpy(float)) for k in self.knobs], -1)

    def cost(self, points: pd.DataFrame) -> np.ndarray:
        """Weighted doublings of each point."""
        return self.doublings(points) @ np.array([k.weight for k in self.knobs])


def _get(raw: Mapping[str, Any], key: str) -> Any:
    node: Any = raw
    for part in key.split("."):
        node = node.get(part) if isinstance(node, Mapping) else None
    return node


def _scaled_sources(base: Mapping[str, Any], knob: str, value: float) -> dict[str, Any]:
    """Study overrides that give each distributed source of ``knob`` the scale ``value``.

    Uniform and corner sources get ``bound = value``, normal ones ``sigma = value``; fixed
    sources (a plain number) stay as they are. Raises :class:`InputError` if the knob has no
    distributed source in the base design.
    """
    out = {}
    for key in KNOBS[knob].keys:
        src = _get(base, key)
        if isinstance(src, Mapping) and src.get("dist") in ("uniform", "corners"):
            out[key] = {**src, "bound": value}
        elif isinstance(src, Mapping) and src.get("dist") == "normal":
            out[key] = {**src, "sigma": value}
    if not out:
        raise InputError(f"knob {knob}: none of {', '.join(KNOBS[knob].keys)} has a "
                         f"distribution in the base design, so there is no error scale to size")
    return out


def design_overrides(base: Mapping[str, Any], point: Mapping[str, float]) -> dict[str, Any]:
    """Study keys and values that put the base design at ``point`` (knob -> value)."""
    out: dict[str, Any] = {}
    for name, value in point.items():
        if KNOBS[name].is_source:
            out.update(_scaled_sources(base, name, float(value)))
        else:
            out[KNOBS[name].keys[0]] = float(value)
    return out


def ground_study(base: Mapping[str, Any], requirement: Requirement,
                 overrides: Sequence[Mapping[str, Any]], relation: str, *, trials: int, seed: int,
                 block_size: int, name: str = "sizing"):
    """A ground study of ``base`` whose grid points apply ``overrides`` (study key -> value,
    a zipped sweep), for one pixel relation, computing only the requirement's solver variant
    with percentile intervals at its confidence."""
    req = requirement
    raw = copy.deepcopy(dict(base))
    raw.pop("sweep", None)
    header = {k: v for k, v in raw.get("study", {}).items() if k == "description"}
    raw["study"] = {**header, "name": name, "system": "ground", "trials": trials, "seed": seed,
                    "block_size": block_size, "confidence": req.confidence,
                    "common_random_numbers": True}
    raw.setdefault("errors", {})["pixel_relation"] = relation
    raw["solver"] = {"variants": [req.variant]}
    raw["spec"] = {"metric": req.metric, "variant": req.variant, "statistic": req.statistic,
                   "limit": req.limit}
    if overrides and overrides[0]:
        raw["sweep"] = [{"mode": "zip", **{k: [o[k] for o in overrides] for k in overrides[0]}}]
    return study_from_dict(raw, f"<{name}>")


def build_study(problem: SizingProblem, points: Sequence[Mapping[str, float]], relation: str,
                *, trials: int, seed: int, block_size: int, name: str = "sizing"):
    """The ground study whose grid points are the design ``points`` (knob -> value)."""
    overrides = [design_overrides(problem.base, p) for p in points]
    return ground_study(problem.base, problem.requirement, overrides, relation, trials=trials,
                        seed=seed, block_size=block_size, name=name)


def meets_with_margin(value: np.ndarray, hi: np.ndarray, limit: float) -> np.ndarray:
    """``hi + sqrt(2) (hi - value) <= limit``: an independent rerun of the same size should meet.

    The rerun's upper bound is its estimate plus the same half-width w = hi - value; its
    estimate differs from this one by a difference of two independent errors, spread sqrt(2)
    times one, whose (1 + c)/2 quantile is sqrt(2) w.
    """
    value = np.asarray(value, float)
    hi = np.asarray(hi, float)
    return np.isfinite(hi) & (hi + math.sqrt(2.0) * (hi - value) <= limit)


def verdicts(value: np.ndarray, lo: np.ndarray, hi: np.ndarray, invalid: np.ndarray,
             limit: float) -> np.ndarray:
    """'meets' (upper bound <= limit), 'fails' (lower bound > limit), 'invalid' (some trial had
    no solution), else 'undecided' (the trials cannot tell)."""
    lo = np.nan_to_num(np.asarray(lo, float), nan=-np.inf)
    hi = np.nan_to_num(np.asarray(hi, float), nan=np.inf)
    out = np.where(hi <= limit, "meets", np.where(lo > limit, "fails", "undecided"))
    return np.where(np.asarray(invalid) > 0, "invalid", out).astype(object)


def run_statistic(study: Any, requirement: Requirement, n_jobs: int = 2) -> pd.DataFrame:
    """Run ``study`` with the study runner; per grid point (in order) the requirement's
    statistic ``value``, its interval ``lo``/``hi`` (display unit), ``count``, ``invalid``, the
    ``verdict`` and ``margin_ok`` (meets with the replication margin)."""
    req = requirement
    with tempfile.TemporaryDirectory(prefix="montecarlo-sizing-") as tmp:
        result = run_study(study, RunOptions(n_jobs=n_jobs, progress=False,
                                             checkpoint_dir=Path(tmp)))
    frame = result.to_frame()
    sel = frame[(frame["metric"] == req.metric) & (frame["variant"] == req.variant)]
    sel = sel.sort_values("point")
    s = req.statistic
    out = pd.DataFrame({"value": sel[s].to_numpy(float), "lo": sel[f"{s}_lo"].to_numpy(float),
                        "hi": sel[f"{s}_hi"].to_numpy(float),
                        "count": sel["count"].to_numpy(int),
                        "invalid": sel["invalid"].to_numpy(int)})
    out["verdict"] = verdicts(out["value"], out["lo"], out["hi"], out["invalid"], req.limit)
    out["margin_ok"] = (out["verdict"] == "meets") & meets_with_margin(
        out["value"], out["hi"], req.limit)
    return out


def evaluate(problem: SizingProblem, points: Sequence[Mapping[str, float]], relation: str, *,
             trials: int, seed: int, block_size: int = 2048, n_jobs: int = 2,
             name: str = "sizing") -> pd.DataFrame:
    """Run the study runner at the design ``points``: one row each with the knobs and the
    columns of :func:`run_statistic`."""
    study = build_study(problem, points, relation, trials=trials, seed=seed,
                        block_size=block_size, name=name)
    stats = run_statistic(study, problem.requirement, n_jobs)
    return pd.concat([pd.DataFrame([dict(p) for p in points]), stats], axis=1)


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
    if options.slice_levels:
        rs.slice = _evaluate_slice(problem, rs, options)
        rs.evaluations += len(rs.slice)
    return rs


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
    anchor = a if a is not None else rs.grid.loc[rs.grid["hi"].fillna(np.inf).idxmin()]
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
            seed: int, block_size: int = 2048, n_jobs: int = 2) -> pd.DataFrame:
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


def size(problem: SizingProblem, options: SizingOptions = SizingOptions(),
         relations: Sequence[str] = RELATIONS, confirm_seed: int | None = None
         ) -> SizingResult:
    """Size ``problem`` for each pixel relation; confirm each answer with ``confirm_seed``
    (skipped if None)."""
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


# --- report and plot -----------------------------------------------------------------------------

RELATION_TEXT = {"common": "pixel error common to both targets (the paper's assumption)",
                 "independent": "pixel error independent between targets (centroid noise)"}


def _fmt(v: Any) -> str:
    if isinstance(v, float | np.floating):
        return "–" if not np.isfinite(v) else f"{v:#.4g}"
    return "–" if v is None else str(v)


VERDICT_STYLES = {"meets": ("o", "tab:green"), "undecided": ("s", "tab:orange"),
                  "fails": ("x", "tab:red"), "invalid": ("x", "k")}


def _log_ticks(ax_set: Any, values: np.ndarray) -> None:
    ax_set(values, [f"{v:.3g}" for v in values], fontsize=7)


def _plot_slice(ax: Any, problem: SizingProblem, rs: RelationSizing, unit: str) -> None:
    """Verdicts on the slice through the answer, the boundary of 'meets' and the answer."""
    req = problem.requirement
    a = rs.answer
    sl = rs.slice
    axes = plotted_knobs(problem, a)
    if sl is None or not axes:
        ax.set_axis_off()
        return
    others = [n for n in problem.names if n not in {k.name for k in axes}]
    fixed = ", ".join(f"{n}={sl[n].iloc[0]:.3g}" for n in others)
    where = "through the answer" if a is not None else "through the best grid point (no answer)"
    title = RELATION_TEXT[rs.relation].split(" (")[0] + f"\nslice {where}" + (
        f" at {fixed}" if fixed else "")
    if len(axes) == 1:
        k = axes[0]
        sel = sl.sort_values(k.name)
        ax.fill_between(sel[k.name], sel["lo"], sel["hi"], color="0.75",
                        label=f"{req.confidence:.0%} interval")
        ax.plot(sel[k.name], sel["value"], "-", color="0.3", lw=1)
        for v, (m, c) in VERDICT_STYLES.items():
            s = sel[sel["verdict"] == v]
            if len(s):
                ax.plot(s[k.name], s["value"], m, color=c, ls="none", label=v)
        ax.axhline(req.limit, color="k", ls="-.", lw=1, label=f"limit {req.limit:g} {unit}")
        if a is not None:
            ax.plot([a[k.name]], [a["value"]], "*", color="gold", mec="k", ms=15, zorder=5,
                    label="answer")
        ax.set_xscale("log")
        _log_ticks(ax.set_xticks, np.unique(sel[k.name]))
        ax.minorticks_off()
        ax.set_xlabel(f"{KNOBS[k.name].label} (cheaper: {k.info.cheaper})")
        ax.set_ylabel(f"{req.statistic} of {req.metric} [{unit}]")
    else:
        xk, yk = axes
        for v, (m, c) in VERDICT_STYLES.items():
            s = sl[sl["verdict"] == v]
            if len(s):
                ax.plot(s[xk.name], s[yk.name], m, color=c, ls="none", ms=6, label=v)
        table = sl.pivot_table(index=yk.name, columns=xk.name, values="hi")
        z = np.log(table.to_numpy(float))
        if np.nanmin(z) < np.log(req.limit) < np.nanmax(z):
            ax.contour(table.columns, table.index, z, levels=[np.log(req.limit)],
                       colors="tab:green", linewidths=1.5)
            ax.plot([], [], "-", color="tab:green", label="upper bound = limit")
        if a is not None:
            ax.plot([a[xk.name]], [a[yk.name]], "*", color="gold", mec="k", ms=16, zorder=5,
                    label=f"answer (limiting: {a['limiting']})")
        ax.set_xscale("log")
        ax.set_yscale("log")
        _log_ticks(ax.set_xticks, np.unique(sl[xk.name]))
        _log_ticks(ax.set_yticks, np.unique(sl[yk.name]))
        ax.minorticks_off()
        ax.set_xlabel(f"{KNOBS[xk.name].label} (cheaper: {xk.info.cheaper})")
        ax.set_ylabel(f"{KNOBS[yk.name].label} (cheaper: {yk.info.cheaper})")
        ax.grid(alpha=0.3)
    ax.set_title(title, fontsize=8)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncols=3,
              frameon=False)


def _plot_corners(ax: Any, problem: SizingProblem, rs: RelationSizing) -> None:
    """Parallel coordinates of the refined Pareto corners: each knob's position in its bounds."""
    free = [k for k in problem.knobs if k.free]
    corners = rs.corners
    if not len(corners):
        ax.text(0.5, 0.5, "no design within the bounds meets the spec", ha="center",
                va="center", transform=ax.transAxes)
        ax.set_axis_off()
        return
    x = np.arange(len(free))
    span = np.array([k.doublings(k.hi if k.info.cheaper == "smaller" else k.lo)
                     for k in free])
    cost = corners["cost"].to_numpy(float)
    cmin, cmax = cost.min(), max(cost.max(), cost.min() + 1e-9)
    for _, c in corners.sort_values("cheapest").iterrows():
        y = np.array([k.doublings(c[k.name]) for k in free]) / span
        if c["cheapest"]:
            ax.plot(x, y, "-o", color="k", lw=2.5, ms=5, label="answer", zorder=5)
            for xi, yi, k in zip(x, y, free, strict=True):
                ax.annotate(f"{c[k.name]:.3g}", (xi, yi), textcoords="offset points",
                            xytext=(4, 4), fontsize=7)
        else:
            shade = 0.2 + 0.6 * (c["cost"] - cmin) / (cmax - cmin)
            ax.plot(x, y, "-o", color=(shade, shade, 1.0), lw=1, ms=3)
    ax.set_xticks(x, [k.name for k in free], fontsize=8)
    ax.set_ylim(-0.05, 1.05)
    ax.set_ylabel("position in bounds\n(0 = cheapest, 1 = dearest, log)", fontsize=8)
    ax.set_title(f"{len(corners)} Pareto-minimal corners (darker = cheaper)", fontsize=8)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")


def frontier_figure(result: SizingResult) -> Figure:
    """Per relation: the grid verdicts on a 2-D slice through the answer with the Pareto
    frontier (top) and the refined Pareto corners in every knob (bottom)."""
    rels = list(result.relations)
    fig = Figure(figsize=(5.6 * len(rels), 8.2), layout="constrained")
    axes = fig.subplots(2, len(rels), squeeze=False)
    for c, rel in enumerate(rels):
        _plot_slice(axes[0, c], result.problem, result.relations[rel], result.unit)
        _plot_corners(axes[1, c], result.problem, result.relations[rel])
    fig.suptitle(f"Sizing: {result.problem.requirement.describe(result.unit)}", fontsize=10)
    return fig


def format_result(result: SizingResult) -> str:
    """Plain-text summary for the terminal."""
    p, o = result.problem, result.options
    req = p.requirement
    lines = [f"requirement: {req.describe(result.unit)} (upper order-statistic bound)",
             "knobs: " + "; ".join(
                 f"{k.name} {k.lo:g}..{k.hi:g} (cheaper: {k.info.cheaper}, weight {k.weight:g})"
                 for k in p.knobs),
             "cost: " + (f"lexicographic in {', '.join(o.order)}" if o.order
                         else "weighted doublings")
             + f"; grid {o.levels} levels per knob, {o.trials} trials per point, seed {o.seed}, "
             f"bisection to {o.tolerance:.0%}, replication margin "
             f"{'on' if o.replication_margin else 'off'}, certification seed "
             f"{o.certification_seed}"]
    for rel, rs in result.relations.items():
        counts = rs.grid["verdict"].value_counts()
        lines += ["", f"== {RELATION_TEXT[rel]} ==",
                  f"grid: {len(rs.grid)} points: " + ", ".join(
                      f"{counts.get(v, 0)} {v}" for v in ("meets", "undecided", "fails",
                                                          "invalid"))
                  + f"; {rs.evaluations} evaluations in all"
                  + (f"; {rs.uncertified} corner(s) failed certification and were dropped"
                     if rs.uncertified else "")]
        a = rs.answer
        if a is None:
            best = rs.grid.loc[rs.grid["hi"].fillna(np.inf).idxmin()]
            lines.append("no design within the bounds meets the spec; the best grid point: "
                         + ", ".join(f"{n}={best[n]:.4g}" for n in p.names)
                         + f", {req.statistic} {_fmt(best['value'])} "
                         f"[{_fmt(best['lo'])}, {_fmt(best['hi'])}] {result.unit}")
            continue
        lines.append(f"{len(rs.corners)} Pareto-minimal corners; the cheapest:")
        lines.append("  " + ", ".join(f"{n} = {a[n]:.4g}" for n in p.names)
                     + f"  (cost {a['cost']:.3g})")
        lines.append(f"  certification: {req.statistic} = {_fmt(a['value'])} {result.unit}, "
                     f"{req.confidence:.0%} interval [{_fmt(a['lo'])}, {_fmt(a['hi'])}]: "
                     f"{a['verdict']} (search seed: {_fmt(a['search_value'])}, upper bound "
                     f"{_fmt(a['search_hi'])})")
        if isinstance(a["limiting"], str):
            lines.append(f"  limiting parameter: {a['limiting']} (its 10 % cheapening raises "
                         f"{req.statistic} most; {a['status']}; in the search "
                         f"{a['limiting']} = {a['bracket_bad']:.4g} did not pass)")
        else:
            lines.append(f"  limiting parameter: none ({a['status']})")
        if rs.confirmation is not None:
            for _, c in rs.confirmation.iterrows():
                what = "at the answer" if c["role"] == "answer" else (
                    f"10 % cheaper, {a['limiting']} = {c[a['limiting']]:.4g}")
                lines.append(f"  confirmation (seed {c['seed']}, {c['count']} trials) {what}: "
                             f"{req.statistic} = "
                             f"{_fmt(c['value'])} [{_fmt(c['lo'])}, {_fmt(c['hi'])}] "
                             f"{result.unit}: {c['verdict']}")
    return "\n".join(lines)


def render_report(result: SizingResult, figure_name: str = "frontier.png") -> str:
    """Markdown report: requirement, method, answers with confirmation, corners, plot."""
    p, o = result.problem, result.options
    req = p.requirement
    cols = [*p.names, "value", "lo", "hi", "verdict", "cost", "limiting", "status"]
    lines = ["# Sizing", "", f"Requirement: **{req.describe(result.unit)}**, judged on the upper "
             f"end of the {req.confidence:.0%} order-statistic interval of {req.statistic}.", "",
             "Knobs and cost directions:", ""]
    lines += [f"- `{k.name}` ({KNOBS[k.name].label}): {k.lo:g} .. {k.hi:g}, cheaper "
              f"{k.info.cheaper}, weight {k.weight:g}" for k in p.knobs]
    lines += ["", f"Search: {o.levels} geometric levels per knob, {o.trials} trials per point, "
              f"seed {o.seed}, common random numbers; every Pareto-minimal meeting grid point "
              f"bisected knob by knob to {o.tolerance:.0%}; limiting knob = the one whose 10 % "
              f"cheapening raises {req.statistic} most; replication margin "
              f"{'on' if o.replication_margin else 'off'}; every corner re-evaluated (certified) "
              f"with seed {o.certification_seed}; answers confirmed with an independent seed at "
              f"{o.confirm_trials or 4 * o.trials} trials; cost "
              + (f"lexicographic in {', '.join(o.order)}" if o.order else "weighted doublings")
              + ".", "", "## Answers", "", "```", format_result(result), "```", ""]
    for rel, rs in result.relations.items():
        lines += [f"## {RELATION_TEXT[rel]}", ""]
        if len(rs.corners):
            lines += [markdown_table(rs.corners[[*cols, "cheapest"]]), ""]
        else:
            lines += ["No design within the bounds meets the spec (after certification).", ""]
    lines += [f"![frontier]({figure_name})", ""]
    return "\n".join(lines)


def write_file(path: Path, data: bytes) -> Path:
    """Write all or nothing (montecarlo.files) and return the path."""
    from montecarlo.io.files import atomic_write_bytes

    atomic_write_bytes(path, data)
    return path


def write_outputs(result: SizingResult, out_dir: Path) -> list[Path]:
    """grid-<relation>.csv, corners-<relation>.csv, answers.csv, frontier.png, report.md; each
    file written under a temporary name and renamed."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []

    def put(name: str, data: bytes) -> None:
        written.append(write_file(out_dir / name, data))

    for rel, rs in result.relations.items():
        put(f"grid-{rel}.csv", rs.grid.to_csv(index=False).encode())
        put(f"corners-{rel}.csv", rs.corners.to_csv(index=False).encode())
        if rs.confirmation is not None:
            put(f"confirmation-{rel}.csv", rs.confirmation.to_csv(index=False).encode())
    put("answers.csv", result.answers().to_csv(index=False).encode())
    import io

    buf = io.BytesIO()
    frontier_figure(result).savefig(buf, format="png", dpi=90)
    put("frontier.png", buf.getvalue())
    put("report.md", render_report(result).encode())
    return written
