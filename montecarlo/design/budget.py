"""Error-budget allocation at a design point: Sobol variance shares and a split of the spec.

For a ground-calibration design (seed 000, section 1) and one pixel relation, each error source's
share of the variance of the chosen metric is estimated with Sobol indices (SALib, Saltelli's
scheme without second-order terms, bootstrap confidence intervals):

* first order ``S1_i = Var(E[Y | X_i]) / Var(Y)``: the share that source i explains alone;
* total order ``ST_i = E[Var(Y | X_~i)] / Var(Y)``: its share including every interaction.

The sources are the placement errors ``dx_m``, ``dy_m``, ``dh1_m``, the height-scale error
``dh_m`` (the paper's delta_b) and the pixel error ``pixel_px`` (one group: both image axes, and
for independent noise both targets). Fixed sources are not varied; corner (worst-case) sources
have no variance and are refused.

The budget table splits the spec limit among the sources **in proportion to their total-order
variance share, root-sum-square consistent**::

    share_i = ST_i / sum_j ST_j,     allocation_i = limit * sqrt(share_i),
    so that sqrt(sum_i allocation_i**2) = limit.

Beside each allocation stands what the source produces *alone* (every other source switched off),
run through the study runner with the requirement's percentile and its confidence interval, and
the scale of that source that would use exactly its allocation (``scale * allocation / alone``,
first order: a lone small error source moves the metric in proportion to its scale).

The RSS rule is exact for the variances of independent additive contributions; the rotation
angle is the length of the error vector, not a sum, so ``sum S1 < 1`` there (interactions), and a
percentile of a sum is not the RSS of the percentiles. The table is a planning aid for where to
spend money, not a second verdict: the verdict on the whole design is the study's.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from SALib.analyze import sobol as sobol_analyze
from SALib.sample import sobol as sobol_sample

from montecarlo.design.sizing_problem import (
    Requirement,
    design_overrides,
    ground_study,
    run_statistic,
    verdicts,
)
from montecarlo.engine.distributions import Distribution
from montecarlo.errors import InputError
from montecarlo.seed000 import ground
from montecarlo.systems.ground import MOUNTING_SOURCES, PLACEMENT_SOURCES, PreparedGround

SOURCE_LABELS = {
    "dx_m": "lateral placement δx",
    "dy_m": "range placement δy",
    "dh1_m": "height reference δh1",
    "dh_m": "height scale δb",
    "pixel_px": "pixel error",
}
SOURCE_UNITS = {"dx_m": "m", "dy_m": "m", "dh1_m": "m", "dh_m": "m", "pixel_px": "px"}


def _seeds(rng: int | np.random.Generator | None) -> tuple[np.random.Generator, int]:
    """Independent streams for the Sobol sample (a Generator) and SALib's bootstrap (an int > 0,
    as SALib treats seed 0 as 'unseeded')."""
    if isinstance(rng, np.random.Generator):
        seq = np.random.SeedSequence(int(rng.integers(2**63)))
    else:
        seq = np.random.SeedSequence(rng)
    sample_seq, boot_seq = seq.spawn(2)
    boot = int(boot_seq.generate_state(1, np.uint64)[0] % np.uint64(2**62)) + 1
    return np.random.Generator(np.random.PCG64(sample_seq)), boot


def sobol_indices(problem: Mapping[str, Any], model: Callable[[np.ndarray], np.ndarray], n: int,
                  rng: int | np.random.Generator | None = None, confidence: float = 0.95,
                  resamples: int = 200) -> pd.DataFrame:
    """First- and total-order Sobol indices with SALib, with bootstrap confidence intervals.

    Parameters
    ----------
    problem : mapping
        SALib problem: ``num_vars``, ``names``, ``bounds``, optional ``dists`` and ``groups``.
    model : callable
        ``model(X)`` for the sample matrix ``X`` of shape (m, num_vars) returns shape (m,).
    n : int
        Base sample size, a power of 2; the model is evaluated ``n (G + 2)`` times for G
        variables or groups.
    rng : int, Generator or None
        Seeds the scrambled Sobol sequence and the bootstrap.
    confidence : float
        Level of the intervals; ``S1_conf``, ``ST_conf`` are their half-widths.
    resamples : int
        Bootstrap resamples.

    Returns
    -------
    DataFrame indexed by variable (or group) name, columns S1, S1_conf, ST, ST_conf.
    """
    if n < 2 or n & (n - 1):
        raise InputError(f"samples: the Sobol base sample size must be a power of 2 (got {n})")
    sample_rng, boot_seed = _seeds(rng)
    problem = dict(problem)
    x = sobol_sample.sample(problem, n, calc_second_order=False, seed=sample_rng)
    y = np.asarray(model(x), float)
    bad = np.count_nonzero(~np.isfinite(y))
    if bad:
        raise InputError(f"{bad} of {y.size} model evaluations have no valid solution; Sobol "
                         f"indices need the design to be solvable everywhere in its error bounds")
    si = sobol_analyze.analyze(problem, y, calc_second_order=False, conf_level=confidence,
                               num_resamples=resamples, seed=boot_seed)
    names = list(dict.fromkeys(problem.get("groups") or problem["names"]))
    return pd.DataFrame({k: np.asarray(si[k], float) for k in ("S1", "S1_conf", "ST", "ST_conf")},
                        index=pd.Index(names, name="source"))


def _pixel_columns(relation: str) -> tuple[str, ...]:
    return ("pixel_x", "pixel_z") if relation == "common" else \
        ("pixel_a_x", "pixel_a_z", "pixel_b_x", "pixel_b_z")


def _salib_dist(name: str, d: Distribution) -> tuple[str, list[float]]:
    if d.kind == "uniform":
        return "unif", [d.location - d.scale, d.location + d.scale]
    if d.kind == "normal":
        return "norm", [d.location, d.scale]
    if d.kind == "triangular":
        return "triang", [d.location - d.scale, d.location + d.scale, 0.5]
    if d.kind == "truncnormal":
        half = d.scale * d.shape
        return "truncnorm", [d.location - half, d.location + half, d.location, d.scale]
    raise InputError(f"{name}: a budget needs uniform, triangular, normal or truncnormal "
                     f"error sources, whose scale it can allot (got {d.kind}); corners are a "
                     f"worst case and have no variance")


@dataclass(frozen=True)
class GroundBudgetModel:
    """The ground calibration as a function of its random error sources, for SALib.

    ``columns`` are the sample-matrix columns: placement sources by name, pixel errors as
    ``pixel_x``/``pixel_z`` (common to both targets) or ``pixel_a_x`` ... ``pixel_b_z``
    (independent); ``groups`` maps each column to its source.
    """

    prepared: PreparedGround
    relation: str
    metric: str
    variant: str
    columns: tuple[str, ...]
    groups: tuple[str, ...]
    dists: tuple[str, ...]
    bounds: tuple[tuple[float, ...], ...]

    @classmethod
    def from_prepared(cls, prepared: PreparedGround, relation: str, metric: str, variant: str
                      ) -> GroundBudgetModel:
        for name, d in zip(MOUNTING_SOURCES, prepared.mounting, strict=True):
            if d.kind != "fixed":
                raise InputError(f"mounting.{name}: a budget needs fixed true mounting angles "
                                 f"(got {d.kind})")
        columns, groups, dists, bounds = [], [], [], []
        for name in PLACEMENT_SOURCES:
            d = prepared.placement[name]
            if d.kind == "fixed" or d.scale == 0.0:
                continue
            dist, b = _salib_dist(f"errors.{name}", d)
            columns.append(name)
            groups.append(name)
            dists.append(dist)
            bounds.append(tuple(b))
        if prepared.pixel.kind != "fixed" and prepared.pixel.scale != 0.0:
            dist, b = _salib_dist("errors.pixel_px", prepared.pixel)
            for col in _pixel_columns(relation):
                columns.append(col)
                groups.append("pixel_px")
                dists.append(dist)
                bounds.append(tuple(b))
        if len(set(groups)) < 2:
            raise InputError("errors: a budget needs at least two random error sources "
                             f"(got {', '.join(dict.fromkeys(groups)) or 'none'})")
        return cls(prepared, relation, metric, variant, tuple(columns), tuple(groups),
                   tuple(dists), tuple(bounds))  # type: ignore[arg-type]

    def salib_problem(self) -> dict[str, Any]:
        return {"num_vars": len(self.columns), "names": list(self.columns),
                "groups": list(self.groups), "dists": list(self.dists),
                "bounds": [list(b) for b in self.bounds]}

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Metric [rad] of each row of the sample matrix ``x``, shape (m,); NaN if invalid."""
        p = self.prepared
        col = {name: x[:, i] for i, name in enumerate(self.columns)}

        def value(name: str, fallback: float) -> Any:
            return col.get(name, fallback)

        px0 = p.pixel.location
        if self.relation == "common":
            pix_a = np.stack([value("pixel_x", px0) * np.ones(len(x)),
                              value("pixel_z", px0) * np.ones(len(x))], -1)
            pix_b = pix_a
        else:
            pix_a = np.stack([value("pixel_a_x", px0) * np.ones(len(x)),
                              value("pixel_a_z", px0) * np.ones(len(x))], -1)
            pix_b = np.stack([value("pixel_b_x", px0) * np.ones(len(x)),
                              value("pixel_b_z", px0) * np.ones(len(x))], -1)
        place = {n: value(n, p.placement[n].location) for n in PLACEMENT_SOURCES}
        true = tuple(d.location for d in p.mounting)
        sol = ground.simulate(p.camera, true, p.L, p.H, dx=place["dx_m"], dy=place["dy_m"],
                              dh1=place["dh1_m"], dh=place["dh_m"], pixel_error_a=pix_a,
                              pixel_error_b=pix_b, solvers=(self.variant,))[self.variant]
        return ground.solution_metrics(sol, true)[self.metric]


