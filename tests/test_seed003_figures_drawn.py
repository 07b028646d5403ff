"""What seed 003's Figs. 3-6 and the procedure figure draw, read through matplotlib's objects
(lines, axes, legends, titles), not pixels: every curve's data against closed forms written out
here (first order in the offsets, docs/reference/collimation.md) and against the deviation it is
said to
plot, its style and colour, the axis labels with their units, and which panels are marked zero."""

import math

import numpy as np
import pytest
from matplotlib.colors import to_rgba
from matplotlib.layout_engine import ConstrainedLayoutEngine

from montecarlo.seed003 import figures as figs
from montecarlo.seed003 import reference as ref
from montecarlo.units import ARCSEC

OFFSETS_DEG = (0.02, 0.05, 0.1)
TITLES = {
    "fig3": "seed 003, Fig. 3: horizontal pair, azimuth offset γ",
    "fig4": "seed 003, Fig. 4: horizontal pair, pitch offset λ",
    "fig5": "seed 003, Fig. 5: vertical pair, azimuth offset γ",
    "fig6": "seed 003, Fig. 6: vertical pair, pitch offset λ",
}


@pytest.fixture
def pair():
    return figs.pair_figures()


def _page(fig):
    """A 9 x 3.8 inch figure, constrained layout, two panels side by side."""
    assert tuple(fig.get_size_inches()) == (9.0, 3.8)
    assert isinstance(fig.get_layout_engine(), ConstrainedLayoutEngine)
    assert len(fig.axes) == 2
    left, right = fig.axes
    assert left.get_position().x0 < right.get_position().x0
    for ax in fig.axes:  # a faint grid on both axes
        for line in (*ax.xaxis.get_gridlines(), *ax.yaxis.get_gridlines()):
            assert line.get_visible() and line.get_alpha() == 0.3


def _style(line, linestyle, colour):
    assert line.get_linestyle() == linestyle
    assert to_rgba(line.get_color()) == to_rgba(colour)


def _legend(ax, labels):
    legend = ax.get_legend()
    assert legend is not None
    assert [t.get_text() for t in legend.get_texts()] == labels
    assert all(t.get_fontsize() == 7 for t in legend.get_texts())


def test_pair_figures_are_four_pages_titled_as_the_paper(pair):
    assert list(pair) == ["fig3", "fig4", "fig5", "fig6"]
    for name, fig in pair.items():
        _page(fig)
        assert fig._suptitle.get_text() == TITLES[name]


def test_pair_figure_curves_are_the_deviations_in_arc_seconds(pair):
    """Figs. 3-4 on alpha = 0, 0.5, ..., 180 deg, Figs. 5-6 on beta = 0, 0.25, ..., 80 deg (321
    points). Per panel, for each offset 0.02, 0.05, 0.1 deg (colours C0, C1, C2): solid the
    attitude change in the INS frame, dotted the difference of readings; left delta alpha, right
    delta beta, in arc-seconds. Closed forms (first order, docs/reference/collimation.md): Fig. 4
    solid
    right ``lambda (cos alpha - 1)`` (-2 lambda at 180 deg) and dotted right 0; Fig. 5 left
    ``-gamma (1/cos beta - 1)`` in both views; the rest of order offset^2 (Figs. 3 and 6: zero,
    below 1e-6″). Tolerance: second order, 4 offset^2 / cos^2 (the largest angle) [rad]."""
    for name in pair:
        _pair_curves(pair, name)


