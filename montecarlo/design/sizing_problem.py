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

The search is :mod:`montecarlo.design.sizing`.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import pandas as pd

from montecarlo.engine.runner import RunOptions, run_study
from montecarlo.errors import InputError
from montecarlo.systems import study_from_dict

Cheaper = Literal["smaller", "larger"]
RELATIONS = ("common", "independent")
RELATION_TEXT = {"common": "pixel error common to both targets (the paper's assumption)",
                 "independent": "pixel error independent between targets (centroid noise)"}
"""What each pixel-noise relation between the two targets means, for reports."""
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
    n_jobs: int | None = None
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

    Uniform, triangular, arcsine and corner sources get ``bound = value``, normal ones
    ``sigma = value``, truncated normal ones ``sigma = value`` with their bound scaled alike;
    fixed sources (a plain number) stay as they are. Raises :class:`InputError` if the knob has
    no such source in the base design (a lognormal source has no additive scale to size).
    """
    out = {}
    for key in KNOBS[knob].keys:
        src = _get(base, key)
        dist = src.get("dist") if isinstance(src, Mapping) else None
        if dist in ("uniform", "triangular", "arcsine", "corners"):
            out[key] = {**src, "bound": value}
        elif dist == "normal":
            out[key] = {**src, "sigma": value}
        elif dist == "truncnormal" and src.get("sigma", 0.0) > 0.0:
            out[key] = {**src, "sigma": value, "bound": src["bound"] * value / src["sigma"]}
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


DESIGN_LABEL = "the design made of the study file and the options"
"""What a mistake in a design's study is blamed on: not one file but the base study with its
--errors, --from-problem-spec, knobs and requirement options applied."""


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
    return study_from_dict(raw, DESIGN_LABEL)


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


def run_statistic(study: Any, requirement: Requirement, n_jobs: int | None = None) -> pd.DataFrame:
    """Run ``study`` with the study runner; per grid point (in order) the requirement's
    statistic ``value``, its interval ``lo``/``hi`` (display unit), ``count``, ``invalid``, the
    ``verdict`` and ``margin_ok`` (meets with the replication margin)."""
    req = requirement
    result = run_study(study, RunOptions(n_jobs=n_jobs, progress=False))
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
             trials: int, seed: int, block_size: int = 2048, n_jobs: int | None = None,
             name: str = "sizing") -> pd.DataFrame:
    """Run the study runner at the design ``points``: one row each with the knobs and the
    columns of :func:`run_statistic`."""
    study = build_study(problem, points, relation, trials=trials, seed=seed,
                        block_size=block_size, name=name)
    stats = run_statistic(study, problem.requirement, n_jobs)
    return pd.concat([pd.DataFrame([dict(p) for p in points]), stats], axis=1)
