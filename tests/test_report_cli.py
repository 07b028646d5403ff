"""``montecarlo report DIR`` draws the plots and report of a saved result again, identically,
in any of the plot formats, and refuses what it cannot rebuild."""

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.forked_cli import montecarlo_cli

ROOT = Path(__file__).parent.parent
TABLE1 = ROOT / "studies" / "table1.toml"


def _mc(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return montecarlo_cli(*args, cwd=cwd)


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("report")
    done = _mc("-q", "run", str(TABLE1), "--trials", "1000", "--out", str(tmp / "run"),
               "--n-jobs", "1")
    assert done.returncode == 0, done.stderr
    return tmp / "run"


def test_report_draws_the_same_report_and_plots_again(saved, tmp_path):
    copy = tmp_path / "copy"
    shutil.copytree(saved, copy)
    (copy / "report.md").unlink()  # what report draws again may be missing (an edited
    shutil.rmtree(copy / "plots")  # one is refused: tests/test_trusted_inputs.py)
    done = _mc("report", str(copy))
    assert done.returncode == 0, done.stderr
    assert (copy / "report.md").read_bytes() == (saved / "report.md").read_bytes()
    names = sorted(p.name for p in (saved / "plots").iterdir())
    assert names and sorted(p.name for p in (copy / "plots").iterdir()) == names
    for name in names:
        assert (copy / "plots" / name).read_bytes() == (saved / "plots" / name).read_bytes()
    assert sorted(p.name for p in copy.iterdir()) == sorted(p.name for p in saved.iterdir())


@pytest.mark.parametrize("fmt, magic", [("svg", b"<?xml"), ("pdf", b"%PDF")])
def test_report_in_other_formats_replaces_the_plots(saved, tmp_path, fmt, magic):
    copy = tmp_path / "copy"
    shutil.copytree(saved, copy)
    done = _mc("report", str(copy), "--format", fmt)
    assert done.returncode == 0, done.stderr
    plots = list((copy / "plots").iterdir())
    assert plots and all(p.suffix == f".{fmt}" and p.read_bytes().startswith(magic)
                         for p in plots)
    assert f"(plots/histograms.{fmt})" in (copy / "report.md").read_text()
    assert not [p for p in copy.iterdir() if p.name.startswith(".")]
    page = (copy / "report.html").read_text()
    # SVG plots are the report's figures as vectors; a PDF's are PNGs drawn beside it
    assert page.count("<svg" if fmt == "svg" else "<img") == len(plots)
    assert page.count("<img" if fmt == "svg" else "<svg") == 0
    if fmt == "svg":
        from montecarlo.output.html_report import inline_svg

        assert all(inline_svg(p.read_text()) in page for p in plots)  # the files' drawing


def test_run_writes_the_format_asked(tmp_path):
    study = tmp_path / "small.toml"
    done = _mc("init", "ground", str(study))
    assert done.returncode == 0, done.stderr
    done = _mc("-q", "run", str(study), "--trials", "500", "--out", str(tmp_path / "out"),
               "--format", "svg", "--n-jobs", "1")
    assert done.returncode == 0, done.stderr
    assert {p.suffix for p in (tmp_path / "out" / "plots").iterdir()} == {".svg"}
    prov = json.loads((tmp_path / "out" / "provenance.json").read_text())
    assert prov["study_source"]["study"]["trials"] == 500  # the override is kept


def test_report_refuses_what_it_cannot_rebuild(saved, tmp_path):
    done = _mc("report", str(tmp_path))
    assert done.returncode == 2 and "provenance.json" in done.stderr
    old = tmp_path / "old"
    shutil.copytree(saved, old)
    (old / "histograms.parquet").unlink()
    before = (old / "report.md").read_bytes()
    done = _mc("report", str(old))
    assert done.returncode == 2 and done.stderr.count("\n") == 1
    assert "histograms.parquet" in done.stderr and "Traceback" not in done.stderr
    assert (old / "report.md").read_bytes() == before
    done = _mc("report", str(saved), "--format", "gif")
    assert done.returncode == 2


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["svg", "pdf"])
def test_svg_and_pdf_are_the_same_bytes_on_every_render(saved, tmp_path, fmt):
    """`report --format svg|pdf` differed on every re-render (creation date, random clip-path
    ids); with the date left out and matplotlib's svg.hashsalt fixed, two renders a second
    apart are byte-identical, as PNG already was. Slow (two reports a second apart, 11 s);
    the bytes themselves are checked in the default run by
    ``tests/test_io_files.py``'s test of ``figure_bytes``."""
    import time

    copies = []
    for name in ("first", "second"):
        copy = tmp_path / name
        shutil.copytree(saved, copy)
        done = _mc("report", str(copy), "--format", fmt)
        assert done.returncode == 0, done.stderr
        copies.append(copy)
        time.sleep(1.1)  # the date would differ in its seconds
    names = sorted(p.name for p in (copies[0] / "plots").iterdir())
    assert names and all(n.endswith(f".{fmt}") for n in names)
    for name in names:
        a = (copies[0] / "plots" / name).read_bytes()
        assert a == (copies[1] / "plots" / name).read_bytes(), name
        assert b"CreationDate" not in a and b"<dc:date>" not in a