def _pair_curves(pair, name):
    kind, offset_name = figs.FIGURES[name][:2]
    fig = pair[name]
    left, right = fig.axes
    top = 180.0 if kind == "horizontal" else 80.0
    symbol = "α" if kind == "horizontal" else "β"
    grid = np.arange(321) * (top / 320)
    assert left.get_xlabel() == right.get_xlabel() == f"mirror angle {symbol} [deg]"
    assert left.get_ylabel() == "Δα (azimuth) [arc-seconds]"
    assert right.get_ylabel() == "Δβ (pitch) [arc-seconds]"
    labels = [f"{v}° ({w})" for v in OFFSETS_DEG for w in ("INS frame", "readings")]
    _legend(left, labels)
    assert right.get_legend() is None
    x = np.radians(grid)
    for j, ax in enumerate((left, right)):
        assert len(ax.lines) == 6
        for i, line in enumerate(ax.lines):
            value, view = OFFSETS_DEG[i // 2], ("body", "readings")[i % 2]
            _style(line, ("-", ":")[i % 2], f"C{i // 2}")
            assert line.get_label() == labels[i]
            np.testing.assert_allclose(line.get_xdata(), grid, rtol=0, atol=1e-12)
            y = np.asarray(line.get_ydata())
            want = figs.pair_deviation(kind, x, view=view,
                                       **{offset_name: math.radians(value)})[j] / ARCSEC
            np.testing.assert_allclose(y, want, rtol=1e-12, atol=1e-9)
            o = math.radians(value)
            first = np.zeros_like(x)
            if name == "fig4" and j == 1 and view == "body":
                first = o * (np.cos(x) - 1.0)
            elif name == "fig5" and j == 0:
                first = -o * (1.0 / np.cos(x) - 1.0)
            tol = 4 * o**2 / math.cos(math.radians(top if kind == "vertical" else 0.0)) ** 2
            np.testing.assert_allclose(y, first / ARCSEC, rtol=0, atol=tol / ARCSEC)
            if name in ("fig3", "fig6"):
                assert np.max(np.abs(y)) < 1e-6
    if name == "fig4":  # -2 lambda at 180 deg, on the solid curve of 0.1 deg
        assert right.lines[4].get_ydata()[-1] == pytest.approx(-720.0, abs=1e-2)


def test_zero_panels_are_drawn_on_one_arc_second_and_say_how_small(pair):
    """A panel whose largest |deviation| is below 1e-6″ is drawn on [-1″, 1″] and titled
    "zero (largest 1e-xx″)" with that largest value (read here from its curves), in 9 pt; the
    others keep matplotlib's limits (around their data) and no title."""
    for name, ax in ((name, ax) for name, fig in pair.items() for ax in fig.axes):
        largest = max(float(np.max(np.abs(line.get_ydata()))) for line in ax.lines)
        if name in ("fig3", "fig6"):
            assert largest < 1e-6
            assert ax.get_ylim() == (-1.0, 1.0)
            assert ax.get_title() == f"zero (largest {largest:.0e}″)"
            assert ax.title.get_fontsize() == 9
        else:
            assert largest > 0.5
            low, high = ax.get_ylim()
            assert low < high and high - low >= largest and (low, high) != (-1.0, 1.0)
            assert ax.get_title() == ""


def _procedure_closed_forms(offset, az, el):
    """First order, level mount, central mirror (0, 0), roll mirror at 90 deg on the right (s =
    1), docs/reference/collimation.md: a horizontal mirror at azimuth alpha reads pitch
    ``-lambda (1 - cos alpha - sin alpha)`` and heading alpha (gamma drops out); a mirror at
    azimuth 0 and elevation e reads heading ``-gamma (1/cos e - 1) - lambda tan e`` and pitch
    e. Rows: gamma = offset, then lambda = offset."""
    out = []
    for gamma, lam in ((offset, 0.0), (0.0, offset)):
        out.append({"pitch_h": -lam * (1 - np.cos(az) - np.sin(az)), "heading_h": 0 * az,
                    "heading_v": -gamma * (1 / np.cos(el) - 1) - lam * np.tan(el),
                    "pitch_v": 0 * el})
    return out


@pytest.mark.parametrize("offset_arcsec", [300.0, 150.0])
def test_procedure_figure_draws_exact_and_first_order_curves(offset_arcsec):
    """Left: horizontal mirrors at azimuth -90, -89, ..., 180 deg; right: mirrors at azimuth 0,
    elevation 0, 0.5, ..., 70 deg. For gamma (C0) then lambda (C1) = the offset: solid the exact
    relative reading minus the mirror angle (pitch left, heading right), dashed its first order
    (the closed forms, to rounding), dotted the other reading minus its mirror angle (zero to
    first order). Exact minus first order is of second order or higher: at half the offset it
    is a quarter (second order) or an eighth (third), to 1 %, the 300″ figure against the 150″
    one."""
    offset = offset_arcsec * ARCSEC
    fig = figs.procedure_figure(offset)
    _page(fig)
    assert fig._suptitle.get_text() == (
        f"seed 003, section 3.2 procedure: offset {offset_arcsec:.0f}″ (solid exact, dashed "
        "first order), level mount, roll mirror right")
    left, right = fig.axes
    assert left.get_xlabel() == "horizontal mirror: azimuth from the central mirror [deg]"
    assert right.get_xlabel() == "mirror at azimuth 0: elevation [deg]"
    for ax in (left, right):
        assert ax.get_ylabel() == "relative reading - mirror angle [arc-seconds]"
        assert len(ax.lines) == 6
    _legend(left, ["γ pitch", "γ heading", "λ pitch", "λ heading"])
    _legend(right, ["γ heading", "γ pitch", "λ heading", "λ pitch"])
    az_deg, el_deg = np.arange(-90.0, 181.0), np.arange(141) * 0.5
    az, el = np.radians(az_deg), np.radians(el_deg)
    forms = _procedure_closed_forms(offset, az, el)
    second = {}
    for k, form in enumerate(forms):
        colour = f"C{k}"
        solid, dashed, dotted = left.lines[3 * k: 3 * k + 3]
        for line, style in ((solid, "-"), (dashed, "--"), (dotted, ":")):
            _style(line, style, colour)
            np.testing.assert_allclose(line.get_xdata(), az_deg, rtol=0, atol=1e-12)
        assert dashed.get_label().startswith("_")  # not in the legend
        np.testing.assert_allclose(dashed.get_ydata(), form["pitch_h"] / ARCSEC, atol=1e-9)
        second[(k, "pitch_h")] = np.asarray(solid.get_ydata()) - form["pitch_h"] / ARCSEC
        second[(k, "heading_h")] = np.asarray(dotted.get_ydata()) - form["heading_h"] / ARCSEC
        solid, dashed, dotted = right.lines[3 * k: 3 * k + 3]
        for line, style in ((solid, "-"), (dashed, "--"), (dotted, ":")):
            _style(line, style, colour)
            np.testing.assert_allclose(line.get_xdata(), el_deg, rtol=0, atol=1e-12)
        assert dashed.get_label().startswith("_")
        np.testing.assert_allclose(dashed.get_ydata(), form["heading_v"] / ARCSEC, atol=1e-9)
        second[(k, "heading_v")] = np.asarray(solid.get_ydata()) - form["heading_v"] / ARCSEC
        second[(k, "pitch_v")] = np.asarray(dotted.get_ydata()) - form["pitch_v"] / ARCSEC
    # against the exact model at the figure's points (level mount, roll mirror right)
    h, p, _ = ref.relative_readings(0.0, offset, az, 0 * az, 0.0, (0.0, 0.0, 0.0),
                                    (math.pi / 2, 0.0, 0.0))
    np.testing.assert_allclose(left.lines[3].get_ydata(), p / ARCSEC, rtol=1e-12, atol=1e-9)
    h, p, _ = ref.relative_readings(offset, 0.0, 0 * el, el, 0.0, (0.0, 0.0, 0.0),
                                    (math.pi / 2, 0.0, 0.0))
    np.testing.assert_allclose(right.lines[0].get_ydata(), h / ARCSEC, rtol=1e-12, atol=1e-9)
    if offset_arcsec == 300.0:
        ratios = {}
        half = figs.procedure_figure(offset / 2)
        forms_half = _procedure_closed_forms(offset / 2, az, el)
        for (k, what), d in second.items():
            ax = half.axes[0] if what.endswith("_h") else half.axes[1]
            line = ax.lines[3 * k + (0 if what in ("pitch_h", "heading_v") else 2)]
            d_half = np.asarray(line.get_ydata()) - forms_half[k][what] / ARCSEC
            big = np.max(np.abs(d))
            if big > 1e-3:  # some rows are zero to rounding (e.g. gamma's pitch at el 0)
                ratios[(k, what)] = float(big / np.max(np.abs(d_half)))
        # second order (ratio 4); the headings at the pitch mirrors third (8); lambda's pitch
        # on the horizontal mirrors and gamma's dotted heading stay below 1e-3″
        want = {(0, "heading_v"): 8.0, (0, "pitch_v"): 4.0, (1, "heading_h"): 4.0,
                (1, "heading_v"): 8.0, (1, "pitch_v"): 4.0}
        assert ratios == pytest.approx(want, rel=1e-2)
