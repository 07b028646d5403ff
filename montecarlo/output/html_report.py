"""``report.html``: the report of a result as one self-contained file to mail or archive.

Written beside ``report.md`` by ``run``, ``report DIR``, ``diagnose --report``, ``size`` and
``budget``. It holds the provenance, the verdict table first, the rest of the report and every
plot inline with a caption stating the metric, the statistic, the unit and the pixel
relation. It references nothing outside itself (no network, no file, no script, no
stylesheet link), so it opens anywhere and reads without JavaScript.

Each figure is drawn once: the report holds the bytes of the plot file written beside it, a
PNG as a ``data:`` image, an SVG (``--format svg``) inline as vectors. The same inputs give the
same bytes: the plot files do (:func:`montecarlo.io.files.figure_bytes`), and the provenance
shown is the saved ``provenance.json``.

The body is converted from the report's Markdown by :func:`markdown_html`, which knows the
subset our reports use: headings, paragraphs, ``-`` lists, pipe tables, fenced code, inline
code, bold and images (``![alt](file)``, each replaced by its figure's SVG; an image without a
figure is an error, never a link).
"""

from __future__ import annotations

import base64
import html
import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from montecarlo.io.files import (
    FILES_KEY,
    HASHES_KEY,
    PROVENANCE,
    RECORD_KEY,
    atomic_write_bytes,
)

HTML_NAME = "report.html"

PROVENANCE_FIELDS = ("kind", "study", "study_hash", "seed", "package_version", "git_commit",
                     "code_fingerprint", "kernel", "created_utc", "command", "platform", "cpu")
"""Provenance entries shown first, in this order (the rest follow, libraries last)."""

CSS = """
body{font-family:system-ui,sans-serif;max-width:72rem;margin:1.5rem auto;padding:0 1rem;
color:#111;line-height:1.4}
table{border-collapse:collapse;margin:.6rem 0;font-size:.85rem}
th,td{border:1px solid #bbb;padding:.15rem .45rem;text-align:right}
th{background:#eee}td:first-child,th:first-child{text-align:left}
code,pre{font-family:ui-monospace,monospace;font-size:.85rem}
pre{background:#f6f6f6;padding:.6rem;overflow-x:auto}
figure{margin:1rem 0}figure svg,figure img{max-width:100%;height:auto}
figcaption{font-size:.85rem;color:#333;max-width:60rem}
.meets{background:#d9f2d9}.fails{background:#f7d4d4}.undecided{background:#fdf1c7}
table.provenance td{text-align:left}
""".strip()


@dataclass(frozen=True)
class HtmlFigure:
    """A figure of the report: its HTML (an inline ``<svg>`` or a ``data:`` PNG ``<img>``)
    and its caption (plain text)."""

    markup: str
    caption: str


_STRIP = [re.compile(p, re.S) for p in (r"<\?xml.*?\?>\s*", r"<!DOCTYPE.*?>\s*",
                                           r"<metadata>.*?</metadata>\s*")]
_XMLNS = re.compile(r'\s+xmlns(:xlink)?="[^"]*"')
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def inline_svg(text: str) -> str:
    """SVG text ready to sit inside HTML: no XML prolog, doctype, metadata or namespace
    declarations (HTML parses ``<svg>`` as SVG without them)."""
    for pattern in _STRIP:
        text = pattern.sub("", text)
    head, sep, rest = text.partition(">")
    return _XMLNS.sub("", head) + sep + rest


def figure_markup(data: bytes, fmt: str, alt: str) -> str:
    """The HTML of a rendered figure: ``data`` (the bytes of a ``png`` or ``svg`` file) as an
    ``<img>`` holding the PNG itself, at its pixel size, or as inline SVG."""
    if fmt == "svg":
        return inline_svg(data.decode("utf-8"))
    if fmt != "png" or not data.startswith(PNG_SIGNATURE):
        raise ValueError(f"{alt}: not a PNG or SVG figure")
    width, height = (int.from_bytes(data[k:k + 4], "big") for k in (16, 20))  # IHDR
    return (f'<img src="data:image/png;base64,{base64.b64encode(data).decode("ascii")}" '
            f'width="{width}" height="{height}" alt="{html.escape(alt)}">')


def saved_figure(path: Path, caption: str) -> HtmlFigure:
    """The figure a PNG or SVG file holds, as drawn (nothing is drawn again)."""
    return HtmlFigure(figure_markup(path.read_bytes(), path.suffix.lstrip("."), path.stem),
                      caption)


