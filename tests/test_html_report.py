"""report.html: one self-contained file, verdicts first, deterministic bytes."""

from __future__ import annotations

import base64
import re
import subprocess
import sys
from pathlib import Path

import pytest

import montecarlo
from montecarlo.output.html_report import (
    HtmlFigure,
    external_references,
    figure_markup,
    inline_svg,
    markdown_html,
    parse_errors,
    verdict_first,
)
from montecarlo.output.outputs import rerender

MD = """# Title

Intro with `code` and **bold**.

## Assumptions

- one
- two

## Spec

| point | verdict |
|---|---|
| 0 | meets |
| 1 | fails |

```
a < b
```

![plot](plots/a.png)
"""


SMALL = {"study": {"name": "small", "system": "ground", "trials": 500, "seed": 3},
         "sensor": {"fov_deg": [90.0, 90.0], "pixels": [512, 512]},
         "mounting": {"psi_deg": 30.0, "theta_deg": 20.0, "gamma_deg": 10.0},
         "geometry": {"L_m": 50.0, "H_m": 2.0},
         "errors": {"dx_m": {"dist": "uniform", "bound": 0.05},
                    "pixel_px": {"dist": "normal", "sigma": 0.3},
                    "pixel_relation": "independent"},
         "solver": {"variants": ["normalised"]},
         "spec": {"metric": "rotation_angle", "statistic": "cvar95", "limit": 3.0},
         "sweep": [{"geometry.L_m": [50.0, 100.0]}]}


def test_markdown_subset_by_hand():
    figs = {"a.png": HtmlFigure("<svg><g/></svg>", "a caption with `m` [mrad]")}
    body = markdown_html(MD, figs)
    assert "<h1>Title</h1>" in body and "<code>code</code>" in body
    assert "<strong>bold</strong>" in body
    assert "<ul>\n<li>one</li>\n<li>two</li>\n</ul>" in body
    assert '<tr class="meets"><td>0</td><td>meets</td></tr>' in body
    assert "<pre>a &lt; b</pre>" in body
    assert '<figure id="a">\n<svg><g/></svg>\n<figcaption>a caption with <code>m</code> ' \
           "[mrad]</figcaption>" in body
    with pytest.raises(KeyError):  # never a link to a file
        markdown_html(MD, {})


def test_verdict_section_moves_first():
    text = verdict_first(MD)
    assert text.index("## Spec") < text.index("```") < text.index("## Assumptions")
    assert text.startswith("# Title")


def test_inline_svg_drops_what_points_outside():
    svg = ('<?xml version="1.0" encoding="utf-8" standalone="no"?>\n<!DOCTYPE svg PUBLIC '
           '"-//W3C//DTD SVG 1.1//EN" "http://www.w3.org/Graphics/SVG/1.1/DTD/svg11.dtd">\n'
           '<svg xmlns:xlink="http://www.w3.org/1999/xlink" width="1" '
           'xmlns="http://www.w3.org/2000/svg"><metadata><rdf:RDF/></metadata>'
           '<use xlink:href="#g1"/></svg>')
    out = inline_svg(svg)
    assert out == '<svg width="1"><use xlink:href="#g1"/></svg>'
    assert external_references(out) == []


def test_a_png_figure_is_held_as_drawn_at_its_pixel_size(tmp_path):
    """The figure's HTML holds the PNG's own bytes, at the size matplotlib's PNG reader gives;
    what is not a PNG or an SVG is refused."""
    import base64

    import matplotlib.image
    from matplotlib.figure import Figure

    fig = Figure(figsize=(3, 2))
    fig.subplots().plot([0, 1], [1, 0])
    fig.savefig(tmp_path / "f.png", dpi=50)
    data = (tmp_path / "f.png").read_bytes()
    markup = figure_markup(data, "png", "f")
    src = re.fullmatch(r'<img src="data:image/png;base64,([^"]+)" width="(\d+)" '
                       r'height="(\d+)" alt="f">', markup)
    assert src is not None and base64.b64decode(src.group(1)) == data
    rows, cols = matplotlib.image.imread(tmp_path / "f.png").shape[:2]
    assert (int(src.group(2)), int(src.group(3))) == (cols, rows) == (150, 100)
    assert external_references(markup) == []
    with pytest.raises(ValueError, match="not a PNG"):
        figure_markup(b"%PDF-1.4", "pdf", "f")
    with pytest.raises(ValueError, match="not a PNG"):
        figure_markup(b"GIF89a", "png", "f")


