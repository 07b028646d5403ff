"""SALib problem files (the ``ProblemSpec`` form) for the error budget: export and import.

``montecarlo budget --problem-spec OUT.json`` writes the factors of each budget as a SALib
problem, the JSON form of ``SALib.ProblemSpec``::

    {"num_vars": 4, "names": ["dx_m", "dy_m", "pixel_x", "pixel_z"],
     "groups": ["dx_m", "dy_m", "pixel_px", "pixel_px"],
     "dists": ["unif", "unif", "unif", "unif"],
     "bounds": [[-0.1, 0.1], [-0.1, 0.1], [-1.0, 1.0], [-1.0, 1.0]],
     "outputs": ["rotation_angle"]}

``montecarlo budget --from-problem-spec IN.json`` reads one and sets the study's error sources
from it, so that engineers who keep their factors in SALib's form need not retype them.

Names are the budget model's columns (:class:`montecarlo.design.budget.GroundBudgetModel`):
``dx_m``, ``dy_m``, ``dh1_m``, ``dh_m`` [m], and the pixel errors [px] as ``pixel_x``,
``pixel_z`` (common to both targets) or ``pixel_a_x``, ``pixel_a_z``, ``pixel_b_x``,
``pixel_b_z`` (independent), all of group ``pixel_px`` with one distribution: the names say
the pixel relation. Distributions (SALib's ``dists`` and the meaning of ``bounds``):

==========  ==============================  ================================================
SALib       bounds                          study error source
==========  ==============================  ================================================
unif        [low, high]                     uniform, center (low+high)/2, bound (high-low)/2
norm        [mean, sigma]                   normal, mean, sigma
triang      [low, high, 0.5]                triangular (symmetric only), center, bound
truncnorm   [low, high, mean, sigma]        truncnormal, mean, sigma, bound (symmetric only)
==========  ==============================  ================================================

A placement source the problem does not list is fixed at its centre. Anything else is refused
in one line naming the file, the entry and the value.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from montecarlo.design.budget import SOURCE_UNITS
from montecarlo.errors import InputError
from montecarlo.systems.ground import PLACEMENT_SOURCES

PIXEL_COLUMNS = {"common": ("pixel_x", "pixel_z"),
                 "independent": ("pixel_a_x", "pixel_a_z", "pixel_b_x", "pixel_b_z")}


def problem_spec(problem: Mapping[str, Any], metric: str) -> dict[str, Any]:
    """The SALib problem of a budget with its output named: what ``--problem-spec`` writes."""
    return {"num_vars": int(problem["num_vars"]), "names": list(problem["names"]),
            "groups": list(problem["groups"]), "dists": list(problem["dists"]),
            "bounds": [[float(b) for b in bounds] for bounds in problem["bounds"]],
            "outputs": [metric]}


def write_problem_spec(path: Path, spec: Mapping[str, Any]) -> None:
    from montecarlo.io.files import atomic_write_bytes

    atomic_write_bytes(path, (json.dumps(spec, indent=2) + "\n").encode())


def _source(path: str, name: str, dist: str, bounds: Sequence[float]) -> dict[str, Any]:
    """A study error source from one SALib factor (see the module table)."""
    where = f"{path}: {name}"
    b = [float(x) for x in bounds]
    if not all(math.isfinite(x) for x in b):
        raise InputError(f"{where}: bounds must be finite numbers (got {list(bounds)})")
    need = {"unif": 2, "norm": 2, "triang": 3, "truncnorm": 4}
    if dist not in need:
        raise InputError(f"{where}: dists: {dist!r} has no study error source; use one of "
                         f"{', '.join(need)}")
    if len(b) != need[dist]:
        raise InputError(f"{where}: bounds: {dist} takes {need[dist]} numbers (got {b})")
    if dist == "unif":
        lo, hi = b
        if not hi > lo:
            raise InputError(f"{where}: bounds: need low < high (got {b})")
        return {"dist": "uniform", "bound": (hi - lo) / 2.0, "center": (lo + hi) / 2.0}
    if dist == "norm":
        mean, sigma = b
        if not sigma > 0:
            raise InputError(f"{where}: bounds: sigma must be positive (got {sigma})")
        return {"dist": "normal", "sigma": sigma, "mean": mean}
    if dist == "triang":
        lo, hi, peak = b
        if not (hi > lo and peak == 0.5):
            raise InputError(f"{where}: bounds: only a symmetric triangle [low, high, 0.5] with "
                             f"low < high has a study source (got {b})")
        return {"dist": "triangular", "bound": (hi - lo) / 2.0, "center": (lo + hi) / 2.0}
    lo, hi, mean, sigma = b
    if not (sigma > 0 and hi > lo and math.isclose(mean - lo, hi - mean, rel_tol=1e-12)):
        raise InputError(f"{where}: bounds: truncnorm needs sigma > 0 and bounds symmetric about "
                         f"the mean (got {b})")
    return {"dist": "truncnormal", "sigma": sigma, "bound": (hi - lo) / 2.0, "mean": mean}


def read_problem_spec(path: str | Path) -> dict[str, Any]:
    """A SALib problem file as a dict (names, bounds; optional dists, groups, outputs)."""
    from montecarlo.io.json_file import read_json

    return read_problem_spec_dict(read_json(path, "problem file"), str(path))


def _short(value: Any) -> str:
    text = json.dumps(value, default=str)
    return text if len(text) <= 40 else text[:37] + "..."


def read_problem_spec_dict(spec: Any, path: str = "problem file") -> dict[str, Any]:
    """A parsed SALib problem checked and completed (dists default to unif, groups to the
    names): ``names``, ``groups`` and ``dists`` lists of texts, ``bounds`` a list of lists of
    finite numbers, ``outputs`` a list of texts, ``num_vars`` the number of names."""
    if not isinstance(spec, dict):
        raise InputError(f"{path}: not a SALib problem (a JSON object with names and bounds)")
    for key in ("names", "bounds"):
        if not isinstance(spec.get(key), list) or not spec[key]:
            raise InputError(f"{path}: {key}: required, a non-empty list (got "
                             f"{_short(spec.get(key))})")
    spec = dict(spec)
    n = len(spec["names"])
    spec.setdefault("dists", ["unif"] * n)
    spec.setdefault("groups", list(spec["names"]))
    for key in ("bounds", "dists", "groups"):
        if not isinstance(spec[key], list) or len(spec[key]) != n:
            got = len(spec[key]) if isinstance(spec[key], list) else _short(spec[key])
            raise InputError(f"{path}: {key}: needs one entry per name ({n}), got {got}")
    if "outputs" in spec and not isinstance(spec["outputs"], list):
        raise InputError(f"{path}: outputs: a list of output names (got {_short(spec['outputs'])})")
    for key in ("names", "groups", "dists", "outputs"):
        for i, item in enumerate(spec.get(key, [])):
            if not isinstance(item, str):
                raise InputError(f"{path}: {key}[{i}]: not a text (got {_short(item)})")
    for i, bounds in enumerate(spec["bounds"]):
        if not isinstance(bounds, list) or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) for x in bounds):
            raise InputError(f"{path}: bounds[{i}] ({spec['names'][i]}): a list of numbers (got "
                             f"{_short(bounds)})")
        if not all(math.isfinite(x) for x in bounds):
            raise InputError(f"{path}: bounds[{i}] ({spec['names'][i]}): not finite numbers "
                             f"(got {_short(bounds)})")
    if "num_vars" in spec and (isinstance(spec["num_vars"], bool) or spec["num_vars"] != n):
        raise InputError(f"{path}: num_vars: {_short(spec['num_vars'])} but {n} names")
    return spec


def errors_from_problem_spec(spec: Mapping[str, Any], path: str = "problem file"
                             ) -> tuple[dict[str, Any], str | None]:
    """The study's ``[errors]`` entries a problem sets, and the pixel relation its names say
    (None if it has no pixel factor)."""
    names = list(spec["names"])
    allowed = {*PLACEMENT_SOURCES, *(c for cols in PIXEL_COLUMNS.values() for c in cols)}
    for name, group in zip(names, spec["groups"], strict=True):
        if name not in allowed:
            raise InputError(f"{path}: names: {name!r} is not a budget factor; choose from "
                             f"{', '.join(sorted(allowed))}")
        want = "pixel_px" if name.startswith("pixel_") else name
        if group != want:
            raise InputError(f"{path}: groups: {name!r} belongs to group {want!r} (got "
                             f"{group!r})")
    if len(set(names)) != len(names):
        raise InputError(f"{path}: names: a factor is listed twice")
    errors: dict[str, Any] = {}
    relation = None
    pixel = [i for i, n in enumerate(names) if n.startswith("pixel_")]
    if pixel:
        cols = tuple(names[i] for i in pixel)
        relation = next((r for r, c in PIXEL_COLUMNS.items() if set(cols) == set(c)), None)
        if relation is None:
            raise InputError(f"{path}: names: the pixel factors must be {PIXEL_COLUMNS['common']}"
                             f" (common) or {PIXEL_COLUMNS['independent']} (independent), "
                             f"got {cols}")
        shapes = {(spec["dists"][i], tuple(spec["bounds"][i])) for i in pixel}
        if len(shapes) > 1:
            raise InputError(f"{path}: the pixel factors need one distribution and bounds "
                             f"(got {sorted(shapes)})")
        i = pixel[0]
        errors["pixel_px"] = _source(path, names[i], spec["dists"][i], spec["bounds"][i])
    for i, name in enumerate(names):
        if not name.startswith("pixel_"):
            errors[name] = _source(path, name, spec["dists"][i], spec["bounds"][i])
    return errors, relation


def _centre(source: Any) -> float:
    """The centre of a study error source as given in a study file (a number is fixed)."""
    if not isinstance(source, Mapping):
        return float(source)
    if source.get("dist") == "lognormal":
        return float(source["median"])
    if source.get("dist") == "fixed":
        return float(source.get("value", 0.0))
    return float(source.get("center", source.get("mean", 0.0)))


def apply_problem_spec(base: Mapping[str, Any], spec: Mapping[str, Any],
                       path: str = "problem file") -> tuple[dict[str, Any], str | None]:
    """The ground study ``base`` with its error sources set from a SALib problem, and the pixel
    relation the problem's names say (None without pixel factors). A source the problem does
    not list is fixed at its centre in ``base``."""
    import copy

    errors, relation = errors_from_problem_spec(spec, path)
    raw = copy.deepcopy(dict(base))
    given = raw.setdefault("errors", {})
    for name in (*PLACEMENT_SOURCES, "pixel_px"):
        given[name] = errors[name] if name in errors else _centre(given.get(name, 0.0))
    return raw, relation


UNITS = {**SOURCE_UNITS, **{c: "px" for cols in PIXEL_COLUMNS.values() for c in cols}}
"""Unit of each factor's bounds."""