_CODE = re.compile(r"`([^`]+)`")
_BOLD = re.compile(r"\*\*(.+?)\*\*")
_EM = re.compile(r"(?<![\w*])\*(?=\S)([^*]+?)(?<=\S)\*(?![\w*])")
_IMAGE = re.compile(r"^!\[([^\]]*)\]\(([^)\s]+)\)$")
_LINK = re.compile(r"\[([^\]]+)\]\(([^)\s]+)\)")


def inline(text: str) -> str:
    """Escaped text with inline code, bold and emphasis (links keep their text only)."""
    parts = _CODE.split(text)
    out = []
    for i, part in enumerate(parts):
        if i % 2:
            out.append(f"<code>{html.escape(part)}</code>")
            continue
        part = _LINK.sub(r"\1", part)
        part = html.escape(part)
        part = _BOLD.sub(r"<strong>\1</strong>", part)
        out.append(_EM.sub(r"<em>\1</em>", part))
    return "".join(out)


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def _table(lines: list[str]) -> str:
    head = _cells(lines[0])
    body = [_cells(x) for x in lines[2:]] if len(lines) > 1 and set(lines[1]) <= set("|-: ") \
        else [_cells(x) for x in lines[1:]]
    verdict = head.index("verdict") if "verdict" in head else None
    rows = ["<tr>" + "".join(f"<th>{inline(c)}</th>" for c in head) + "</tr>"]
    for cells in body:
        cls = ""
        if verdict is not None and verdict < len(cells) and cells[verdict] in (
                "meets", "fails", "undecided"):
            cls = f' class="{cells[verdict]}"'
        rows.append(f"<tr{cls}>" + "".join(f"<td>{inline(c)}</td>" for c in cells) + "</tr>")
    return "<table>\n" + "\n".join(rows) + "\n</table>"


def markdown_html(md: str, figures: Mapping[str, HtmlFigure]) -> str:
    """HTML of the Markdown subset our reports use; ``![alt](path)`` becomes the figure
    named by the path's file name.

    Raises
    ------
    KeyError
        An image whose file has no figure (the report would otherwise point outside itself).
    """
    out: list[str] = []
    lines = md.splitlines()
    i = 0
    para: list[str] = []

    def flush() -> None:
        if para:
            out.append("<p>" + inline(" ".join(para)) + "</p>")
            para.clear()

    while i < len(lines):
        line = lines[i]
        stripped = line.strip()
        if stripped.startswith("```"):
            flush()
            j = i + 1
            while j < len(lines) and not lines[j].strip().startswith("```"):
                j += 1
            out.append("<pre>" + html.escape("\n".join(lines[i + 1:j])) + "</pre>")
            i = j + 1
            continue
        if not stripped:
            flush()
        elif m := re.match(r"^(#{1,6})\s+(.*)$", stripped):
            flush()
            level = len(m.group(1))
            out.append(f"<h{level}>{inline(m.group(2))}</h{level}>")
        elif m := _IMAGE.match(stripped):
            flush()
            name = Path(m.group(2)).name
            fig = figures[name]
            out.append(f'<figure id="{html.escape(Path(name).stem)}">\n{fig.markup}\n'
                       f"<figcaption>{inline(fig.caption)}</figcaption>\n</figure>")
        elif stripped.startswith("|"):
            flush()
            j = i
            while j < len(lines) and lines[j].strip().startswith("|"):
                j += 1
            out.append(_table([x.strip() for x in lines[i:j]]))
            i = j
            continue
        elif stripped.startswith("- "):
            flush()
            items = []
            while i < len(lines) and lines[i].strip().startswith("- "):
                items.append(f"<li>{inline(lines[i].strip()[2:])}</li>")
                i += 1
            out.append("<ul>\n" + "\n".join(items) + "\n</ul>")
            continue
        else:
            para.append(stripped)
        i += 1
    flush()
    return "\n".join(out)


def _sections(md: str) -> list[str]:
    """The report split before each second-level heading (the first part: title and intro)."""
    parts = re.split(r"(?m)^(?=## )", md)
    return [p for p in parts if p.strip()]


def verdict_first(md: str, headings: Sequence[str] = ("Spec", "Verdict", "Answers")) -> str:
    """The report with its verdict sections (``## Spec`` ...) moved right after the title."""
    parts = _sections(md)
    if not parts:
        return md
    head, rest = parts[0], parts[1:]
    if head.startswith("## "):
        head, rest = "", parts
    first = [p for p in rest if p[3:].startswith(tuple(headings))]
    return "\n".join([head, *first, *(p for p in rest if p not in first)])


