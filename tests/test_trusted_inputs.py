"""Inputs users hand the commands that read results and saved files back: each is refused in one
line (exit 2) naming the file, the field and the value, leaving every file as it was, or
handled correctly (``compare`` pairs each row with at most one row).

Result directories come from two small runs (two and four grid points, 200 trials) made once in
this process; the other inputs are ``tests/data/trusted/`` (see its README) and the valid files
of ``tests/data/bad_inputs/``.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import stat
from pathlib import Path

import pandas as pd
import pytest

from montecarlo.cli import main

DATA = Path(__file__).parent / "data"
FIT = DATA / "trusted" / "collimation_fit.json"
NEW_SET = DATA / "trusted" / "collimation_new.csv"
CAM_MODEL = DATA / "bad_inputs" / "csv" / "valid_camera_model.csv"
CAM_VIEWS = DATA / "bad_inputs" / "csv" / "valid_camera_views.csv"

STUDY = """
[study]
name = "{name}"
system = "ground"
trials = 200
seed = 3

[sensor]
fov_deg = [90.0, 90.0]
pixels = [512, 512]

[mounting]
psi_deg = 30.0
theta_deg = 20.0
gamma_deg = 10.0

[geometry]
L_m = 100.0
H_m = 2.0

[errors]
pixel_px = {{ dist = "normal", sigma = 0.3 }}
pixel_relation = "common"

[solver]
variants = ["normalised"]

