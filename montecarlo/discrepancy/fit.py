"""Nonlinear least-squares fit of a :class:`~montecarlo.discrepancy.problem.Problem`'s model.

The base model plus named candidate effects, candidate parameters within their physical
bounds (``scipy.optimize.least_squares``), with the whitened Jacobian by central differences.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy import optimize
from threadpoolctl import ThreadpoolController

from montecarlo.discrepancy.problem import Problem
from montecarlo.lsq import LeastSquaresFit

FloatArray = NDArray[np.float64]

ONE_THREAD = ThreadpoolController().wrap(limits=1, user_api="blas")
"""Decorator: the function runs with BLAS and LAPACK on one thread. The engine decomposes tall,
thin matrices (n x p, p of tens), whose threads cost far more CPU than they save: an SVD of a
2,600 x 45 matrix took 0.7 s of CPU on two threads of a loaded host, 0.01 s on one."""


SEPARABLE_CONDITION = float(np.sqrt(np.finfo(float).eps))
"""Smallest ratio of the column-normalised design's least to largest singular value that a fit
accepts: the normal matrix then keeps a condition number within double precision (1/eps)."""


class FitError(ValueError):
    """The model cannot be fitted to these data (too few observations, singular design)."""


def jacobian(problem: Problem, values: Mapping[str, float], names: Sequence[str],
             step_scale: float = 1.0, groups: list[list[int]] | None = None) -> FloatArray:
    """Whitened design columns ``-d residual / d parameter`` by central differences, (n, k).

    All perturbed parameter vectors go through ``problem.residuals`` in one vectorised call;
    parameters in ``values`` but not in ``names`` are held at their values. The steps are the
    effects' ``steps`` times ``step_scale``. A parameter of ``problem.unit_columns`` gets its
    exact column (a row of the identity) instead. Parameters of ``problem.local_rows`` whose
    rows do not overlap are perturbed together (:func:`perturbation_groups`): each one's
    column is read on its own rows, where the others change nothing. ``groups``, if given,
    are those groups (a fit's every Jacobian has the same).
    """
    effect_of = problem.parameter_effect
    unit = problem.unit_columns
    varied = [j for j, n in enumerate(names) if n not in unit]
    steps = step_scale * np.array([effect_of[names[j]].steps[
        effect_of[names[j]].parameters.index(names[j])] for j in varied])
    if groups is None:
        groups = perturbation_groups([names[j] for j in varied], problem.local_row_sets)
    k = len(groups)
    batch = {n: np.full((2 * k, 1), float(v)) for n, v in values.items()}
    for g, members in enumerate(groups):
        for i in members:
            column = batch.setdefault(names[varied[i]], np.zeros((2 * k, 1)))
            column[g, 0] += steps[i]
            column[k + g, 0] -= steps[i]
    if k:
        r = problem.residuals(batch)
        n_obs = r.shape[-1]
    else:
        n_obs = problem.residuals(dict(values)).size
    J = np.zeros((n_obs, len(names)))
    for g, members in enumerate(groups):
        for i in members:
            rows = problem.local_rows.get(names[varied[i]], slice(None))
            J[rows, varied[i]] = -(r[g, rows] - r[k + g, rows]) / (2.0 * steps[i])
    for j, n in enumerate(names):
        if n in unit:
            J[unit[n], j] = 1.0
    return J


def perturbation_groups(names: Sequence[str], local_rows: Mapping[str, frozenset[int]]
                        ) -> list[list[int]]:
    """Indices of ``names`` in groups that can be perturbed in one model evaluation: each
    parameter not in ``local_rows`` alone, the others first-fit into groups of disjoint rows
    (a camera's views: the same pose parameter of every view in one group)."""
    groups: list[list[int]] = []
    taken: list[set[int]] = []
    for i, name in enumerate(names):
        rows = local_rows.get(name)
        if not rows:
            groups.append([i])
            taken.append(set())
            continue
        for members, used in zip(groups, taken, strict=True):
            if used and used.isdisjoint(rows):
                members.append(i)
                used |= rows
                break
        else:
            groups.append([i])
            taken.append(set(rows))
    return groups


ROUNDOFF = 0.5
"""A column is round-off when its estimates at two steps ``h`` and ``2h`` differ by more than
this fraction of its norm (:func:`candidate_columns`)."""


def candidate_columns(problem: Problem, values: Mapping[str, float], names: Sequence[str]
                      ) -> FloatArray:
    """:func:`jacobian` columns of candidate parameters, those that are round-off set to zero.

    A parameter that changes the data gives the same column at steps ``h`` and ``2h`` (to
    ``O(h^2)``); one that does not (it cancels, e.g. a common bias of relative readings) gives
    the round-off of the residuals over ``2h``, which halves from ``h`` to ``2h``: the two
    estimates then differ by about the column's own norm. So do the differences of a parameter
    whose derivative is zero here but not its higher ones (``k^3`` at ``k = 0`` gives ``h^2``
    and ``4 h^2``). Such a column is zero, so that its candidate has "no effect" instead of an
    MDB of the round-off (1e9 arcsec and more) and an influence on the model that is noise.
    """
    G = jacobian(problem, values, names)
    wide = jacobian(problem, values, names, step_scale=2.0)
    noise = np.linalg.norm(G - wide, axis=0) > ROUNDOFF * np.linalg.norm(G, axis=0)
    G[:, noise] = 0.0
    return G


@ONE_THREAD
def fit_model(problem: Problem, effects: Sequence[str], start: Mapping[str, float] | None = None
              ) -> LeastSquaresFit:
    """Fit the base model plus ``effects`` (names of candidates) by nonlinear least squares.

    Candidate parameters are bounded by their physical bounds (``method="trf"``); unspecified
    starting values are the problem's base start and zero for candidates. An unbounded
    parameter of ``problem.unit_columns`` (a flagged observation's shift ``b`` of one whitened
    residual) is not iterated on: its residual ``r_i - b`` is zero at ``b = r_i``, so the other
    parameters are those of the fit without row ``i`` (:func:`_solve`), and ``b`` is ``r_i``
    there. The result is the fit of every parameter, with its full Jacobian and covariance.

    Raises
    ------
    FitError
        Fewer observations than parameters plus one, or a singular design.
    """
    model = (problem.base.name, *[e for e in effects if e != problem.base.name])
    chosen = [problem.effect(e) for e in model]
    names = tuple(p for e in chosen for p in e.parameters)
    bounds = [b for e in chosen for b in e.bounds]
    lower = np.array([b[0] for b in bounds])
    upper = np.array([b[1] for b in bounds])
    guess = {**problem.start, **(start or {})}
    margin = np.where(np.isfinite(upper - lower), 1e-9 * (upper - lower), 0.0)
    x0 = np.clip(np.array([float(guess.get(n, 0.0)) for n in names]), lower + margin,
                 upper - margin)
    n_obs = problem.residuals(dict(zip(names, x0, strict=True))).size
    if n_obs < len(names) + 1:
        raise FitError(f"{n_obs} observations cannot fit {len(names)} parameters with a "
                       "degree of freedom left")
    shift = [j for j, n in enumerate(names) if n in problem.unit_columns
             and np.isinf(lower[j]) and np.isinf(upper[j])]
    iterated = [j for j in range(len(names)) if j not in set(shift)]
    out_rows = [problem.unit_columns[names[j]] for j in shift]
    keep = np.ones(n_obs, bool)
    keep[out_rows] = False
    theta, J, r = _solve(problem, [names[j] for j in iterated], x0[iterated], lower[iterated],
                         upper[iterated], keep)
    values = np.empty(len(names))
    values[iterated] = theta
    values[shift] = r[out_rows]
    r[out_rows] = 0.0
    A = np.zeros((n_obs, len(names)))
    A[:, iterated] = J
    A[out_rows, shift] = 1.0
    norms = np.linalg.norm(A, axis=0)
    s = np.linalg.svd(A / np.where(norms > 0, norms, 1.0), compute_uv=False)
    # the normal matrix A'A has the square of this condition: beyond 1/sqrt(eps) its inverse
    # is round-off, whether or not LAPACK happens to find it singular
    if norms.min() == 0.0 or s[-1] < SEPARABLE_CONDITION * s[0]:
        raise FitError(f"parameters of {', '.join(model)} are not separable with these data")
    try:
        cov = np.linalg.inv(A.T @ A)
    except np.linalg.LinAlgError:  # condition of A'A, the square of A's, beyond double precision
        raise FitError(f"parameters of {', '.join(model)} are not separable with these "
                       "data") from None
    return LeastSquaresFit(names, values, cov, r, A, effects=model)


def _solve(problem: Problem, names: list[str], x0: FloatArray, lower: FloatArray,
           upper: FloatArray, keep: NDArray[np.bool_]
           ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``scipy.optimize.least_squares`` of parameters ``names`` on the whitened residuals
    ``keep`` selects. Returns the solution, :func:`jacobian` there and the residuals there
    (every row of both)."""
    rows: slice | NDArray[np.bool_] = slice(None) if keep.all() else keep
    last: dict[str, FloatArray] = {}
    groups = perturbation_groups([n for n in names if n not in problem.unit_columns],
                                 problem.local_row_sets)

    def fun(x: FloatArray) -> FloatArray:
        return problem.residuals(dict(zip(names, x, strict=True)))[rows]

    def jac(x: FloatArray) -> FloatArray:
        last["x"], last["J"] = x.copy(), jacobian(problem, dict(zip(names, x, strict=True)),
                                                  names, groups=groups)
        return -last["J"][rows]

    bounded = bool(np.isfinite(lower).any() or np.isfinite(upper).any())
    sol = optimize.least_squares(fun, x0, jac=jac, bounds=(lower, upper),
                                 method="trf" if bounded else "lm", x_scale="jac",
                                 xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=200)
    r = np.array(problem.residuals(dict(zip(names, sol.x, strict=True))), dtype=float)
    if not np.all(np.isfinite(r)):
        raise FitError("the model gives no finite prediction for these data")
    if not np.array_equal(last.get("x"), sol.x):  # trf and lm evaluate it after each step
        jac(sol.x)
    return sol.x, last["J"], r