def allocate(total_order: pd.Series, limit: float) -> pd.DataFrame:
    """Split ``limit`` in proportion to the total-order shares, RSS-consistent.

    Negative estimates (noise around 0) count as 0. Returns columns ``share`` (sums to 1) and
    ``allocation`` (``limit * sqrt(share)``, whose root-sum-square is ``limit``).
    """
    st = total_order.clip(lower=0.0)
    if not st.sum() > 0:
        raise ValueError("no source has a positive total-order index")
    share = st / st.sum()
    return pd.DataFrame({"share": share, "allocation": limit * np.sqrt(share)})


def _describe_source(raw: Mapping[str, Any], unit: str) -> str:
    match raw.get("dist"):
        case "uniform":
            return f"uniform ±{raw['bound']:.3g} {unit}"
        case "normal":
            return f"normal σ {raw['sigma']:.3g} {unit}"
        case "corners":
            return f"corners ±{raw['bound']:.3g} {unit}"
        case "triangular" | "arcsine":
            return f"{raw['dist']} ±{raw['bound']:.3g} {unit}"
        case "truncnormal":
            return f"normal σ {raw['sigma']:.3g} {unit} cut at ±{raw['bound']:.3g} {unit}"
        case "lognormal":
            return f"lognormal, median {raw['median']:.3g} {unit}, σ_ln {raw['sigma_ln']:.3g}"
    return f"fixed {raw.get('value', 0.0):.3g} {unit}"


