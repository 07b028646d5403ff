"""The docs cite acceptance figures from the files ``make acceptance`` wrote, and their links hold.

A figure is cited as a link whose text is the number and whose target is the suite's JSON with
the figure's name as fragment, e.g. ``[95.5 %](../../results/acceptance/sizing.json#name)`` (a
share printed as a percentage when the text ends in ``%``). Each must equal the recorded value
at the printed digits. Every relative link of the README and the docs, and every path of a
docs page named in the repository's text, must exist.
"""

import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).parent.parent
PAGES = [*sorted((ROOT / "docs").rglob("*.md")), ROOT / "README.md"]
CITATION = re.compile(r"\[([^\]]+)\]\(((?:\.\./)*results/acceptance/([\w.-]+)\.json)#([^)\s]+)\)")
LINK = re.compile(r"\]\(([^)\s]+)\)")


def citations() -> list[tuple[str, str, str, str, str]]:
    """(page, printed text, link path, suite, figure) of every cited figure."""
    found = []
    for page in PAGES:
        for m in CITATION.finditer(page.read_text()):
            found.append((str(page.relative_to(ROOT)), *m.groups()))
    return found


def printed_equals(printed: str, value: float) -> bool:
    """``value`` rounded to the decimals of ``printed`` ("0.955", "95.5 %", "1.02") is it.

    >>> printed_equals("95.5 %", 0.955), printed_equals("0.96", 0.955), printed_equals("1", 1.0)
    (True, True, True)
    >>> printed_equals("95.4 %", 0.955)
    False
    """
    text = printed.replace("−", "-").replace(",", "").strip()
    if text.endswith("%"):
        text, value = text[:-1].strip(), value * 100.0
    decimals = len(text.split(".")[1]) if "." in text else 0
    return abs(value - float(text)) <= 0.5 * 10.0**-decimals * (1 + 1e-9)


def test_every_recorded_suite_is_cited():
    """Each results/acceptance/<suite>.json with figures is cited by the docs."""
    recorded = {p.stem for p in (ROOT / "results" / "acceptance").glob("*.json")
                if json.loads(p.read_text())["figures"]}
    assert recorded, "no results/acceptance/*.json: run make acceptance"
    assert recorded <= {c[3] for c in citations()}, recorded - {c[3] for c in citations()}


@pytest.mark.parametrize(("page", "printed", "path", "suite", "name"), citations(),
                         ids=lambda v: str(v)[:60])
def test_a_cited_figure_is_the_recorded_one(page, printed, path, suite, name):
    target = (ROOT / page).parent / path
    assert target.resolve() == (ROOT / "results" / "acceptance" / f"{suite}.json").resolve(), page
    record = json.loads(target.read_text())
    assert name in record["figures"], f"{page}: {suite}.json has no figure {name!r}"
    figure = record["figures"][name]
    assert printed_equals(printed, figure["value"]), (
        f"{page} prints {printed} for {suite}#{name}; the recorded value is {figure['value']}")


def _links(page: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)
    return [t for t in LINK.findall(text) if not re.match(r"^[a-z]+:", t) and not t.startswith("#")]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(page):
    missing = [t for t in _links(page) if not (page.parent / t.split("#")[0]).exists()]
    assert not missing, missing


def test_every_docs_path_named_in_the_repository_exists():
    named = set()
    for path in [*ROOT.glob("*.md"), *ROOT.glob("Makefile"), *(ROOT / "docs").rglob("*.md"),
                 *(ROOT / "montecarlo").rglob("*.py"), *(ROOT / "tests").rglob("*.py"),
                 *(ROOT / "studies").glob("*.toml")]:
        named |= {(str(path.relative_to(ROOT)), m)
                  for m in re.findall(r"\bdocs/[\w/.-]+?\.md", path.read_text())}
    missing = sorted((where, p) for where, p in named if not (ROOT / p).exists())
    assert not missing, missing


def test_guide_pages_are_short():
    """A guide page is one task: at most about 300 lines."""
    long = {p.name: n for p in (ROOT / "docs" / "guide").glob("*.md")
            if (n := len(p.read_text().splitlines())) > 320}
    assert not long, long


def test_the_cli_reference_is_the_parsers():
    """docs/reference/cli.md is what ``python -m tests.cli_reference`` prints from the parser."""
    from tests.cli_reference import page

    assert (ROOT / "docs" / "reference" / "cli.md").read_text() == page(), (
        "docs/reference/cli.md is stale: .venv/bin/python -m tests.cli_reference > "
        "docs/reference/cli.md")
