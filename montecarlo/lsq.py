"""The result of a weighted least-squares fit: the one type every fit of the package returns.

Residuals are *whitened*: ``r = W (observed - predicted)`` has unit variance and no correlation
when the model is right and the stated noise is true, so ``chi2 = r'r`` follows ``chi2(dof)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def orthonormal_basis(M: FloatArray) -> FloatArray:
    """Orthonormal basis of the column space of M (SVD, numerically rank-revealing: directions
    whose singular value is below 1e-12 of the largest are dropped)."""
    if M.shape[1] == 0:
        return np.zeros((M.shape[0], 0))
    u, s, _ = np.linalg.svd(M, full_matrices=False)
    keep = s > 1e-12 * max(s[0], 1e-300)
    return u[:, keep]


class ParameterSummary:
    """Named values, standard errors, correlations and chi2_red of a fit result.

    For a (data)class with ``names``, ``values``, ``covariance``, ``chi2`` and ``dof``.
    """

    if TYPE_CHECKING:
        names: tuple[str, ...]
        values: FloatArray
        covariance: FloatArray
        chi2: float
        dof: int

    @property
    def params(self) -> dict[str, float]:
        return dict(zip(self.names, self.values.tolist(), strict=True))

    @property
    def stderr(self) -> dict[str, float]:
        return dict(zip(self.names, np.sqrt(np.diag(self.covariance)).tolist(), strict=True))

    @property
    def correlation(self) -> FloatArray:
        """(p, p) correlation matrix of the values."""
        s = np.sqrt(np.diag(self.covariance))
        return self.covariance / np.outer(s, s)

    @property
    def chi2_red(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else math.nan


@dataclass(frozen=True)
class LeastSquaresFit(ParameterSummary):
    """Weighted least-squares solution of a model with named parameters.

    Attributes
    ----------
    names, values : fitted parameters, in SI units and radians.
    covariance : (p, p) covariance of the values, ``(A'A)^-1`` of the whitened Jacobian ``A``
        (scaled by the a-posteriori variance where the noise was estimated, see the fitter).
    residual : (n,) whitened residuals at the solution.
    jacobian : (n, p) ``A = d(predicted, whitened)/d(parameters) = -d residual / d parameters``.
    effects : names of the model's components whose parameters were fitted (if it has any).
    """

    names: tuple[str, ...]
    values: FloatArray
    covariance: FloatArray
    residual: FloatArray
    jacobian: FloatArray
    effects: tuple[str, ...] = ()

    @property
    def chi2(self) -> float:  # type: ignore[override]
        return float(self.residual @ self.residual)

    @property
    def dof(self) -> int:  # type: ignore[override]
        return self.residual.size - len(self.names)

    @property
    def p_value(self) -> float:
        """Global test: ``P(chi2(dof) >= chi2)``."""
        from scipy import stats

        return float(stats.chi2.sf(self.chi2, self.dof)) if self.dof > 0 else math.nan

    @cached_property
    def column_basis(self) -> FloatArray:
        """Orthonormal basis of the Jacobian's column space (:func:`orthonormal_basis`),
        computed once per fit: every test of a step projects on it."""
        return orthonormal_basis(self.jacobian)
