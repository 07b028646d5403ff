"""Figures drawn on calibration photographs: the contact sheet of detected corners, and each
view's residual vectors on its own image."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from montecarlo.camera_calibration.detect import Detection, read_grey, view_label
from montecarlo.discrepancy.problem import OUTLIER
from montecarlo.io.camera_csv import CameraData
from montecarlo.io.files import save_figure

if TYPE_CHECKING:
    from montecarlo.discrepancy.engine import Diagnosis

FloatArray = NDArray[np.float64]

COLUMNS = 4
"""Images per row of a sheet."""
PER_PAGE = 12
"""Views per figure of residuals on images (more views: more figures)."""


def _grid(n: int, width: float) -> tuple[object, NDArray[np.object_]]:
    from matplotlib.figure import Figure

    cols = min(COLUMNS, n)
    rows = math.ceil(n / cols)
    fig = Figure(figsize=(width * cols, width * 0.8 * rows + 0.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False).ravel())
    for ax in axes[n:]:
        ax.set_axis_off()
    return fig, axes


def _show(ax, image: NDArray[np.uint8], alpha: float = 1.0) -> None:
    h, w = image.shape
    ax.imshow(image, cmap="gray", vmin=0, vmax=255, alpha=alpha, interpolation="antialiased",
              extent=(-0.5, w - 0.5, h - 0.5, -0.5))
    ax.set_xticks([])
    ax.set_yticks([])


def contact_sheet(paths: Sequence[str | Path], found: Sequence[Detection], board_text: str,
                  path: Path) -> Path:
    """Every image with its detected corners numbered by id (id 0 ringed, an arrow from id 0
    to id 1 along +X); an image where the board was not found says so in red."""
    by_path = {Path(d.path): d for d in found}
    fig, axes = _grid(len(paths), 4.8)
    for ax, image_path in zip(axes, paths, strict=False):
        _show(ax, read_grey(image_path))
        d = by_path.get(Path(image_path))
        name = view_label(image_path)
        if d is None:
            ax.set_title(f"{name}: board not found", color="C3", fontsize=9)
            continue
        ax.plot(d.pixels[:, 0], d.pixels[:, 1], "+", color="C1", ms=5, mew=0.8)
        for k, (u, v) in zip(d.ids, d.pixels, strict=True):
            ax.annotate(str(k), (u, v), xytext=(2, 2), textcoords="offset points",
                        fontsize=4.5, color="C0")
        first = int(np.argmin(d.ids))
        ax.plot(*d.pixels[first], "o", ms=9, mfc="none", color="C3", mew=1.2)
        if len(d.ids) > 1 and d.ids[first] + 1 == d.ids[first + 1]:
            ax.annotate("", d.pixels[first + 1], d.pixels[first],
                        arrowprops={"arrowstyle": "->", "color": "C3", "lw": 1.2})
        rule = "" if d.by_colour else "; id 0 by image position"
        ax.set_title(f"{name}: {len(d.ids)} corners{rule}", fontsize=9)
    fig.suptitle(f"{board_text}: {len(found)} of {len(paths)} images; id 0 ringed, arrow "
                 "to id 1 (+X)")
    return save_figure(fig, path, dpi=100)


def nice_scale(largest: float, target: float) -> float:
    """The factor 1, 2 or 5 x 10^k at or below ``target / largest`` (1 if nothing to draw).

    >>> nice_scale(0.5, 30.0), nice_scale(2.0, 30.0)
    (50.0, 10.0)
    """
    if not largest > 0:
        return 1.0
    raw = target / largest
    base = 10.0 ** math.floor(math.log10(raw))
    return max(m * base for m in (1.0, 2.0, 5.0) if m * base <= raw * (1 + 1e-12))


def view_rms(d: Diagnosis, data: CameraData) -> dict[str, tuple[float, int, int]]:
    """Per view: residual RMS under the adapted model [px] (u and v pooled, flagged corners
    left out), corners, flagged corners."""
    from montecarlo.discrepancy.camera_effects import raw_residuals

    res = raw_residuals(data, d.after.params)
    flagged = {t.name[len(OUTLIER):] for t in d.outliers}
    names = np.array([oid for oid, _, _ in d.problem.observations])
    bad = np.isin(names, sorted(flagged))
    out = {}
    for v, label in enumerate(data.views):
        mine = data.view == v
        keep = mine & ~bad
        rms = float(np.sqrt(np.mean(res[keep] ** 2))) if keep.any() else math.nan
        out[label] = (rms, int(mine.sum()), int((mine & bad).sum()))
    return out


def pages(data: CameraData) -> list[tuple[str, ...]]:
    """The views of each residuals-on-images figure, :data:`PER_PAGE` at most."""
    return [data.views[i:i + PER_PAGE] for i in range(0, len(data.views), PER_PAGE)]


def plot_image_residuals(d: Diagnosis, data: CameraData, images: Mapping[str, str | Path],
                         views: Sequence[str], path: Path, page: str = "") -> Path:
    """``views``' residual vectors (measured − adapted model) drawn from their corners on their
    own images, at one scale for every view of the data (a 1, 2, 5 step putting the 95th
    percentile of the unflagged residuals at 8 % of the image; stated in the title, with a key
    arrow), flagged corners circled and named, each view's RMS in its title."""
    from montecarlo.discrepancy.camera_effects import raw_residuals

    res = raw_residuals(data, d.after.params)
    flagged = {t.name[len(OUTLIER):] for t in d.outliers}
    names = [oid for oid, _, _ in d.problem.observations]
    rms = view_rms(d, data)
    height, width = read_grey(images[data.views[0]]).shape
    size = np.hypot(res[:, 0], res[:, 1])
    kept = size[[n not in flagged for n in names]]
    typical = float(np.percentile(kept, 95)) if kept.size else 0.0
    scale = nice_scale(typical, 0.08 * max(width, height))
    key = nice_scale(1.0, typical) if typical > 0 else 1.0  # a 1, 2, 5 step <= typical
    fig, axes = _grid(len(views), 4.4)
    for ax, label in zip(axes, views, strict=False):
        mine = np.flatnonzero(data.view == data.views.index(label))
        _show(ax, read_grey(images[label]), alpha=0.55)
        xy, r = data.pixels[mine], res[mine]
        arrows = ax.quiver(xy[:, 0], xy[:, 1], r[:, 0] * scale, r[:, 1] * scale,
                           color="#ff6a00", angles="xy", scale_units="xy", scale=1.0,
                           width=0.006, headwidth=3.5)
        ax.quiverkey(arrows, 0.82, 0.04, key * scale, f"{key:g} px", labelpos="W",
                     coordinates="axes", color="#ff6a00", labelcolor="#ff6a00",
                     fontproperties={"size": 7})
        for i in mine:
            if names[i] in flagged:
                ax.plot(*data.pixels[i], "o", ms=11, mfc="none", color="C3", mew=1.3)
                ax.annotate(names[i].split("/", 1)[1], data.pixels[i], xytext=(6, 6),
                            textcoords="offset points", fontsize=7, color="C3")
        value, count, bad = rms[label]
        ax.set_title(f"{label}: rms {value:.3f} px ({count} corners"
                     + (f", {bad} flagged" if bad else "") + ")", fontsize=8)
        ax.set_xlim(-0.5, width - 0.5)
        ax.set_ylim(height - 0.5, -0.5)
    fig.suptitle(f"camera: residuals (measured − adapted model) drawn {scale:g} × their size; "
                 f"flagged corners circled; rms per coordinate{page}", fontsize=10)
    return save_figure(fig, path, dpi=90)


def image_residual_caption(views: str) -> str:
    """Caption of a residuals-on-images figure in report.html."""
    return (f"Residual of every corner (measured − adapted model) [px], drawn from the corner on "
            f"its own photograph at the scale stated in the title, for views {views}; circled: "
            "corners flagged as outliers (left out of the fit); statistic: each corner's own "
            "residual, and per view the RMS per image coordinate (u and v pooled, flagged "
            f"corners left out). Pixel relation: one residual per corner.")
