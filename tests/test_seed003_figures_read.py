"""What a user reads from seed 003's section-2 statements and Figs. 3-6: the values against
their first-order closed forms, the verdicts, and the figures' titles, labels and curves."""

import math

import numpy as np
import pytest

from montecarlo.seed003 import figures as figs
from montecarlo.units import ARCSEC

OFFSET = math.radians(0.1)


def test_paper_statements_values_by_hand():
    """Offset 0.1 deg. Horizontal pair, lambda: delta beta = -lambda (1 - cos alpha), largest 2
    at 180 deg; vertical pair, gamma: delta alpha = -gamma (1/cos beta - 1), 1/cos 85 - 1 =
    10.474 at the end of the range and -1 at 60 deg, where delta beta is 0. Offsets along the
    mirror plane leave 0. The readings' difference at 180 deg shows no pitch change (both
    mirrors are read at pitch -lambda). Tolerance: first order, relative error ~ the offset
    (1.7e-3)."""
    rows = figs.paper_statements()
    model = [r["model"] for r in rows]
    expected = [0.0, 2.0, None, -2.0, 0.0, 0.0, 1 / math.cos(math.radians(85.0)) - 1, 0.0, -1.0]
    for i, (got, want) in enumerate(zip(model, expected, strict=True)):
        if want is not None:
            assert got == pytest.approx(want, rel=2e-3, abs=2e-3), rows[i]["quantity"]
    # second order: |delta alpha| / lambda and delta beta(60) / gamma of the order of the offset
    assert 0.5 * OFFSET < model[2] < 2 * OFFSET and 0.5 * OFFSET < model[7] < 2 * OFFSET
    assert [r["holds"] for r in rows] == [True, True, None, True, False, True, True, False, True]
    assert all(isinstance(r["holds"], bool) for i, r in enumerate(rows) if i != 2)
    assert all(isinstance(r["model"], float) for r in rows)
    assert rows[3]["statement"] == "at α = 180°, Δβ is almost twice λ"
    assert rows[3]["quantity"] == "Δβ(180°) / λ"
    assert rows[7]["statement"] == "at β = 60°, Δβ is almost equal to γ"
    # a larger offset moves the second-order values only
    assert figs.paper_statements(math.radians(0.2))[3]["model"] == pytest.approx(-2.0, abs=4e-3)


def test_pair_deviation_refuses_unknown_kinds_and_views():
    with pytest.raises(ValueError, match=r"^kind must be 'horizontal' or 'vertical', not 'x'$"):
        figs.pair_deviation("x", 0.1)
    with pytest.raises(ValueError, match=r"^view must be 'body' or 'readings', not 'x'$"):
        figs.pair_deviation("horizontal", 0.1, view="x")


def _largest(ax):
    return max(float(np.max(np.abs(line.get_ydata()))) for line in ax.lines)


def test_pair_figures_titles_labels_and_curves():
    """Three offsets (0.02, 0.05, 0.1 deg) x two views per panel, in arc-seconds: Fig. 4's pitch
    panel reaches 2 lambda = 720″ for 0.1 deg, Fig. 5's azimuth panel
    gamma (1/cos 80 - 1) = 1713″; Figs. 3 and 6 are zero, drawn on +-1″ and titled so."""
    out = figs.pair_figures()
    assert list(out) == ["fig3", "fig4", "fig5", "fig6"]
    assert out["fig4"]._suptitle.get_text() == "seed 003, Fig. 4: horizontal pair, pitch offset λ"
    for name, fig in out.items():
        left, right = fig.axes
        symbol = "α" if name in ("fig3", "fig4") else "β"
        assert left.get_xlabel() == right.get_xlabel() == f"mirror angle {symbol} [deg]"
        assert left.get_ylabel() == "Δα (azimuth) [arc-seconds]"
        assert right.get_ylabel() == "Δβ (pitch) [arc-seconds]"
        assert len(left.lines) == len(right.lines) == 6
        assert left.lines[0].get_xdata()[-1] == (180.0 if symbol == "α" else 80.0)
    assert _largest(out["fig4"].axes[1]) == pytest.approx(720.0, rel=2e-3)
    gamma = 0.1 * 3600
    assert _largest(out["fig5"].axes[0]) == pytest.approx(
        gamma * (1 / math.cos(math.radians(80.0)) - 1), rel=5e-3)
    for name in ("fig3", "fig6"):
        for ax in out[name].axes:
            assert ax.get_ylim() == (-1.0, 1.0)
            assert ax.get_title().startswith("zero (largest ")
    assert out["fig4"].axes[1].get_ylim() != (-1.0, 1.0) and out["fig4"].axes[1].get_title() == ""
    labels = [line.get_label() for line in out["fig4"].axes[0].lines]
    assert labels == ["0.02° (INS frame)", "0.02° (readings)", "0.05° (INS frame)",
                      "0.05° (readings)", "0.1° (INS frame)", "0.1° (readings)"]
    assert out["fig4"].axes[0].lines[1].get_linestyle() == ":"