def test_checks_find_what_they_look_for():
    """The acceptance checks can fail: a URL, a file source, a stylesheet link and a stray
    end tag are found."""
    bad = ('<!DOCTYPE html><html><head><title>t</title><link href="x.css" rel="stylesheet">'
           '</head><body><img src="a.png"><a href="http://x">x</a></div></body></html>')
    found = " ".join(external_references(bad))
    assert "http:" in found and "src=" in found and "<link" in found
    assert parse_errors(bad)  # the stray </div>
    assert parse_errors("<!DOCTYPE html><html><head><title>t</title></head><body><p>x</p>"
                        "</body></html>") == []


def test_run_writes_a_self_contained_report_that_rerenders_identically(tmp_path):
    """A run's report.html: parses without errors, references nothing outside itself, puts
    the verdict table before the provenance and the rest, captions every figure with metric,
    unit, statistic and pixel relation, and is byte-identical when drawn again."""
    out = tmp_path / "r"
    montecarlo.run(SMALL).report(out)
    first = (out / "report.html").read_bytes()
    text = first.decode()
    assert parse_errors(text) == []
    assert external_references(text) == []
    heads = re.findall(r"<h2>(.*?)</h2>", text)
    assert heads[:3] == ["Spec", "Provenance", "Assumptions"]
    assert "Nominal case" in heads
    captions = re.findall(r"<figcaption>(.*?)</figcaption>", text, re.S)
    plots = sorted((out / "plots").iterdir())
    assert len(captions) == text.count("<img") == len(plots) >= 2
    for plot in plots:  # each figure drawn once: the report holds the plot file's bytes
        assert base64.b64encode(plot.read_bytes()).decode() in text
    for c in captions:
        assert "<code>rotation_angle</code>" in c and "[mrad]" in c
        assert "Pixel relation between targets A and B: independent" in c
        assert re.search(r"p95|max", c)
    rerender(out)
    assert (out / "report.html").read_bytes() == first


ROOT = Path(__file__).parent.parent
SHIPPED = sorted(p.stem for p in (ROOT / "studies").glob("*.toml"))


@pytest.mark.slow
@pytest.mark.parametrize("name", SHIPPED)
def test_every_shipped_study_report_is_self_contained_and_deterministic(tmp_path, name):
    """The acceptance check on every shipped study, at few trials (the report's form does
    not depend on the trial count): no parse error, no external reference, the same bytes
    after `montecarlo report`. Prints the size."""
    out = tmp_path / name
    run = [sys.executable, "-m", "montecarlo"]
    trials = {"stabilization": "4", "collimation_layout": "16"}.get(name, "256")
    done = subprocess.run([*run, "run", f"studies/{name}.toml", "--trials", trials, "-q",
                           "--out", str(out)], capture_output=True, text=True, timeout=1800,
                          cwd=ROOT)
    assert done.returncode == 0, done.stderr[-2000:]
    first = (out / "report.html").read_bytes()
    text = first.decode()
    assert parse_errors(text) == []
    assert external_references(text) == []
    done = subprocess.run([*run, "report", str(out), "-q"], capture_output=True, text=True,
                          timeout=1800)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (out / "report.html").read_bytes() == first
    print(f"{name}: report.html {len(first):,} bytes, {text.count('<figure')} figures")
