"""Property-based fuzzing of every input reader and of ``compare``'s row matching.

Random corruptions of valid files (truncation, bytes that are not UTF-8, a token put anywhere:
NaN, inf, a huge number, a text, null, a list; a line repeated, dropped or swapped; in JSON a
value swapped for another type or a key removed) must be either accepted or refused with an
:class:`~montecarlo.errors.InputError` of one line, never another exception, and must leave the
input file as it was. ``compare``'s matching of two random grids pairs each row at most once,
only rows equal on every sweep key of either run (a key one run does not sweep at its fixed
value), or refuses in one line.

The default run tries a few dozen cases per reader (seconds in total); ``-m slow`` runs the
long version (:data:`LONG` cases each).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from montecarlo.errors import InputError

DATA = Path(__file__).parent / "data"
CSV = DATA / "bad_inputs" / "csv"
FIT = DATA / "trusted" / "collimation_fit.json"
NEW_SET = DATA / "trusted" / "collimation_new.csv"
STUDY = DATA / "bad_inputs" / "studies" / "valid_ground.toml"
ERRORS = b'[errors]\npixel_px = { dist = "normal", sigma = 0.2 }\ndx_m = 0.01\n'
PROBLEM = json.dumps({"num_vars": 3, "names": ["dx_m", "pixel_x", "pixel_z"],
                      "groups": ["dx_m", "pixel_px", "pixel_px"],
                      "dists": ["unif", "norm", "norm"],
                      "bounds": [[-0.1, 0.1], [0.0, 0.3], [0.0, 0.3]],
                      "outputs": ["rotation_angle"]}, indent=1).encode()

SHORT, LONG = 25, 400
TOKENS = [b"NaN", b"nan", b"inf", b"-Infinity", b"1e400", b"1e300", b"-1e308", b'"x"', b"null",
          b"[]", b"{}", b"true", b"\xff\xfe", b"\x00", b",", b'"', b"\n", b"=", b"0", b"-1"]
"""What a corruption may put anywhere in a file."""
VALUES = [math.nan, math.inf, -math.inf, 1e300, -1e300, 0, -1, "text", None, [], {}, True,
          [1, 2], {"a": 1}]
"""What a value of a JSON file may be swapped for."""


@st.composite
def corrupted(draw, data: bytes, structured: bool = False) -> bytes:
    """``data`` with one random corruption (``structured``: also JSON value swaps)."""
    kinds = ["truncate", "token", "bytes", "line"] + (["json"] * 3 if structured else [])
    kind = draw(st.sampled_from(kinds))
    if kind == "truncate":
        return data[:draw(st.integers(0, max(len(data) - 1, 0)))]
    if kind == "token":
        i = draw(st.integers(0, len(data)))
        cut = draw(st.integers(0, 12))
        return data[:i] + draw(st.sampled_from(TOKENS)) + data[i + cut:]
    if kind == "bytes":
        i = draw(st.integers(0, max(len(data) - 1, 0)))
        return data[:i] + draw(st.binary(min_size=1, max_size=4)) + data[i + 1:]
    if kind == "line":
        lines = data.split(b"\n")
        i, j = draw(st.integers(0, len(lines) - 1)), draw(st.integers(0, len(lines) - 1))
        how = draw(st.sampled_from(["repeat", "drop", "swap"]))
        if how == "repeat":
            lines.insert(j, lines[i])
        elif how == "drop":
            del lines[i]
        else:
            lines[i], lines[j] = lines[j], lines[i]
        return b"\n".join(lines)
    tree = json.loads(data)
    paths = list(_paths(tree))
    path = draw(st.sampled_from(paths))
    parent = tree
    for key in path[:-1]:
        parent = parent[key]
    if draw(st.booleans()) and isinstance(parent, dict):
        del parent[path[-1]]
    else:
        parent[path[-1]] = draw(st.sampled_from(VALUES))
    return json.dumps(tree).encode()


def _paths(node, prefix=()):
    """Every (key or index) path below a parsed JSON value."""
    items = node.items() if isinstance(node, dict) else enumerate(node) \
        if isinstance(node, list) else ()
    for key, value in items:
        yield (*prefix, key)
        yield from _paths(value, (*prefix, key))


def accepted_or_refused(call: Callable[[], object], *files: Path) -> str:
    """Run ``call``; it may return or raise a one-line InputError, and must not change
    ``files``. Returns 'accepted' or 'refused'."""
    before = [f.read_bytes() for f in files]
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            call()
        outcome = "accepted"
    except InputError as exc:
        message = str(exc)
        assert message and "\n" not in message, message
        outcome = "refused"
    assert [f.read_bytes() for f in files] == before
    return outcome


def _case(name: str, data: bytes) -> tuple[Path, Path]:
    tmp = Path(tempfile.mkdtemp(prefix="fuzz-"))
    path = tmp / name
    path.write_bytes(data)
    return tmp, path


def fuzz(examples: int):
    return settings(max_examples=examples, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


# --- the readers --------------------------------------------------------------------------------


def _read_study(path: Path) -> None:
    from montecarlo.systems import load_study

    load_study(path)


def _read_errors(path: Path) -> None:
    from montecarlo.engine.study import read_study_file
    from montecarlo.systems import study_with_errors

    study_with_errors(read_study_file(STUDY), STUDY, path)


def _read_problem(path: Path) -> None:
    from montecarlo.design.problem_spec import errors_from_problem_spec, read_problem_spec

    errors_from_problem_spec(read_problem_spec(path), str(path))


def _read_ground(path: Path) -> None:
    from montecarlo.geometry.camera import Camera
    from montecarlo.io.ground_csv import read_ground_csv

    read_ground_csv(path, Camera.from_degrees(90.0, 90.0, 512, 512))


def _read_mirrors(path: Path) -> None:
    from montecarlo.io.collimation_csv import read_mirror_csv

    read_mirror_csv(path)


def _read_stabilization(path: Path) -> None:
    from montecarlo.io.stabilization_csv import read_csv

    read_csv(path)


def _read_camera_model(path: Path) -> None:
    from montecarlo.io.camera_csv import read_camera_csv

    read_camera_csv(path, CSV / "valid_camera_views.csv")


def _read_camera_views(path: Path) -> None:
    from montecarlo.io.camera_csv import read_camera_csv

    read_camera_csv(CSV / "valid_camera_model.csv", path)


def _verify_fit(path: Path) -> None:
    from montecarlo.cli import main

    code = main(["collimation", "verify", str(path), str(NEW_SET)])
    if code == 2:  # main printed the one line; the reader's refusal
        raise InputError("refused by the command line")
    assert code == 0


READERS = {
    "study-toml": (_read_study, STUDY.read_bytes(), False),
    "errors-toml": (_read_errors, ERRORS, False),
    "problem-json": (_read_problem, PROBLEM, True),
    "fit-json": (_verify_fit, FIT.read_bytes(), True),
    "ground-csv": (_read_ground, (CSV / "valid_ground.csv").read_bytes(), False),
    "collimation-csv": (_read_mirrors, (CSV / "valid_collimation.csv").read_bytes(), False),
    "stabilization-csv": (_read_stabilization, (CSV / "valid_stabilization.csv").read_bytes(),
                          False),
    "camera-model-csv": (_read_camera_model, (CSV / "valid_camera_model.csv").read_bytes(),
                         False),
    "camera-views-csv": (_read_camera_views, (CSV / "valid_camera_views.csv").read_bytes(),
                         False),
}


def _fuzz_reader(kind: str, examples: int) -> None:
    read, valid, structured = READERS[kind]
    assert accepted_or_refused(lambda: read(_case("valid", valid)[1])) == "accepted"

    @fuzz(examples)
    @given(corrupted(valid, structured))
    def check(data: bytes) -> None:
        tmp, path = _case(f"input{Path(kind).suffix}", data)
        try:
            accepted_or_refused(lambda: read(path), path)
        finally:
            shutil.rmtree(tmp)

    check()


@pytest.mark.parametrize("kind", sorted(READERS))
def test_a_corrupted_input_is_accepted_or_refused_in_one_line(kind):
    _fuzz_reader(kind, SHORT if kind != "fit-json" else SHORT // 2)


@pytest.mark.slow
@pytest.mark.parametrize("kind", sorted(READERS))
def test_a_corrupted_input_is_accepted_or_refused_in_one_line_long(kind):
    _fuzz_reader(kind, LONG)


# --- a result directory read back ------------------------------------------------------------


def _result_dir(root: Path) -> Path:
    """A result directory as `montecarlo run` leaves it, for `compare` (summary and
    provenance with its list of files)."""
    from montecarlo.io.files import record_written_files

    d = root / "result"
    d.mkdir()
    summary = pd.DataFrame({"point": [0, 0, 1, 1], "geometry.L_m": [50.0, 50.0, 100.0, 100.0],
                            "variant": "raw", "metric": ["a", "b", "a", "b"], "unit": "mrad",
                            "sampling": "random", "count": 400, "mean": [1.0, 2.0, 3.0, 4.0],
                            "std": 0.5, "p95": [2.0, 3.0, 4.0, 5.0], "p95_lo": 1.5,
                            "p95_hi": 5.5})
    summary.to_parquet(d / "summary.parquet", index=False)
    points = [{"values": {"geometry.L_m": v}, "trials": 400,
               "config": {"geometry": {"L_m": v, "H_m": 2.0}}} for v in (50.0, 100.0)]
    prov = {"kind": "run", "study": "fuzz", "study_hash": "0" * 64,
            "resolved_study": {"study": {"confidence": 0.95}, "spec": None, "points": points}}
    (d / "provenance.json").write_text(json.dumps(prov, indent=1))
    record_written_files(d)
    return d


def _fuzz_result(examples: int) -> None:
    from montecarlo.io.files import record_sha256
    from montecarlo.output.compare import compare_runs, load_run

    root = Path(tempfile.mkdtemp(prefix="fuzz-result-"))
    try:
        valid = _result_dir(root)
        prov, summary = (valid / "provenance.json").read_bytes(), \
            (valid / "summary.parquet").read_bytes()
        assert accepted_or_refused(lambda: compare_runs(load_run(valid), load_run(valid))) \
            == "accepted"

        @fuzz(examples)
        @given(st.sampled_from(["provenance", "summary"]), st.data(), st.booleans())
        def check(which: str, data: st.DataObject, reseal: bool) -> None:
            tmp = Path(tempfile.mkdtemp(prefix="fuzz-run-"))
            d = tmp / "run"
            shutil.copytree(valid, d)
            try:
                if which == "provenance":
                    text = data.draw(corrupted(prov, True))
                    if reseal:  # as if written so: the checks of its structure, not its checksum
                        with contextlib.suppress(ValueError, TypeError, AttributeError):
                            record = json.loads(text)
                            record["record_sha256"] = record_sha256(record)
                            text = json.dumps(record).encode()
                    (d / "provenance.json").write_bytes(text)
                else:
                    (d / "summary.parquet").write_bytes(data.draw(corrupted(summary)))
                files = [p for p in d.rglob("*") if p.is_file()]
                accepted_or_refused(lambda: compare_runs(load_run(valid), load_run(d),
                                                         allow_different=True), *files)
            finally:
                shutil.rmtree(tmp)

        check()
    finally:
        shutil.rmtree(root)


def test_a_corrupted_result_directory_is_accepted_or_refused_in_one_line():
    _fuzz_result(SHORT)


@pytest.mark.slow
def test_a_corrupted_result_directory_is_accepted_or_refused_in_one_line_long():
    _fuzz_result(LONG)


# --- compare: random grids ------------------------------------------------------------------


@st.composite
def grids(draw):
    """A synthetic run: a sweep over some of L, H (values from small sets, maybe repeated),
    the rest fixed; one or two variants."""
    from montecarlo.output.compare import Run

    keys = draw(st.lists(st.sampled_from(["geometry.L_m", "geometry.H_m"]), unique=True,
                         max_size=2))
    fixed = {"geometry.L_m": draw(st.sampled_from([50.0, 100.0])),
             "geometry.H_m": draw(st.sampled_from([1.0, 2.0]))}
    n = draw(st.integers(1, 4))
    values = [{k: draw(st.sampled_from([50.0, 100.0, 1.0, 2.0])) for k in keys}
              for _ in range(n)]
    variants = draw(st.sampled_from([["raw"], ["raw", "normalised"]]))
    rows = [{"point": p, **v, "variant": var, "metric": "m", "unit": "mrad",
             "sampling": "random", "count": 100, "std": 1.0, "mean": float(p),
             "p95": float(p), "p95_lo": p - 0.5, "p95_hi": p + 0.5}
            for p, v in enumerate(values) for var in variants]
    points = [{"config": {"geometry": {"L_m": v.get("geometry.L_m", fixed["geometry.L_m"]),
                                       "H_m": v.get("geometry.H_m", fixed["geometry.H_m"])}}}
              for v in values]
    prov = {"kind": "run", "study": "grid", "study_hash": draw(st.sampled_from("ab")),
            "resolved_study": {"study": {"confidence": 0.95}, "points": points}}
    columns = ["point", *keys, "variant", "metric", "unit", "sampling", "count", "std", "mean",
               "p95", "p95_lo", "p95_hi"]
    return Run(Path(f"run-{id(rows)}"), pd.DataFrame(rows, columns=columns), prov)


def _fuzz_compare(examples: int) -> None:
    from montecarlo.output.compare import compare_runs, match_rows

    @fuzz(examples)
    @given(grids(), grids())
    def check(a, b) -> None:
        try:
            pairs, only_a, only_b, keys = match_rows(a, b)
            table = compare_runs(a, b, "p95", allow_different=True)
        except InputError as exc:
            assert "\n" not in str(exc)
            return
        assert pairs["row_a"].is_unique and pairs["row_b"].is_unique
        assert len(pairs) + len(only_a) == len(a.summary)
        assert len(pairs) + len(only_b) == len(b.summary)
        config = {id(r): r.provenance["resolved_study"]["points"] for r in (a, b)}
        for ra, rb in zip(pairs["row_a"], pairs["row_b"], strict=True):
            pa, pb = (int(r.summary["point"].iloc[i]) for r, i in ((a, ra), (b, rb)))
            for key in keys:  # equal on every sweep key of either run
                name = key.split(".")[1]
                assert config[id(a)][pa]["config"]["geometry"][name] == \
                    config[id(b)][pb]["config"]["geometry"][name]
            assert a.summary["variant"].iloc[ra] == b.summary["variant"].iloc[rb]
        assert len(table) == len(pairs)
        assert np.array_equal(table["a"].to_numpy(), a.summary["p95"].to_numpy()[
            pairs["row_a"].to_numpy()])

    check()


def test_compare_pairs_each_row_of_random_grids_at_most_once():
    _fuzz_compare(SHORT)


@pytest.mark.slow
def test_compare_pairs_each_row_of_random_grids_at_most_once_long():
    _fuzz_compare(LONG * 4)