def provenance_table(prov: Mapping[str, Any]) -> str:
    """The provenance as an HTML table: the main entries, then the rest (JSON for nested).
    The directory's list of written files is left out: it is written after the report and
    changes with it, so the same results would not give the same bytes."""
    keys = [k for k in PROVENANCE_FIELDS if k in prov]
    skip = {"resolved_study", "study_source", "libraries", FILES_KEY, HASHES_KEY, RECORD_KEY}
    keys += sorted(k for k in prov if k not in keys and k not in skip)
    rows = []
    for k in keys:
        v = prov[k]
        text = v if isinstance(v, str) else json.dumps(v, sort_keys=True, default=str)
        if len(text) > 400:
            text = text[:397] + "..."
        rows.append(f"<tr><th>{html.escape(k)}</th><td>{html.escape(text)}</td></tr>")
    libs = prov.get("libraries")
    if isinstance(libs, Mapping):
        text = ", ".join(f"{k} {v}" for k, v in libs.items())
        rows.append(f"<tr><th>libraries</th><td>{html.escape(text)}</td></tr>")
    return '<table class="provenance">\n' + "\n".join(rows) + "\n</table>"


def render_html(md: str, figures: Mapping[str, HtmlFigure], provenance: Mapping[str, Any],
                title: str) -> str:
    """The whole document: title, verdicts, provenance, the rest of the report, figures."""
    body = markdown_html(verdict_first(md), figures)
    # provenance right after the verdict sections (before the first other section)
    parts = body.split("\n<h2>")
    verdicts = [p for p in parts[1:] if p.startswith(("Spec", "Verdict", "Answers"))]
    cut = 1 + len(verdicts)
    prov = "<h2>Provenance</h2>\n" + provenance_table(provenance) if provenance else ""
    body = "\n<h2>".join(parts[:cut]) + "\n" + prov + (
        "\n<h2>" + "\n<h2>".join(parts[cut:]) if parts[cut:] else "")
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            f"<title>{html.escape(title)}</title>\n<style>\n{CSS}\n</style>\n</head>\n"
            f"<body>\n{body}\n</body>\n</html>\n")


def write_html(out_dir: str | Path, figures: Mapping[str, HtmlFigure], title: str,
               md: str | None = None) -> Path:
    """Write ``report.html`` into ``out_dir`` from its ``report.md`` (or ``md``) and
    ``provenance.json`` (if there), atomically."""
    out_dir = Path(out_dir)
    text = (out_dir / "report.md").read_text(encoding="utf-8") if md is None else md
    prov_path = out_dir / PROVENANCE
    prov = json.loads(prov_path.read_text(encoding="utf-8")) if prov_path.exists() else {}
    path = out_dir / HTML_NAME
    atomic_write_bytes(path, render_html(text, figures, prov, title).encode("utf-8"))
    return path


_EXTERNAL = [re.compile(p, re.I) for p in (
    r"https?:", r"\bsrc\s*=\s*(?!['\"]data:image/png;base64,)", r"<link\b", r"<script\b",
    r"@import", r"url\(\s*['\"]?(?!#)",
    r"\bhref\s*=\s*['\"](?!#|data:image/png;base64,)", r"<iframe\b", r"<object\b",
    r"<embed\b")]


def external_references(text: str) -> list[str]:
    """Whatever in an HTML text could reach outside it (empty for a self-contained report):
    URLs, stylesheet links, scripts, imports, and ``src``s and ``href``s that are neither
    ``#ids`` nor a PNG held in the text itself (a figure, or a photograph under a figure's
    vectors)."""
    return [m.group(0) for p in _EXTERNAL for m in p.finditer(text)]


def parse_errors(text: str) -> list[str]:
    """Parse errors of an HTML text by the WHATWG algorithm (html5lib), or by the standard
    library's parser where html5lib is not installed (which reports only what it cannot
    parse at all)."""
    try:
        import html5lib
    except ImportError:  # pragma: no cover - html5lib is a dev dependency
        from html.parser import HTMLParser

        try:
            HTMLParser().feed(text)
        except Exception as exc:  # any failure is the answer
            return [str(exc)]
        return []
    parser = html5lib.HTMLParser(strict=False, namespaceHTMLElements=False)
    parser.parse(text)
    return [f"line {line}, col {col}: {err}" for (line, col), err, _ in parser.errors]
