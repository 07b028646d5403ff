"""Open report.html files in headless Chromium (Playwright) and check what a reader sees.

For each report: no console error and no uncaught script error, no request other than the
file itself (any other is recorded and aborted), every figure's SVG or image laid out at a
non-zero size with something drawn in it, the verdict first, and a full-page screenshot.

Used by ``tests/test_browser.py`` (``make test-browser``). Playwright is imported only when a
browser is started, so this module imports without it. The browser is Debian's ``chromium``
package (``/usr/bin/chromium``, or ``$CHROMIUM``), never one that Playwright downloads.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync")
"""Flags that run Chromium headless on a shared machine without a GPU or network access of
its own. Playwright gives every launch a fresh temporary profile (user data directory)."""

VERDICT_HEADINGS = ("Spec", "Verdict", "Answers")

# What the page shows, measured in the browser: headings in order, where the first table
# sits, and each figure's laid-out size and the size of what is drawn inside it.
_LAYOUT_JS = """() => {
  const heading = el => {
    let n = el;
    while (n) {
      let p = n.previousElementSibling;
      while (p) { if (p.tagName === 'H2') return p.textContent; p = p.previousElementSibling; }
      n = n.parentElement;
      if (n === document.body) break;
    }
    return null;
  };
  const table = document.querySelector('table');
  const pre = document.querySelector('pre');
  const h2 = document.querySelector('h2');
  const before = (a, b) => !!a && (!b ||
      !!(a.compareDocumentPosition(b) & Node.DOCUMENT_POSITION_FOLLOWING));
  const figures = [...document.querySelectorAll('figure')].map(f => {
    const g = f.querySelector('svg, img');
    if (!g) return {id: f.id, kind: null, width: 0, height: 0, drawn_width: 0, drawn_height: 0};
    const r = g.getBoundingClientRect();
    let dw = g.naturalWidth || 0, dh = g.naturalHeight || 0;
    if (g.tagName.toLowerCase() === 'svg') { const b = g.getBBox(); dw = b.width; dh = b.height; }
    return {id: f.id, kind: g.tagName.toLowerCase(), width: r.width, height: r.height,
            drawn_width: dw, drawn_height: dh};
  });
  return {
    headings: [...document.querySelectorAll('h2')].map(h => h.textContent),
    first_table_heading: table ? heading(table) : null,
    verdict_cells: [...document.querySelectorAll('tr.meets, tr.fails, tr.undecided')].length,
    pre_before_first_heading: before(pre, h2),
    figures: figures,
    stray_media: document.querySelectorAll('body > svg, body > img, p img, li img').length,
    page_width: document.documentElement.scrollWidth,
    page_height: document.documentElement.scrollHeight,
  };
}"""


@dataclass
class PageCheck:
    """What one report looked like in the browser, and what was wrong with it."""

    path: Path
    screenshot: Path | None = None
    console_errors: list[str] = field(default_factory=list)
    requests_out: list[str] = field(default_factory=list)
    layout: dict[str, Any] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)

    def summary(self) -> str:
        figs = self.layout.get("figures", [])
        sizes = ", ".join(f"{f['width']:.0f}×{f['height']:.0f}" for f in figs)
        first = (self.layout.get("headings") or ["-"])[0]
        status = "ok" if not self.problems else "FAILED: " + "; ".join(self.problems)
        return (f"{self.path.parent.name}/{self.path.name}: {len(figs)} figures [{sizes}] px, "
                f"first section '{first}', {len(self.console_errors)} console errors, "
                f"{len(self.requests_out)} requests out, page {self.layout.get('page_width')}×"
                f"{self.layout.get('page_height')} px -> {status}")


def chromium_path() -> str | None:
    """The Chromium binary to drive: ``$CHROMIUM``, else Debian's ``/usr/bin/chromium`` or
    one on the PATH; None if there is none."""
    for candidate in (os.environ.get("CHROMIUM"), "/usr/bin/chromium"):
        if candidate and Path(candidate).is_file() and os.access(candidate, os.X_OK):
            return candidate
    return shutil.which("chromium") or shutil.which("chromium-browser")


@contextmanager
def chromium() -> Iterator[Any]:
    """A headless Chromium browser (Playwright ``Browser``) for the duration of the block."""
    from playwright.sync_api import sync_playwright

    executable = chromium_path()
    if executable is None:
        raise FileNotFoundError("no Chromium: install Debian's chromium package or set "
                                "$CHROMIUM")
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=executable, headless=True,
                                    args=list(CHROMIUM_FLAGS))
        try:
            yield browser
        finally:
            browser.close()


def check_report(browser: Any, path: str | Path, verdict: str,
                 screenshot: str | Path | None = None, width: int = 1280) -> PageCheck:
    """Load one ``report.html`` and check it.

    ``verdict`` says where the report's verdict is: ``"section"`` (a Spec, Verdict or Answers
    section is the first section and holds the first table, its rows coloured by verdict),
    ``"text"`` (the diagnosis text comes before any section) or ``"none"`` (a study without a
    spec: the provenance is the first section).
    """
    path = Path(path).resolve()
    url = path.as_uri()
    check = PageCheck(path, Path(screenshot) if screenshot else None)
    context = browser.new_context(viewport={"width": width, "height": 900},
                                  java_script_enabled=True, offline=True)
    try:
        page = context.new_page()

        def on_request(request: Any) -> None:
            if request.url != url:
                check.requests_out.append(request.url)

        def on_route(route: Any) -> None:
            if route.request.url == url:
                route.continue_()
            else:
                route.abort()

        page.on("console", lambda msg: check.console_errors.append(msg.text)
                if msg.type == "error" else None)
        page.on("pageerror", lambda exc: check.console_errors.append(str(exc)))
        page.on("request", on_request)
        context.route("**/*", on_route)
        page.goto(url, wait_until="load")
        page.wait_for_load_state("networkidle")
        check.layout = page.evaluate(_LAYOUT_JS)
        if check.screenshot is not None:
            check.screenshot.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(check.screenshot), full_page=True)
    finally:
        context.close()
    check.problems = _problems(check, verdict)
    return check


def _problems(check: PageCheck, verdict: str) -> list[str]:
    layout = check.layout
    problems = [f"console error: {e}" for e in check.console_errors]
    problems += [f"request leaving the file: {u}" for u in check.requests_out]
    figures = layout["figures"]
    if not figures:
        problems.append("no figure")
    for f in figures:
        if f["kind"] is None:
            problems.append(f"figure {f['id']!r} holds no svg or img")
        elif min(f["width"], f["height"]) <= 0:
            problems.append(f"figure {f['id']!r} laid out at {f['width']}×{f['height']} px")
        elif min(f["drawn_width"], f["drawn_height"]) <= 0:
            problems.append(f"figure {f['id']!r} draws nothing")
    if layout["stray_media"]:
        problems.append(f"{layout['stray_media']} images outside a figure")
    headings = layout["headings"]
    first = headings[0] if headings else None
    if verdict == "section":
        if first is None or not first.startswith(VERDICT_HEADINGS):
            problems.append(f"first section is {first!r}, not the verdict")
        elif layout["first_table_heading"] != first:
            problems.append(f"first table is under {layout['first_table_heading']!r}, "
                            f"not under {first!r}")
        if not layout["verdict_cells"]:
            problems.append("no row marked meets, fails or undecided")
    elif verdict == "text":
        if not layout["pre_before_first_heading"]:
            problems.append("the diagnosis text does not come before the first section")
        if first != "Provenance":
            problems.append(f"first section after the diagnosis is {first!r}")
    elif first != "Provenance":
        problems.append(f"first section of a report without a verdict is {first!r}")
    return problems
