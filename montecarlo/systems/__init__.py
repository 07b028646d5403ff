"""The simulated systems a study file can name (``[study] system = ...``), and study loading.

| name | what a trial is | module |
|---|---|---|
| ``ground`` | seed 000's two-target ground calibration (eqs. 1-18) | :mod:`.ground` |
| ``air`` | seed 000's air dynamic calibration (eq. 19) | :mod:`.air` |
| ``collimation`` | seed 003's autocollimator-INS calibration | :mod:`.collimation` |
| ``stabilization`` | seed 001's gimbal installation angles | :mod:`.stabilization` |
| ``discrepancy_ground``, ``discrepancy_collimation`` | a simulated data set, fitted or
  diagnosed | :mod:`.discrepancy` |
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from montecarlo.engine import study as _study
from montecarlo.engine.study import Study
from montecarlo.engine.system import System


def _ground() -> System:
    from montecarlo.systems.ground import GroundSystem

    return GroundSystem()


def _air() -> System:
    from montecarlo.systems.air import AIR

    return AIR


def _collimation() -> System:
    from montecarlo.systems.collimation import COLLIMATION

    return COLLIMATION


def _stabilization() -> System:
    from montecarlo.systems.stabilization import STABILIZATION

    return STABILIZATION


def _discrepancy_ground() -> System:
    from montecarlo.systems.discrepancy import GROUND

    return GROUND


def _discrepancy_collimation() -> System:
    from montecarlo.systems.discrepancy import COLLIMATION

    return COLLIMATION


REGISTRY: dict[str, Callable[[], System]] = {
    "ground": _ground,
    "air": _air,
    "collimation": _collimation,
    "stabilization": _stabilization,
    "discrepancy_ground": _discrepancy_ground,
    "discrepancy_collimation": _discrepancy_collimation,
}
"""System name -> factory; each system's module is imported only when a study names it."""


def load_study(path: str | Path, *, trials: int | None = None, seed: int | None = None,
               max_points: int = _study.MAX_POINTS) -> Study:
    """Read, validate and expand a study file; ``trials``/``seed`` override the file's; a
    sweep of more than ``max_points`` grid points is refused before it is expanded.

    Raises
    ------
    montecarlo.errors.InputError
        One line naming the file, the key and the value.
    """
    return _study.load_study(path, REGISTRY, trials=trials, seed=seed, max_points=max_points)


def study_with_errors(raw: dict[str, Any], path: str | Path, errors: str | Path,
                      **options: Any) -> tuple[dict[str, Any], Study]:
    """The study ``raw`` (from ``path``) with its [errors] updated from the errors file
    ``errors``, each mistake named in the file that makes it (see
    :func:`montecarlo.engine.study.study_with_errors`)."""
    return _study.study_with_errors(raw, path, errors, REGISTRY, **options)


def study_from_dict(raw: dict[str, Any], path: str | Path = "<study>", *,
                    trials: int | None = None, seed: int | None = None,
                    max_points: int = _study.MAX_POINTS) -> Study:
    """Validate and expand a study given as a dict (the parsed TOML); ``path`` labels errors."""
    return _study.study_from_dict(raw, REGISTRY, path, trials=trials, seed=seed,
                                  max_points=max_points)
