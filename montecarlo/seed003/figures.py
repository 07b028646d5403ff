"""Seed 003, section 2: the mirror-pair deviations of Figs. 3-6 and the text's statements.

References
----------
seed 003, section 2 (Figs. 3-6); docs/reference/collimation.md; docs/reference/references.md.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from montecarlo.seed003.model import (
    attitude_angles,
    attitude_matrix,
    predict_readings,
    wrap,
)
from montecarlo.units import ARCSEC

if TYPE_CHECKING:
    from matplotlib.figure import Figure

FloatArray = NDArray[np.float64]


# --------------------------------------------------------------------------- Figs. 3-6


def pair_deviation(kind: str, angle: ArrayLike, axis_az: float = 0.0, axis_el: float = 0.0,
                   view: str = "body") -> tuple[FloatArray, FloatArray]:
    """Deviations (delta_alpha, delta_beta) of the INS attitude change for a mirror pair.

    Mirror 1 at azimuth 0, elevation 0; mirror 2 at azimuth ``angle`` (``kind="horizontal"``,
    mirror change: azimuth alpha, pitch 0) or elevation ``angle`` (``"vertical"``: azimuth 0,
    pitch beta). The INS autocollimates both on a level mount (roll 0), reference frames
    aligned. Deviation = INS attitude change - mirror attitude change.

    ``view="body"``: the INS attitude change is the rotation ``C_1^T C_2`` between the two INS
    attitudes, resolved in the INS frame at mirror 1, as heading and pitch (Z-X-Y): this
    reproduces the paper's figures. ``view="readings"``: differences of the reported heading
    and pitch.

    Returns
    -------
    delta_alpha, delta_beta : ndarray [rad]

    References
    ----------
    seed 003, section 2, Figs. 3-4 (horizontal pair) and 5-6 (vertical pair).
    """
    angle = np.asarray(angle, float)
    zero = np.zeros_like(angle)
    if kind == "horizontal":
        az2, el2, change = angle, zero, (angle, zero)
    elif kind == "vertical":
        az2, el2, change = zero, angle, (zero, angle)
    else:
        raise ValueError(f"kind must be 'horizontal' or 'vertical', not {kind!r}")
    params = {"axis_az": axis_az, "axis_el": axis_el}
    h1, p1 = predict_readings(params, zero, zero)
    h2, p2 = predict_readings(params, az2, el2)
    if view == "body":
        rel = np.swapaxes(attitude_matrix(h1, p1, 0.0), -1, -2) @ attitude_matrix(h2, p2, 0.0)
        dh, dp, _ = attitude_angles(rel)
    elif view == "readings":
        dh, dp = h2 - h1, p2 - p1
    else:
        raise ValueError(f"view must be 'body' or 'readings', not {view!r}")
    return wrap(dh - change[0]), dp - change[1]


FIGURES = {
    "fig3": ("horizontal", "axis_az", "Fig. 3: horizontal pair, azimuth offset γ"),
    "fig4": ("horizontal", "axis_el", "Fig. 4: horizontal pair, pitch offset λ"),
    "fig5": ("vertical", "axis_az", "Fig. 5: vertical pair, azimuth offset γ"),
    "fig6": ("vertical", "axis_el", "Fig. 6: vertical pair, pitch offset λ"),
}
"""Figs. 3-6 of seed 003: mirror pair and which offset is non-zero."""

FIGURE_OFFSETS_DEG = (0.02, 0.05, 0.1)


def pair_figures() -> dict[str, Figure]:
    """Figs. 3-6 as matplotlib figures, keyed ``fig3`` ... ``fig6``.

    Solid: attitude change in the INS frame (``view="body"``); dotted: difference of readings.
    """
    from matplotlib.figure import Figure

    figures = {}
    for name, (kind, offset, title) in FIGURES.items():
        top = 180.0 if kind == "horizontal" else 80.0
        deg = np.linspace(0.0, top, 321)
        fig = Figure(figsize=(9, 3.8), layout="constrained")
        axes = fig.subplots(1, 2)
        largest = [0.0, 0.0]
        for k, value in enumerate(FIGURE_OFFSETS_DEG):
            color = f"C{k}"
            for view, style in (("body", "-"), ("readings", ":")):
                dev = pair_deviation(kind, np.radians(deg), view=view,
                                     **{offset: math.radians(value)})
                label = f"{value}° ({'INS frame' if view == 'body' else 'readings'})"
                for j in (0, 1):
                    axes[j].plot(deg, dev[j] / ARCSEC, style, color=color, label=label)
                    largest[j] = max(largest[j], float(np.max(np.abs(dev[j]))) / ARCSEC)
        symbol = "α" if kind == "horizontal" else "β"
        for j, what in enumerate(("Δα (azimuth)", "Δβ (pitch)")):
            axes[j].set_xlabel(f"mirror angle {symbol} [deg]")
            axes[j].set_ylabel(f"{what} [arc-seconds]")
            axes[j].grid(alpha=0.3)
            if largest[j] < 1e-6:
                axes[j].set_ylim(-1.0, 1.0)
                axes[j].set_title(f"zero (largest {largest[j]:.0e}″)", fontsize=9)
        axes[0].legend(fontsize=7)
        fig.suptitle(f"seed 003, {title}")
        figures[name] = fig
    return figures


def procedure_figure(offset: float = 300.0 * ARCSEC) -> Figure:
    """The procedure's relative readings minus the mirror angles, exact and first order.

    Left: horizontal mirrors against azimuth (pitch error from lambda through the reference);
    right: mirrors at azimuth 0 against elevation (heading error from gamma and lambda). Level
    mount, central mirror at (0, 0), roll mirror at (90 deg, 0) on the right; solid: exact
    (:func:`montecarlo.seed003.reference.relative_readings`), dashed: first order
    (:func:`montecarlo.seed003.reference.first_order_readings`).
    """
    from matplotlib.figure import Figure

    from montecarlo.seed003 import reference as ref

    fig = Figure(figsize=(9, 3.8), layout="constrained")
    axes = fig.subplots(1, 2)
    center, mirror = (0.0, 0.0, 0.0), (math.pi / 2, 0.0, 0.0)
    az = np.radians(np.linspace(-90.0, 180.0, 271))
    el = np.radians(np.linspace(0.0, 70.0, 141))
    for k, (label, gamma, lam) in enumerate((("γ", offset, 0.0), ("λ", 0.0, offset))):
        color = f"C{k}"
        h, p, _ = ref.relative_readings(gamma, lam, az, 0 * az, 0.0, center, mirror)
        h1, p1 = ref.first_order_readings(gamma, lam, az, 0 * az)
        axes[0].plot(np.degrees(az), p / ARCSEC, "-", color=color, label=f"{label} pitch")
        axes[0].plot(np.degrees(az), p1 / ARCSEC, "--", color=color)
        axes[0].plot(np.degrees(az), wrap(h - az) / ARCSEC, ":", color=color,
                     label=f"{label} heading")
        h, p, _ = ref.relative_readings(gamma, lam, 0 * el, el, 0.0, center, mirror)
        h1, p1 = ref.first_order_readings(gamma, lam, 0 * el, el)
        axes[1].plot(np.degrees(el), wrap(h) / ARCSEC, "-", color=color, label=f"{label} heading")
        axes[1].plot(np.degrees(el), wrap(h1) / ARCSEC, "--", color=color)
        axes[1].plot(np.degrees(el), (p - el) / ARCSEC, ":", color=color, label=f"{label} pitch")
    axes[0].set_xlabel("horizontal mirror: azimuth from the central mirror [deg]")
    axes[1].set_xlabel("mirror at azimuth 0: elevation [deg]")
    for a in axes:
        a.set_ylabel("relative reading - mirror angle [arc-seconds]")
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
    fig.suptitle(f"seed 003, section 3.2 procedure: offset {offset / ARCSEC:.0f}″ "
                 "(solid exact, dashed first order), level mount, roll mirror right")
    return fig


def paper_statements(offset: float = math.radians(0.1)) -> list[dict[str, object]]:
    """Each statement of seed 003, section 2, evaluated with the model (offset ``offset`` [rad]).

    Returns
    -------
    list of dict with ``statement``, ``quantity``, ``model`` (value in units of the offset
    unless said otherwise) and ``holds`` (bool; None for a row shown with the claim of the
    row above), in the order of the text.
    """
    a = np.radians(np.linspace(0.0, 180.0, 721))
    b = np.radians(np.linspace(0.0, 85.0, 341))
    out = []

    def add(statement, quantity, value, holds):
        out.append({"statement": statement, "quantity": quantity, "model": float(value),
                    "holds": None if holds is None else bool(holds)})

    h_g = np.abs(pair_deviation("horizontal", a, axis_az=offset))
    add("horizontal pair, azimuth offset: INS change almost equals the mirror change",
        "max |Δα|, |Δβ| over α in [0, 180°] / γ", np.max(h_g) / offset, np.max(h_g) < 0.05 * offset)
    da, db = pair_deviation("horizontal", a, axis_el=offset)
    add("horizontal pair, pitch offset: clear difference, especially in pitch",
        "max |Δβ| / λ (max |Δα| / λ in the next row)", np.max(np.abs(db)) / offset,
        np.max(np.abs(db)) > 10 * np.max(np.abs(da)))
    add("(same)", "max |Δα| / λ", np.max(np.abs(da)) / offset, None)  # the row above's claim
    _, db180 = pair_deviation("horizontal", math.pi, axis_el=offset)
    add("at α = 180°, Δβ is almost twice λ", "Δβ(180°) / λ", db180 / offset,
        abs(abs(db180) / offset - 2.0) < 0.05)
    _, db180r = pair_deviation("horizontal", math.pi, axis_el=offset, view="readings")
    add("(same, with differences of the reported pitch)", "Δβ(180°) / λ, readings",
        db180r / offset, abs(abs(db180r) / offset - 2.0) < 0.05)
    v_l = np.abs(pair_deviation("vertical", b, axis_el=offset))
    add("vertical pair, pitch offset: INS change almost equals the mirror change",
        "max |Δα|, |Δβ| over β in [0, 85°] / λ", np.max(v_l) / offset, np.max(v_l) < 0.05 * offset)
    da, db = pair_deviation("vertical", b, axis_az=offset)
    add("vertical pair, azimuth offset: clear difference, especially in azimuth",
        "max |Δα| / γ over β in [0, 85°]", np.max(np.abs(da)) / offset,
        np.max(np.abs(da)) > 10 * np.max(np.abs(db)))
    da60, db60 = pair_deviation("vertical", math.radians(60.0), axis_az=offset)
    add("at β = 60°, Δβ is almost equal to γ", "Δβ(60°) / γ", db60 / offset,
        abs(abs(db60) / offset - 1.0) < 0.05)
    add("(the same read as Δα)", "Δα(60°) / γ", da60 / offset, abs(abs(da60) / offset - 1.0) < 0.05)
    return out
