"""What the discrepancy engine sees of measured data: effects, a base model and candidates.

A :class:`Problem` states the measured data through one function of named parameters, the
*whitened* residuals ``r = W (observed - predicted)`` (unit variance, uncorrelated when the model
is right and the stated noise is true), a base model (an :class:`Effect` whose parameters are
always fitted) and a library of candidate effects, each a parametric extension of the forward
model that is zero (absent) when its parameters are zero.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Effect:
    """A named group of parameters of a forward model.

    Attributes
    ----------
    name : effect name (e.g. ``"focal_scale"``).
    parameters : parameter names, unique across the problem.
    bounds : physical (lower, upper) bound of each parameter, in its SI unit.
    steps : central-difference step of each parameter for the Jacobian.
    description : one line for reports (parametrisation and units).
    direction : relative size of the parameters for an injection "along the effect" (synthetic
        data, acceptance runs); the diagnosis never uses it.
    """

    name: str
    parameters: tuple[str, ...]
    bounds: tuple[tuple[float, float], ...]
    steps: tuple[float, ...]
    description: str = ""
    direction: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        k = len(self.parameters)
        if len(self.bounds) != k or len(self.steps) != k:
            raise ValueError(f"effect {self.name}: bounds and steps need one entry per parameter")
        if self.direction is not None and len(self.direction) != k:
            raise ValueError(f"effect {self.name}: direction needs one entry per parameter")


Residuals = Callable[[Mapping[str, FloatArray]], FloatArray]
"""Whitened residuals of named parameter values. Values are floats, or arrays of shape (k, 1)
for k parameter vectors at once (result (k, n)); parameters not given are zero."""


@dataclass(frozen=True)
class Problem:
    """Measured data, a base model and candidate effects, as the engine sees them.

    Attributes
    ----------
    system : name for reports (``"ground"``, ``"collimation"``).
    base : the parameters always fitted (bounds usually infinite).
    candidates : the library of candidate effects.
    residuals : see :data:`Residuals`; ``n_obs`` values per parameter vector.
    start : starting values of the base parameters.
    unavailable : candidate name -> reason it cannot be tested with these data (e.g. no time
        column); such candidates are reported, never tested.
    observations : (id, row in the data file, indices of its whitened residuals) of each
        observation that can be wrong on its own (a target's image point, a mirror's
        readings); empty: no data snooping.
    separating_data : pair of candidate names -> the extra data that would tell them apart
        (for reports of confounded groups; pairs not listed get a generic text).
    requires : candidate name -> the candidate that must be in the model before it is tested
        (a hierarchy such as radial distortion's k1, then k2, then k3); until then it is
        reported ``unavailable``.
    unit_columns : parameter -> the one whitened residual it shifts, ``r - b`` (an
        observation's shift, :func:`with_outliers`): its Jacobian column is that row of the
        identity, exactly, and is not differentiated numerically.
    local_rows : parameter -> the only whitened residuals it changes (a camera view's pose:
        that view's corners); parameters of disjoint rows are differentiated in one model
        evaluation (:func:`~montecarlo.discrepancy.fit.jacobian`). Parameters not listed may
        change every residual.
    """

    system: str
    base: Effect
    candidates: tuple[Effect, ...]
    residuals: Residuals
    start: Mapping[str, float]
    unavailable: Mapping[str, str] = field(default_factory=dict)
    observations: tuple[tuple[str, int, tuple[int, ...]], ...] = ()
    separating_data: Mapping[frozenset[str], str] = field(default_factory=dict)
    requires: Mapping[str, str] = field(default_factory=dict)
    unit_columns: Mapping[str, int] = field(default_factory=dict)
    local_rows: Mapping[str, NDArray[np.int64]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        names = [p for e in (self.base, *self.candidates) for p in e.parameters]
        if len(set(names)) != len(names):
            raise ValueError("parameter names must be unique across base and candidates")
        effects = [e.name for e in (self.base, *self.candidates)]
        if len(set(effects)) != len(effects):
            raise ValueError("effect names must be unique")

    def effect(self, name: str) -> Effect:
        for e in (self.base, *self.candidates):
            if e.name == name:
                return e
        raise KeyError(f"unknown effect {name!r}; known: "
                       f"{', '.join(e.name for e in self.candidates)}")

    @cached_property
    def local_row_sets(self) -> dict[str, frozenset[int]]:
        """``local_rows`` as sets, formed once per problem (every Jacobian groups by them)."""
        return {n: frozenset(np.asarray(r).tolist()) for n, r in self.local_rows.items()}

    @cached_property
    def parameter_effect(self) -> dict[str, Effect]:
        return {p: e for e in (self.base, *self.candidates) for p in e.parameters}


OUTLIER = "outlier:"
"""Prefix of the effect (and its parameters) that shifts one observation."""


def outlier_effect(obs_id: str, rows: tuple[int, ...]) -> Effect:
    """The mean-shift model of one observation: a shift of each of its whitened residuals
    [units of the stated noise, sigma], unbounded."""
    return Effect(f"{OUTLIER}{obs_id}", tuple(f"{OUTLIER}{obs_id}[{k}]" for k in range(len(rows))),
                  ((-np.inf, np.inf),) * len(rows), (1.0,) * len(rows),
                  f"observation {obs_id} off by more than its noise [sigma]")


def with_outliers(problem: Problem) -> Problem:
    """``problem`` with one mean-shift effect per observation among its candidates.

    Observation shifts enter the whitened residuals directly: ``r - E b``, E the observation's
    rows. Baarda's data snooping is then the identification test of these effects.
    """
    if not problem.observations:
        return problem
    effects = tuple(outlier_effect(oid, rows) for oid, _, rows in problem.observations)
    where = {p: row for e, (_, _, rows) in zip(effects, problem.observations, strict=True)
             for p, row in zip(e.parameters, rows, strict=True)}
    base = problem.residuals

    def residuals(values: Mapping[str, FloatArray]) -> FloatArray:
        r = np.asarray(base(values), dtype=float)
        shifts = [(where[p], np.asarray(v, float)) for p, v in values.items() if p in where]
        batch = max((v.shape[0] for _, v in shifts if v.ndim), default=0)
        r = np.array(np.broadcast_to(r, (batch, r.shape[-1])) if batch and r.ndim == 1 else r)
        for row, v in shifts:
            r[..., row] -= v.reshape(-1) if v.ndim else v
        return r

    return Problem(problem.system, problem.base, (*problem.candidates, *effects), residuals,
                   problem.start, problem.unavailable, problem.observations,
                   problem.separating_data, problem.requires,
                   {**problem.unit_columns, **where}, problem.local_rows)


def is_outlier(name: str) -> bool:
    return name.startswith(OUTLIER)