[[sweep]]
"geometry.L_m" = [50.0, 100.0]
{extra}
"""


def snapshot(root: Path) -> dict[str, tuple]:
    """Every entry below ``root``: kind, content hash, mode and modification time."""
    out = {}
    for p in sorted(root.rglob("*")):
        st = p.lstat()
        data = None if p.is_dir() else hashlib.sha256(p.read_bytes()).hexdigest()
        out[str(p.relative_to(root))] = (stat.S_IFMT(st.st_mode), data, st.st_mode,
                                         st.st_mtime_ns)
    return out


def refused(capsys, argv: list[str], *expect: str) -> str:
    """Run ``argv`` in this process: exit 2, one line on stderr holding ``expect``."""
    capsys.readouterr()
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err
    for text in expect:
        assert text in lines[0], (text, lines[0])
    return lines[0]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """``a``: L in {50, 100} at H = 2; ``b``: L in {50, 100} x H in {1, 2} (one more key)."""
    tmp = tmp_path_factory.mktemp("trusted")
    out = {}
    for tag, extra in (("a", ""), ("b", '"geometry.H_m" = [1.0, 2.0]')):
        study = tmp / f"{tag}.toml"
        study.write_text(STUDY.format(name=f"trusted-{tag}", extra=extra))
        assert main(["-q", "run", str(study), "--out", str(tmp / tag), "--n-jobs", "1"]) == 0
        out[tag] = tmp / tag
    return out


# --- compare: each row paired at most once, on every sweep key of both runs -------------------


def test_compare_allow_different_pairs_each_row_once_on_every_key(runs, capsys):
    """b sweeps H too; a is at H = 2: a's rows pair with b's H = 2 rows only, and b's H = 1
    rows are listed as b's own (the old match on L alone paired each a row twice)."""
    from montecarlo.output.compare import compare_runs, load_run, match_rows

    a, b = load_run(runs["a"]), load_run(runs["b"])
    table = compare_runs(a, b, "p95", allow_different=True)
    assert len(table) == len(a.summary)
    assert set(table["geometry.H_m"]) == {2.0}
    assert not table.duplicated(["geometry.L_m", "geometry.H_m", "variant", "metric"]).any()
    _, only_a, only_b, keys = match_rows(a, b)
    assert keys == ["geometry.L_m", "geometry.H_m"]
    assert only_a.empty and len(only_b) == len(b.summary) - len(a.summary)
    assert set(only_b["geometry.H_m"]) == {1.0}
    capsys.readouterr()
    assert main(["compare", str(runs["a"]), str(runs["b"]), "--allow-different", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert sum(data["counts"].values()) == len(a.summary) and len(data["only_b"]) == len(only_b)
    # the other way round: b's H = 1 rows are a's missing ones
    table = compare_runs(b, a, "p95", allow_different=True)
    assert len(table) == len(a.summary) and set(table["geometry.H_m"]) == {2.0}


# --- report: a changed result directory is refused, nothing is touched -------------------------


def _plots_replaced_by_notes(d: Path) -> None:
    shutil.rmtree(d / "plots")
    (d / "plots").write_text("my notes\n")


def _study_key_removed(d: Path) -> None:
    prov = json.loads((d / "provenance.json").read_text())
    del prov["study"]
    (d / "provenance.json").write_text(json.dumps(prov, indent=2))


def _summary_edit(change):
    def edit(d: Path) -> None:
        table = pd.read_parquet(d / "summary.parquet")
        change(table).to_parquet(d / "summary.parquet", index=False)
    return edit


def _csv_digit_changed(d: Path) -> None:
    text = (d / "summary.csv").read_text()
    i = text.index("\n") + 1
    j = i + text[i:].index(",")  # the first data row's point number: same size, other digit
    (d / "summary.csv").write_text(text[:j - 1] + "7" + text[j:])


EDITS = {
    "plots-is-a-file": (_plots_replaced_by_notes, ("'plots'", "directory")),
    "study-key-removed": (_study_key_removed, ("provenance.json",)),
    "metric-column-dropped": (_summary_edit(lambda t: t.drop(columns=["metric"])),
                              ("summary.parquet",)),
    "a-point-deleted": (_summary_edit(lambda t: t[t["point"] != 1]), ("summary.parquet",)),
    "metrics-renamed": (_summary_edit(lambda t: t.assign(metric=t["metric"] + "_x")),
                        ("summary.parquet",)),
    "summary-csv-edited": (_csv_digit_changed, ("summary.csv", "edited")),
    "report-md-edited": (lambda d: (d / "report.md").write_text("my conclusions\n"),
                         ("report.md",)),
}


@pytest.mark.parametrize("edit", sorted(EDITS))
def test_report_refuses_a_result_changed_since_it_was_written(runs, tmp_path, capsys, edit):
    change, expect = EDITS[edit]
    d = tmp_path / "result"
    shutil.copytree(runs["a"], d)
    change(d)
    before = snapshot(tmp_path)
    refused(capsys, ["report", str(d)], str(d), *expect)
    assert snapshot(tmp_path) == before


def test_report_of_an_unchanged_result_keeps_its_files_and_modes(runs, tmp_path, capsys):
    """Drawn again, the plots are the same bytes and plots/ keeps the mode `run` gave it."""
    d = tmp_path / "result"
    shutil.copytree(runs["a"], d)
    before = snapshot(d)
    assert main(["report", str(d)]) == 0
    after = snapshot(d)
    assert oct(after["plots"][2]) == oct(before["plots"][2])
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(after["plots"][2]) == 0o777 & ~umask
    assert {k: v[1] for k, v in after.items()} == {k: v[1] for k, v in before.items()}
    assert main(["compare", str(runs["a"]), str(d)]) == 0  # still a result compare reads


# --- collimation verify: the fit file --------------------------------------------------------


def _fit(tmp_path: Path, change=None, raw: bytes | None = None) -> Path:
    path = tmp_path / "fit.json"
    if raw is not None:
        path.write_bytes(raw)
        return path
    data = json.loads(FIT.read_text())
    if change is not None:
        change(data)
    path.write_text(json.dumps(data))  # Python writes NaN as NaN, as a script would
    return path


def test_verify_refuses_a_non_finite_offset(tmp_path, capsys):
    fit = _fit(tmp_path, lambda d: d["parameters"].update(axis_az=float("nan")))
    refused(capsys, ["collimation", "verify", str(fit), str(NEW_SET)],
            "fit.json", "parameters.axis_az", "nan")


def test_verify_refuses_a_fit_file_that_is_not_utf8(tmp_path, capsys):
    text = FIT.read_text().replace('"reference"', '"reference", "note": "\u00e9t\u00e9"', 1)
    fit = _fit(tmp_path, raw=text.encode("latin-1"))
    refused(capsys, ["collimation", "verify", str(fit), str(NEW_SET)], "fit.json", "UTF-8")


def test_verify_blames_zero_sigmas_on_the_fit_file(tmp_path, capsys):
    fit = _fit(tmp_path, lambda d: d["sigma_arcsec"].update(ins=0.0, theodolite=0.0))
    line = refused(capsys, ["collimation", "verify", str(fit), str(NEW_SET)], "fit.json",
                   "sigma_arcsec")
    assert "collimation_new.csv" not in line


def test_verify_of_the_saved_fit_is_accepted(capsys):
    assert main(["collimation", "verify", str(FIT), str(NEW_SET)]) == 0
    assert "holds out of sample" in capsys.readouterr().out


# --- budget --from-problem-spec: malformed SALib problems ------------------------------------

PROBLEM = {"num_vars": 2, "names": ["dx_m", "dy_m"], "groups": ["dx_m", "dy_m"],
           "dists": ["unif", "unif"], "bounds": [[-0.1, 0.1], [-0.1, 0.1]],
           "outputs": ["rotation_angle"]}
MALFORMED = {
    "flat-bounds": ({"bounds": [-0.1, 0.1]}, "bounds[0]"),
    "outputs-int": ({"outputs": 3}, "outputs"),
    "outputs-object": ({"outputs": {"a": 1}}, "outputs"),
    "names-nested": ({"names": [["dx_m"], "dy_m"]}, "names[0]"),
    "dists-nested": ({"dists": [["unif"], "unif"]}, "dists[0]"),
    "string-bounds": ({"bounds": [["-0.1", "0.1"], [-0.1, 0.1]]}, "bounds[0]"),
    "null-bound": ({"bounds": [[None, 0.1], [-0.1, 0.1]]}, "bounds[0]"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_budget_refuses_a_malformed_problem_file(tmp_path, capsys, case):
    change, field = MALFORMED[case]
    path = tmp_path / "problem.json"
    path.write_text(json.dumps({**PROBLEM, **change}))
    before = snapshot(tmp_path)
    refused(capsys, ["budget", "--from-problem-spec", str(path), "--limit", "3", "--out",
                     str(tmp_path / "out")], "problem.json", field)
    assert snapshot(tmp_path) == before


# --- diagnose camera: model coordinates -------------------------------------------------------


def test_diagnose_camera_refuses_a_huge_model_coordinate(tmp_path, capsys):
    model = tmp_path / "model.csv"
    lines = CAM_MODEL.read_text().splitlines()
    first = lines[1].split(",")
    first[1] = "1e300"
    model.write_text("\n".join([lines[0], ",".join(first), *lines[2:]]) + "\n")
    refused(capsys, ["diagnose", "camera", str(model), str(CAM_VIEWS), "--pixel-sigma-px", "0.2"],
            "model.csv", "row 2", "'X'", "1e300")


# --- mistakes named in the file that makes them ----------------------------------------------

SMALL = STUDY.format(name="small", extra="")


def test_errors_file_mistakes_are_named_in_the_errors_file(tmp_path, capsys):
    study = tmp_path / "small.toml"
    study.write_text(SMALL)
    errors = tmp_path / "more.toml"
    errors.write_text("[errors]\nbanana_m = 0.1\n")
    line = refused(capsys, ["run", str(study), "--errors", str(errors), "--out",
                            str(tmp_path / "out")], "more.toml", "errors.banana_m")
    assert "small.toml" not in line
    refused(capsys, ["run", str(study), "--errors", str(tmp_path / "none.toml"), "--out",
                     str(tmp_path / "out")], "none.toml", "no such errors file")
    study.write_text(SMALL.replace("trials = 200", "trials = 0"))  # the study's own mistake
    refused(capsys, ["run", str(study), "--errors", str(errors), "--out", str(tmp_path / "out")],
            "small.toml", "study.trials")


def test_an_unknown_output_of_a_problem_file_is_named_there(tmp_path, capsys):
    """The output name became the budget's metric; its refusal named an internal study."""
    path = tmp_path / "problem.json"
    path.write_text(json.dumps({**PROBLEM, "outputs": ["banana"]}))
    line = refused(capsys, ["budget", "--from-problem-spec", str(path), "--limit", "3",
                            "--out", str(tmp_path / "out")], "problem.json", "outputs[0]",
                   "banana")
    assert "<" not in line
    assert not (tmp_path / "out").exists()
