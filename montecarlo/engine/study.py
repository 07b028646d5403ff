"""Study files: TOML definitions validated on load and expanded into grid points.

Layout of a study file::

    [study]                      # what to run
    name = "range_sizing"        # results go to results/<name>/
    system = "ground"            # which simulated system (montecarlo.systems)
    trials = 10000               # per grid point
    seed = 1
    # optional: description, block_size, common_random_numbers, per_trial, confidence

    [spec]                       # optional requirement drawn on plots and checked in reports
    metric = "rotation_angle"; variant = "normalised"; statistic = "p95"; limit = 3.0
    # statistic: p50/p90/p95/p99, mean, std, rms, max, or cvar95 (mean of the worst 5 %; any cvarNN)

    ... the system's own sections (e.g. [sensor], [geometry], [errors] for "ground") ...

    [[sweep]]                    # optional, repeatable: each group is "product" (default),
    mode = "zip"                 # "zip" or "one_at_a_time"; groups combine as a product
    "geometry.L_m" = [50, 100]
    "geometry.H_m" = [1, 2]

A "one_at_a_time" group varies each of its keys alone while the others keep the value the file
gives them (the base point, which is also run).

Every mistake raises :class:`InputError` with one line naming the file, the key and the value.
"""

from __future__ import annotations

import copy
import difflib
import hashlib
import itertools
import json
import math
import os
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from pydantic import Field, ValidationError, field_validator

from montecarlo.engine.schema import Strict
from montecarlo.engine.system import Metric, System
from montecarlo.errors import InputError

MAX_TRIALS = 10**13
"""Most trials per grid point (years of computing at today's rates)."""

MAX_POINTS = 10_000
"""Default limit on the grid points of a study (``--max-points`` raises it)."""

BYTES_PER_POINT = 150_000
"""Memory a grid point takes while a study is expanded and run [bytes]: about 11 kB for its
validated configuration and 66 kB for its results (summary rows, histograms), peaking near
134 kB while the summary is built (measured with ``tracemalloc`` on ground studies of 2000 and
300 points), rounded up."""


class StudyHeader(Strict):
    """The ``[study]`` table."""

    name: str = Field(pattern=r"^[A-Za-z0-9_.-]+$", max_length=80)
    description: str = ""
    system: str
    trials: int = Field(gt=0, le=MAX_TRIALS)
    seed: int = Field(ge=0)
    block_size: int | None = Field(default=None, gt=0, le=1 << 24)
    common_random_numbers: bool = True
    per_trial: bool = False
    confidence: float = Field(default=0.95, gt=0.0, lt=1.0)

    @field_validator("name")
    @classmethod
    def _not_a_directory_name(cls, name: str) -> str:
        """'.' and '..' (any name of dots only) are directories: results/<name> would be the
        results root or its parent."""
        if not name.strip("."):
            raise ValueError("must not be only dots ('.' and '..' name directories, and "
                             "results go to results/<name>/)")
        return name


class Spec(Strict):
    """The optional ``[spec]`` table: a requirement in the metric's display unit."""

    metric: str
    variant: str | None = None
    statistic: str = Field(default="p95",
                           pattern=r"^(mean|std|rms|p50|p90|p95|p99|max|cvar[1-9][0-9]?)$")
    """A percentile, mean, std, rms (sqrt of the mean square), max, or ``cvarNN``: the mean of
    the worst (100 - NN) %. Of a signed (per-axis) metric, the percentiles, ``cvarNN`` and max
    are of its magnitude and the mean is judged by its magnitude, the bias ``abs(mean)``."""
    limit: float = Field(gt=0)

    def statistic_label(self, signed: bool) -> str:
        """The statistic as judged: ``abs(mean)`` for the mean of a signed metric."""
        return "abs(mean)" if signed and self.statistic == "mean" else self.statistic


@dataclass(frozen=True)
class GridPoint:
    """One point of a study's sweep: its overrides and its validated, prepared config."""

    index: int
    overrides: dict[str, Any]
    values: dict[str, Any]
    """The value of every sweep key at this point (overridden or the file's base value)."""
    config: Any
    prepared: Any
    trials: int
    sampled: bool = True
    """False if the trials enumerate every case (worst-case corners) instead of sampling."""