def _scale_of(raw: Mapping[str, Any]) -> float:
    return float(raw.get("sigma", raw.get("bound", raw.get("value", 0.0))))


@dataclass
class BudgetResult:
    """Sobol indices and the budget table of one design point and pixel relation.

    ``table`` has one row per source (index) with: distribution, S1, S1_conf, ST, ST_conf,
    share, allocation, alone, alone_lo, alone_hi, alone_verdict (alone vs allocation), scale,
    allowed_scale; ``total`` holds the whole design's statistic, interval and verdict.
    """

    relation: str
    requirement: Requirement
    point: dict[str, float]
    unit: str
    table: pd.DataFrame
    total: pd.Series
    samples: int
    evaluations: int
    seed: int
    trials: int
    problem: dict[str, Any] | None = None
    """The SALib problem of the Sobol analysis (names, groups, dists, bounds)."""


def budget(base: Mapping[str, Any], requirement: Requirement, relation: str,
           point: Mapping[str, float] | None = None, *, samples: int = 8192, seed: int = 0,
           trials: int = 20000, resamples: int = 200, n_jobs: int | None = None,
           block_size: int = 4096) -> BudgetResult:
    """Sobol indices of every random error source and the budget table at a design point.

    Parameters
    ----------
    base : mapping
        Ground study (parsed TOML, sweeps ignored).
    requirement : Requirement
        Metric, solver variant, percentile, limit [display unit] and confidence (used for the
        Sobol intervals and the percentile intervals).
    relation : {"common", "independent"}
    point : mapping, optional
        Sizing knobs (``L_m``, ``H_m``, ``pixel_px``, ``survey_m``, ``scale_m``) to set.
    samples : int
        Sobol base sample size (power of 2).
    seed : int
        Seeds the Sobol sample, the bootstrap and the study runs.
    trials : int
        Trials of each study run (the design and each source alone).
    """
    point = dict(point or {})
    req = requirement
    design = design_overrides(base, point)

    def study(overrides: Sequence[Mapping[str, Any]], name: str) -> Any:
        return ground_study(base, req, overrides, relation, trials=trials, seed=seed,
                            block_size=block_size, name=name)

    one = study([design], "budget-design")
    metric = one.metric(req.metric)
    gp = one.points[0]
    model = GroundBudgetModel.from_prepared(gp.prepared, relation, req.metric, req.variant)
    indices = sobol_indices(model.salib_problem(), model, samples, rng=seed,
                            confidence=req.confidence, resamples=resamples)
    sources = list(indices.index)
    raw = {s: gp.config.errors.model_dump(mode="json")[s] for s in sources}
    keys = [f"errors.{s}" for s in sources]
    rows = [{**design, **{k: raw[s] for k, s in zip(keys, sources, strict=True)}}]
    for s in sources:
        rows.append({**design, **{k: raw[t] if t == s else 0.0
                                  for k, t in zip(keys, sources, strict=True)}})
    stats = run_statistic(study(rows, "budget-alone"), req, n_jobs)
    table = indices.join(allocate(indices["ST"], req.limit))
    table.insert(0, "distribution", [_describe_source(raw[s], SOURCE_UNITS[s]) for s in sources])
    alone = stats.iloc[1:].set_index(pd.Index(sources))
    table["alone"] = alone["value"]
    table["alone_lo"] = alone["lo"]
    table["alone_hi"] = alone["hi"]
    table["alone_verdict"] = [verdicts(a["value"], a["lo"], a["hi"], a["invalid"], lim)[()]
                              for (_, a), lim in zip(alone.iterrows(), table["allocation"],
                                                     strict=True)]
    table["scale"] = [_scale_of(raw[s]) for s in sources]
    table["allowed_scale"] = table["scale"] * table["allocation"] / table["alone"]
    total = stats.iloc[0].copy()
    evaluations = samples * (len(sources) + 2)
    return BudgetResult(relation, req, point, metric.unit, table, total, samples, evaluations,
                        seed, trials, model.salib_problem())
