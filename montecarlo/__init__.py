"""Monte Carlo error budgets for boresight calibration of strapdown electro-optical sensors.

``montecarlo.run(study)`` runs a study and returns a :class:`montecarlo.api.Result`;
``montecarlo.load_study(path)`` validates a study file. They are imported on first use, so that
``import montecarlo`` (and the command line) stay quick.
"""

import importlib
from typing import Any

__version__ = "0.1.0"
__all__ = ["Result", "load_study", "run"]

_LAZY = {"run": "montecarlo.api", "Result": "montecarlo.api", "load_study": "montecarlo.systems"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'montecarlo' has no attribute {name!r}")