def test_procedure_figure_curves_by_hand():
    """Offset 300″, level mount: a horizontal mirror at 180 deg reads pitch
    -lambda (1 - cos 180 - sin 180) = -600″; a mirror at elevation 70 deg reads heading
    -gamma (1/cos 70 - 1) = -577″ (first order; exact within 1″)."""
    fig = figs.procedure_figure()
    assert fig._suptitle.get_text() == ("seed 003, section 3.2 procedure: offset 300″ (solid "
                                        "exact, dashed first order), level mount, roll mirror "
                                        "right")
    left, right = fig.axes
    assert left.get_xlabel() == "horizontal mirror: azimuth from the central mirror [deg]"
    assert right.get_xlabel() == "mirror at azimuth 0: elevation [deg]"
    by_label = {line.get_label(): line for line in left.lines}
    lam_pitch = by_label["λ pitch"]
    assert lam_pitch.get_xdata()[-1] == pytest.approx(180.0)
    assert lam_pitch.get_ydata()[-1] == pytest.approx(-600.0, abs=1.0)
    dashed = left.lines[4]  # lambda, first order
    assert dashed.get_linestyle() == "--" and dashed.get_ydata()[-1] == pytest.approx(-600.0)
    gamma_heading = {line.get_label(): line for line in right.lines}["γ heading"]
    assert gamma_heading.get_xdata()[-1] == pytest.approx(70.0)
    assert gamma_heading.get_ydata()[-1] == pytest.approx(
        -300 * (1 / math.cos(math.radians(70.0)) - 1), abs=1.0)
    assert figs.procedure_figure(100 * ARCSEC)._suptitle.get_text().startswith(
        "seed 003, section 3.2 procedure: offset 100″")


def test_paper_statements_are_the_texts_a_user_reads():
    """The statements of seed 003, section 2, in the text's order, with what each row shows."""
    rows = figs.paper_statements()
    assert [(r["statement"], r["quantity"]) for r in rows] == [
        ("horizontal pair, azimuth offset: INS change almost equals the mirror change",
         "max |Δα|, |Δβ| over α in [0, 180°] / γ"),
        ("horizontal pair, pitch offset: clear difference, especially in pitch",
         "max |Δβ| / λ (max |Δα| / λ in the next row)"),
        ("(same)", "max |Δα| / λ"),
        ("at α = 180°, Δβ is almost twice λ", "Δβ(180°) / λ"),
        ("(same, with differences of the reported pitch)", "Δβ(180°) / λ, readings"),
        ("vertical pair, pitch offset: INS change almost equals the mirror change",
         "max |Δα|, |Δβ| over β in [0, 85°] / λ"),
        ("vertical pair, azimuth offset: clear difference, especially in azimuth",
         "max |Δα| / γ over β in [0, 85°]"),
        ("at β = 60°, Δβ is almost equal to γ", "Δβ(60°) / γ"),
        ("(the same read as Δα)", "Δα(60°) / γ"),
    ]
    assert list(rows[0]) == ["statement", "quantity", "model", "holds"]
