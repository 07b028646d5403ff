"""Every shipped study's report.html and a diagnosis report, opened in headless Chromium.

Run by ``make test-browser`` (which installs Debian's chromium and Playwright first); skipped
where either is missing. The studies run at few trials (the report's form does not depend on
the trial count) into ``$MONTECARLO_BROWSER_OUT`` (``make test-browser``: results/browser),
else a temporary directory; each report's full-page screenshot is saved in its result
directory as ``report-screenshot.png``.
"""

from __future__ import annotations

import os
import tomllib
from pathlib import Path

import pytest
from browser_check import check_report, chromium, chromium_path

from montecarlo.cli import main

ROOT = Path(__file__).parent.parent
STUDIES = sorted((ROOT / "studies").glob("*.toml"))
TRIALS = {"stabilization": "4", "collimation_layout": "16"}  # the slowest trials
SCREENSHOT = "report-screenshot.png"
GROUND = ROOT / "results/examples/discrepancy_ground/data.csv"


def _browser_missing() -> str | None:
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "Playwright is not installed (make test-browser installs it)"
    if chromium_path() is None:
        return "Chromium is not installed (make test-browser installs Debian's chromium)"
    return None


pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(_browser_missing() is not None,
                                 reason=_browser_missing() or "")]


@pytest.fixture(scope="module")
def out_root(tmp_path_factory) -> Path:
    given = os.environ.get("MONTECARLO_BROWSER_OUT")
    if not given:
        return tmp_path_factory.mktemp("browser")
    root = Path(given).resolve()
    root.mkdir(parents=True, exist_ok=True)
    return root


@pytest.fixture(scope="module")
def browser():
    with chromium() as b:
        yield b


def _fresh(path: Path) -> Path:
    """A result directory this test may write: absent, or one it wrote before (replaced)."""
    if path.exists():
        assert (path / "report.html").exists(), f"{path} is not an earlier result; move it"
        import shutil

        shutil.rmtree(path)
    return path


def _show(capsys, check) -> None:
    """The check's one-line summary and screenshot on the terminal (the run's output not)."""
    capsys.readouterr()
    with capsys.disabled():
        print(f"\n{check.summary()}\n  screenshot: {check.screenshot}")


@pytest.mark.parametrize("study", STUDIES, ids=[s.stem for s in STUDIES])
def test_study_report_in_chromium(study, out_root, browser, capsys):
    out = _fresh(out_root / study.stem)
    code = main(["run", str(study), "--trials", TRIALS.get(study.stem, "256"), "-q",
                 "--n-jobs", "1", "--out", str(out)])
    assert code == 0
    has_spec = "spec" in tomllib.loads(study.read_text())
    check = check_report(browser, out / "report.html", "section" if has_spec else "none",
                         out / SCREENSHOT)
    _show(capsys, check)
    assert check.problems == []
    figures = check.layout["figures"]
    assert len(figures) == len(list((out / "plots").iterdir()))
    assert (out / SCREENSHOT).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_diagnose_report_in_chromium(out_root, browser, capsys):
    out = _fresh(out_root / "diagnose_ground")
    code = main(["diagnose", "ground", str(GROUND), "--fov-deg", "90", "90", "--pixels", "512",
                 "512", "--pixel-sigma-px", "0.3", "--survey-sigma-m", "0.01", "--trials", "20",
                 "--report", str(out), "-q"])
    assert code == 0
    check = check_report(browser, out / "report.html", "text", out / SCREENSHOT)
    _show(capsys, check)
    assert check.problems == []
    assert [f["id"] for f in check.layout["figures"]] == ["residuals", "gap"]


def test_a_broken_report_is_caught(tmp_path, browser):
    """The checks can fail: a figure of zero size, a script error, an image fetched from the
    network, and a verdict placed after another section are each reported."""
    page = tmp_path / "report.html"
    page.write_text(
        "<!DOCTYPE html><html><head><meta charset='utf-8'><title>t</title></head><body>"
        "<h1>t</h1><h2>Provenance</h2><table><tr><td>x</td></tr></table>"
        "<h2>Spec</h2><table><tr class='meets'><td>meets</td></tr></table>"
        "<figure id='a'><svg width='0' height='0'><rect width='5' height='5'/></svg></figure>"
        "<figure id='b'><img src='http://192.0.2.1/x.png' width='10' height='10'></figure>"
        "<script>undefined_function()</script></body></html>")
    check = check_report(browser, page, "section")
    text = "\n".join(check.problems)
    assert "first section is 'Provenance', not the verdict" in text
    assert "figure 'a' laid out at 0×0 px" in text
    assert "request leaving the file: http://192.0.2.1/x.png" in text
    assert "undefined_function" in text