@dataclass(frozen=True)
class Study:
    """A validated study: header, system, spec and the expanded grid."""

    path: Path
    header: StudyHeader
    spec: Spec | None
    system: System
    sweep_groups: tuple[tuple[str, tuple[str, ...]], ...]
    """(mode, keys) of each sweep group, in file order."""
    points: tuple[GridPoint, ...]
    metrics: tuple[tuple[str, Metric], ...]
    source: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)
    """The study as given (the parsed TOML with the trials and seed overrides applied): what
    :func:`study_from_dict` needs to build it again, e.g. to re-render a saved result."""

    @property
    def sweep_keys(self) -> tuple[str, ...]:
        return tuple(k for _, keys in self.sweep_groups for k in keys)

    @property
    def block_size(self) -> int:
        return self.header.block_size or self.system.default_block_size

    def with_trials(self, trials: dict[int, int]) -> Study:
        """The same study with the trials of some grid points changed (index -> trials)."""
        points = tuple(replace(gp, trials=trials.get(gp.index, gp.trials)) for gp in self.points)
        return replace(self, points=points)

    def resolved(self) -> dict[str, Any]:
        """Everything that determines the results, as plain JSON-able data."""
        return {
            "study": self.header.model_dump(mode="json"),
            "spec": None if self.spec is None else self.spec.model_dump(mode="json"),
            "block_size": self.block_size,
            "points": [{"values": p.values, "trials": p.trials,
                        "config": p.config.model_dump(mode="json")} for p in self.points],
        }

    def hash(self) -> str:
        """SHA-256 of :meth:`resolved` (canonical JSON)."""
        text = json.dumps(self.resolved(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()

    def metric(self, name: str) -> Metric:
        return next(m for _, m in self.metrics if m.name == name)


def _describe(overrides: dict[str, Any]) -> str:
    return ", ".join(f"{k} = {v!r}" for k, v in overrides.items())


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _validation_message(path: Path, err: ValidationError, prefix: tuple[str, ...],
                        where: str = "") -> str:
    """One line for the most telling error: an unknown key (a typo) before anything else."""
    errors = sorted(err.errors(), key=lambda e: e["type"] != "extra_forbidden")
    e = errors[0]
    loc = ".".join(str(x) for x in (*prefix, *e["loc"]))
    messages = {"extra_forbidden": "unknown key", "missing": "required key is missing"}
    msg = messages.get(e["type"], e["msg"])
    if e["type"] == "extra_forbidden":
        missing = [str(m["loc"][-1]) for m in errors
                   if m["type"] == "missing" and m["loc"][:-1] == e["loc"][:-1]]
        close = difflib.get_close_matches(str(e["loc"][-1]), missing, n=1)
        if close:
            msg += f" (did you mean '{close[0]}'?)"
    value = "" if e["type"] == "missing" else f" (got {_short(e.get('input'))})"
    return f"{path}: {loc}: {msg}{value}{where}"


def _reject_non_finite(path: Path, node: Any, where: str = "") -> None:
    """NaN or infinity anywhere in the file is an error (even a base value a sweep replaces)."""
    if isinstance(node, float) and not math.isfinite(node):
        raise InputError(f"{path}: {where or '(file)'}: not a finite number (got {node!r})")
    if isinstance(node, dict):
        for key, value in node.items():
            _reject_non_finite(path, value, f"{where}.{key}" if where else str(key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            _reject_non_finite(path, value, f"{where}[{i}]")


def _parse_sweep(path: Path, raw: Any) -> list[tuple[str, dict[str, list[Any]]]]:
    groups = raw if isinstance(raw, list) else [raw]
    parsed = []
    for i, group in enumerate(groups):
        where = f"sweep[{i}]" if isinstance(raw, list) else "sweep"
        if not isinstance(group, dict):
            raise InputError(f"{path}: {where}: must be a table of key = [values]")
        group = dict(group)
        mode = group.pop("mode", "product")
        if mode not in SWEEP_MODES:
            raise InputError(f"{path}: {where}.mode: must be one of {', '.join(SWEEP_MODES)} "
                             f"(got {mode!r})")
        if not group:
            raise InputError(f"{path}: {where}: no keys to sweep")
        for key, values in group.items():
            if not isinstance(values, list):
                raise InputError(f"{path}: {where}.{key}: must be a list (got {_short(values)})")
            if not values:
                raise InputError(f"{path}: {where}.{key}: empty list, nothing to sweep")
        lengths = {len(v) for v in group.values()}
        if mode == "zip" and len(lengths) > 1:
            sizes = ", ".join(f"{k}: {len(v)}" for k, v in group.items())
            raise InputError(f"{path}: {where}: zipped lists differ in length ({sizes})")
        parsed.append((mode, group))
    return parsed


def _expand(groups: list[tuple[str, dict[str, list[Any]]]]) -> list[dict[str, Any]]:
    per_group: list[list[dict[str, Any]]] = []
    for mode, group in groups:
        keys = list(group)
        if mode == "one_at_a_time":
            per_group.append([{}] + [{k: v} for k, values in group.items() for v in values])
            continue
        combos = zip(*group.values(), strict=True) if mode == "zip" \
            else itertools.product(*group.values())
        per_group.append([dict(zip(keys, c, strict=True)) for c in combos])
    return [{k: v for part in combo for k, v in part.items()}
            for combo in itertools.product(*per_group)] if per_group else [{}]


SWEEP_MODES = ("product", "zip", "one_at_a_time")


def grid_size(groups: list[tuple[str, dict[str, list[Any]]]]) -> int:
    """Grid points the sweep groups expand to, counted without expanding them: a product
    group gives the product of its list lengths, a zip group their common length, a
    one_at_a_time group one point per value plus the base point; groups multiply."""
    n = 1
    for mode, group in groups:
        lengths = [len(v) for v in group.values()]
        n *= 1 + sum(lengths) if mode == "one_at_a_time" else \
            lengths[0] if mode == "zip" else math.prod(lengths)
    return n


def _physical_memory() -> int | None:
    """The machine's memory [bytes], or None where it cannot be read."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return None


def check_grid_size(path: Path, groups: list[tuple[str, dict[str, list[Any]]]],
                    max_points: int) -> int:
    """The grid size, or one line (before anything is expanded) if it exceeds ``max_points``
    or its memory estimate (:data:`BYTES_PER_POINT` each) exceeds the machine's memory."""
    n = grid_size(groups)
    need = n * BYTES_PER_POINT
    memory = _physical_memory()
    if n > max_points:
        raise InputError(f"{path}: sweep: {n:,} grid points (about {_bytes_text(need)} of "
                         f"memory) exceed the limit of {max_points:,}; sweep fewer values or "
                         "raise the limit with --max-points")
    if memory is not None and need > memory:
        raise InputError(f"{path}: sweep: {n:,} grid points need about {_bytes_text(need)} of "
                         f"memory, more than this machine's {_bytes_text(memory)}; sweep fewer "
                         "values")
    return n


def _bytes_text(n: float) -> str:
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n:.0f} B"


def _lookup(path: Path, raw: dict[str, Any], key: str) -> Any:
    """The value at a dotted key of a study dict (the base of a one_at_a_time sweep)."""
    node: Any = raw
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            raise InputError(f"{path}: sweep key '{key}': a one_at_a_time sweep needs its base "
                             f"value in the file")
        node = node[part]
    return node


def _apply(path: Path, raw: dict[str, Any], key: str, value: Any) -> None:
    parts = key.split(".")
    node = raw
    for depth, part in enumerate(parts[:-1]):
        child = node.setdefault(part, {})
        if not isinstance(child, dict):
            raise InputError(f"{path}: sweep key '{key}': '{'.'.join(parts[:depth + 1])}' "
                             f"is not a table")
        node = child
    node[parts[-1]] = value


Systems = Mapping[str, Callable[[], System]]
"""System name -> factory of the system (see :data:`montecarlo.systems.REGISTRY`)."""


def _check_swept_base_values(path: Path, system: System, raw: dict[str, Any],
                             first: dict[str, Any], sweep_keys: tuple[str, ...]) -> None:
    """Refuse an invalid base value of a swept key (e.g. a negative ``geometry.L_m`` that the
    sweep replaces), as a non-finite one is refused: the file's values are checked whether or
    not a sweep replaces them.

    The base values of the swept keys are validated together with the first grid point's
    values of the other keys; only an error at a swept key is reported (the grid points
    themselves are checked afterwards).
    """
    given = []
    for key in sweep_keys:
        try:
            _lookup(path, raw, key)
        except InputError:
            continue
        given.append(key)
    if not given:
        return
    probe = copy.deepcopy(raw)
    for key, value in first.items():
        if key not in given:
            _apply(path, probe, key, value)
    try:
        system.config_model.model_validate(probe)
    except ValidationError as err:
        for e in err.errors():
            loc = ".".join(str(x) for x in e["loc"])
            if any(loc == k or loc.startswith(k + ".") for k in given):
                value = _short(e.get("input"))
                raise InputError(f"{path}: {loc}: {e['msg']} (got {value}) [the base value, "
                                 "which the sweep replaces: give a valid one or remove it]"
                                 ) from None


def read_study_file(path: str | Path, what: str = "study file") -> dict[str, Any]:
    """The parsed TOML of a study file (or of another TOML file: ``what`` names its kind in
    the messages); every problem is one line naming the file."""
    path = Path(path)
    try:
        data = path.read_bytes()
        if data.startswith(b"\xef\xbb\xbf"):
            raise InputError(f"{path}: starts with a byte-order mark (BOM, bytes EF BB BF), "
                             "which TOML does not allow; save it as UTF-8 without BOM")
        return tomllib.loads(data.decode("utf-8"))
    except FileNotFoundError:
        raise InputError(f"{path}: no such {what}") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a directory, not a {what}") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not valid TOML: {exc}") from None


def merge_errors_file(raw: dict[str, Any], path: str | Path) -> dict[str, Any]:
    """The study ``raw`` with its ``[errors]`` table updated, key by key, from the TOML file at
    ``path`` (e.g. the pixel error a camera calibration left, ``diagnose camera
    --emit-errors``). The file may hold an ``[errors]`` table and nothing else.

    Raises
    ------
    InputError
        The file is missing or not TOML, or holds anything but an ``[errors]`` table.
    """
    extra = read_study_file(path, "errors file")
    if not isinstance(extra.get("errors"), dict) or set(extra) != {"errors"}:
        other = sorted(set(extra) - {"errors"})
        raise InputError(f"{path}: an errors file holds one [errors] table"
                         + (f" and nothing else (got: {', '.join(other)})" if other else
                            " (none found)"))
    merged = copy.deepcopy(raw)
    table = merged.setdefault("errors", {})
    if not isinstance(table, dict):
        raise InputError(f"{path}: errors: the study's errors is not a table")
    table.update(copy.deepcopy(extra["errors"]))
    return merged


def study_with_errors(raw: dict[str, Any], path: str | Path, errors: str | Path,
                      systems: Systems, **options: Any) -> tuple[dict[str, Any], Study]:
    """The study ``raw`` (read from ``path``) with its ``[errors]`` table updated from the
    errors file ``errors`` (:func:`merge_errors_file`): the merged dict and its study.

    A mistake is named in the file that makes it: the study file's own, else the errors
    file's (an unknown or invalid error source it brings). ``options`` go to
    :func:`study_from_dict`.
    """
    merged = merge_errors_file(raw, errors)
    try:
        return merged, study_from_dict(merged, systems, path, **options)
    except InputError:
        study_from_dict(raw, systems, path, **options)  # the study's own mistake, named in it
        study_from_dict(merged, systems, errors, **options)  # else the errors file's
        raise


def load_study(path: str | Path, systems: Systems, *, trials: int | None = None,
               seed: int | None = None, max_points: int = MAX_POINTS) -> Study:
    """Read, validate and expand a study file; ``trials``/``seed`` override the file's."""
    return study_from_dict(read_study_file(path), systems, path, trials=trials, seed=seed,
                           max_points=max_points)


def study_from_dict(raw: dict[str, Any], systems: Systems, path: str | Path = "<study>", *,
                    trials: int | None = None, seed: int | None = None,
                    max_points: int = MAX_POINTS) -> Study:
    """Validate and expand a study given as a dict (the parsed TOML); ``path`` labels errors.

    ``systems`` maps the names ``[study] system`` may take to their factories. A sweep of more
    than ``max_points`` grid points is refused before it is expanded (:func:`check_grid_size`).
    A base value that a sweep replaces is checked as strictly as the values that replace it.
    """
    path = Path(path)
    _reject_non_finite(path, raw)
    raw = copy.deepcopy(raw)
    source = copy.deepcopy(raw)
    header_raw = raw.pop("study", None)
    if not isinstance(header_raw, dict):
        raise InputError(f"{path}: study: required table [study] is missing")
    header_raw = dict(header_raw)
    header_raw.setdefault("name", path.stem.strip("<>") or "study")
    if trials is not None:
        header_raw["trials"] = trials
    if seed is not None:
        header_raw["seed"] = seed
    source["study"] = dict(header_raw)
    try:
        header = StudyHeader.model_validate(header_raw)
    except ValidationError as err:
        raise InputError(_validation_message(path, err, ("study",))) from None
    if header.system not in systems:
        raise InputError(f"{path}: study.system: unknown system; choose from "
                         f"{', '.join(systems)} (got {header.system!r})")
    system = systems[header.system]()

    spec = None
    if "spec" in raw:
        try:
            spec = Spec.model_validate(raw.pop("spec"))
        except ValidationError as err:
            raise InputError(_validation_message(path, err, ("spec",))) from None

    groups = _parse_sweep(path, raw.pop("sweep")) if "sweep" in raw else []
    sweep_keys = tuple(k for _, g in groups for k in g)
    repeated = [k for i, k in enumerate(sweep_keys) if k in sweep_keys[:i]]
    if repeated:
        raise InputError(f"{path}: sweep: key {repeated[0]!r} appears in two sweep groups")
    check_grid_size(path, groups, max_points)
    expanded = _expand(groups)
    _check_swept_base_values(path, system, raw, expanded[0],
                             tuple(k for mode, g in groups if mode != "one_at_a_time"
                                   for k in g))

    points = []
    seen: dict[str, int] = {}
    for i, overrides in enumerate(expanded):
        point_raw = copy.deepcopy(raw)
        for key, value in overrides.items():
            _apply(path, point_raw, key, value)
        where = f" [sweep point {i}: {_describe(overrides)}]" if overrides else ""
        try:
            config = system.config_model.model_validate(point_raw)
        except ValidationError as err:
            raise InputError(_validation_message(path, err, (), where)) from None
        resolved = json.dumps(config.model_dump(mode="json"), sort_keys=True)
        if resolved in seen:
            first = seen[resolved]
            raise InputError(f"{path}: sweep: points {first} and {i} are the same study "
                             f"({_describe(overrides) or 'the base point'}); remove the "
                             "repeated value")
        seen[resolved] = i
        prepared = system.prepare(config)
        values = {k: overrides[k] if k in overrides else _lookup(path, point_raw, k)
                  for k in sweep_keys}
        points.append(GridPoint(i, overrides, values, config, prepared,
                                system.trials_per_point(prepared, header.trials),
                                system.is_sampled(prepared)))

    metrics = tuple(dict.fromkeys(m for p in points for m in system.metrics(p.prepared)))
    if spec is not None:
        names = {m.name for _, m in metrics}
        variants = {v for v, _ in metrics}
        if spec.metric not in names:
            raise InputError(f"{path}: spec.metric: unknown metric (got {spec.metric!r}); "
                             f"choose from {', '.join(sorted(names))}")
        if spec.variant is not None and spec.variant not in variants:
            raise InputError(f"{path}: spec.variant: not computed (got {spec.variant!r}); "
                             f"choose from {', '.join(sorted(variants))}")
    sweep_groups = tuple((mode, tuple(g)) for mode, g in groups)
    return Study(path, header, spec, system, sweep_groups, tuple(points), metrics, source)

