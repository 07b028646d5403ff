"""``camera detect`` (corners found in photographs, written as the two CSV files) and
``diagnose camera`` (planar-target camera calibration on the discrepancy workflow, from the CSV
files or straight from the photographs)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from montecarlo.cli.common import (
    Parser,
    check_json_option,
    emit_json,
    positive,
    write_provenance,
)
from montecarlo.cli.noise_options import (
    AUTO,
    AUTO_HELP,
    diagnose_scaled,
    positive_or_auto,
    report_entry,
)
from montecarlo.cli.steps import Steps, fit_why
from montecarlo.errors import InputError
from montecarlo.io.files import OutputDir, writable_file

if TYPE_CHECKING:
    from montecarlo.camera_calibration.detect import Board, Detection
    from montecarlo.discrepancy.engine import Diagnosis
    from montecarlo.io.camera_csv import CameraData
    from montecarlo.output.html_report import HtmlFigure


def _unit(unit: str) -> str:
    return "" if unit == "1" else f" {unit}"


HELD_OUT = ("the left-out view's pose is fitted to that view alone, with the intrinsics and "
            "distortion held at the values fitted on the other views: the standard "
            "cross-validation of a camera calibration")

RMS_CONVENTION = ("rms is per image coordinate (u and v pooled); the rms of the 2-D residual "
                  "of a point is sqrt(2) times larger")


def camera_summary(d: Diagnosis) -> dict[str, dict[str, float]]:
    """The final model's camera in Zhang's terms: alpha = f, beta = f (1 + a), gamma, u0, v0
    [px] and the distortion terms, each with its standard error."""
    p, cov, names = d.after.params, d.after.covariance, d.after.names
    se = d.after.stderr
    out = {"alpha": {"value": p["f"], "stderr": se["f"], "unit": "px"}}
    a = p.get("a", 0.0)
    grad = np.zeros(len(names))
    grad[names.index("f")] = 1.0 + a
    if "a" in names:
        grad[names.index("a")] = p["f"]
    out["beta"] = {"value": p["f"] * (1.0 + a), "stderr": float(np.sqrt(grad @ cov @ grad)),
                   "unit": "px"}
    for key, name, unit in (("gamma", "gamma", "px"), ("u0", "cx", "px"), ("v0", "cy", "px"),
                            ("k1", "k1", "1"), ("k2", "k2", "1"), ("k3", "k3", "1"),
                            ("p1", "p1", "1"), ("p2", "p2", "1")):
        out[key] = {"value": p.get(name, 0.0), "stderr": se.get(name, 0.0), "unit": unit}
    return out


def _inputs(args: argparse.Namespace) -> tuple[Path, ...]:
    """The input files: the two CSV files, or the images; InputError for a mix or neither."""
    if args.images:
        if args.model or args.views:
            raise InputError("--images: instead of MODEL.csv VIEWS.csv, not with them")
        for flag, value in (("--board", args.board), ("--square-mm", args.square_mm)):
            if value is None:
                raise InputError(f"{flag}: needed with --images")
        return tuple(Path(p) for p in args.images)
    if not (args.model and args.views):
        raise InputError("diagnose camera: give MODEL.csv VIEWS.csv, or --images with --board "
                         "and --square-mm")
    for flag, value in (("--board", args.board), ("--square-mm", args.square_mm),
                        ("--charuco", args.charuco), ("--marker-mm", args.marker_mm)):
        if value is not None:
            raise InputError(f"{flag}: only with --images")
    return (Path(args.model), Path(args.views))


def _image_figures(staging: Path, det: Detected, d: Diagnosis,
                   md: list[str]) -> dict[str, HtmlFigure]:
    """The corners found (CSV files, contact sheet) and the residuals drawn on each image,
    into ``staging``; their section appended to the report's Markdown ``md``; the figures of
    report.html."""
    from montecarlo.camera_calibration.detect import view_label
    from montecarlo.output import camera_images as ci
    from montecarlo.output.html_report import saved_figure

    write_detected(staging, det)
    images = {view_label(x.path): x.path for x in det.found}
    md += ["## Residuals on the images", "",
           "The corners found are in `model.csv`, `views.csv` and `contact_sheet.png`.", ""]
    figures = {}
    pages = ci.pages(det.data)
    for k, views in enumerate(pages):
        name = f"image_residuals_{k + 1}.png"
        page = f" ({k + 1}/{len(pages)})" if len(pages) > 1 else ""
        ci.plot_image_residuals(d, det.data, images, views, staging / name, page)
        figures[name] = saved_figure(staging / name, ci.image_residual_caption(", ".join(views)))
        md += [f"![residuals on the images{page}]({name})", ""]
    return figures


def diagnose_camera(args: argparse.Namespace) -> int:
    """``diagnose camera MODEL.csv VIEWS.csv``: the pinhole model against distortion, skew,
    aspect ratio and bad corners; the final camera, practical significance, pixel error left."""
    steps = Steps()
    with steps.loading():
        from montecarlo.camera_calibration.calibrate import CalibrationError
        from montecarlo.discrepancy import camera_effects as cam
        from montecarlo.discrepancy.engine import diagnose
        from montecarlo.discrepancy.fit import FitError, fit_model
        from montecarlo.discrepancy.groups import clustering, format_clustering
        from montecarlo.discrepancy.out_of_sample import (
            format_leave_one_out,
            leave_one_group_out,
            markdown_leave_one_out,
        )
        from montecarlo.discrepancy.significance import (
            format_significance,
            practical_significance,
        )
        from montecarlo.discrepancy.view import format_text, to_json
        from montecarlo.io.camera_csv import read_camera_csv
        from montecarlo.io.files import atomic_write_bytes
        from montecarlo.output.provenance import provenance

    inputs = _inputs(args)
    if args.report:
        OutputDir(args.report, "diagnose", inputs=inputs).check()
    check_json_option(args)
    if args.emit_errors:
        writable_file(args.emit_errors, args.force)
    det = detect_views(args, steps) if args.images else None
    if det is None:
        data = read_camera_csv(args.model, args.views)
        source, where = f"{args.model}, {args.views}", str(args.views)
    else:
        data, where = det.data, "--images"
        source = f"{len(det.found)} images ({det.found[0].path} ... {det.found[-1].path})"
    sigma = args.pixel_sigma_px
    noise = None
    try:
        if sigma == AUTO:
            # started at the model with every candidate fitted, then the final model's
            with steps("the diagnosis, the pixel sigma estimated",
                       fit_why(2 * data.n, 13 + 6)):
                d, used, found = diagnose_scaled(
                    lambda s: cam.camera_problem(data, s), "pixel_sigma_px", args.alpha,
                    initial=lambda p: fit_model(p, [c.name for c in cam.CANDIDATES]))
            sigma = used["pixel_sigma_px"]
            noise = report_entry(used, found)
        else:
            with steps("the diagnosis", fit_why(2 * data.n, 4 + 6)):
                d = diagnose(cam.camera_problem(data, sigma), args.alpha)
    except (FitError, CalibrationError) as exc:
        raise InputError(f"{where}: {exc}") from None
    view = cam.report_view(data, sigma)
    report = to_json(d, view, source)
    if noise is not None:
        report["noise_estimate"] = noise
    significance = practical_significance(d, view, cam.INTRINSIC_REPORTED)
    error = cam.pixel_error(d, data, sigma)
    groups = cam.view_groups(data)
    report.update({"rms_convention": RMS_CONVENTION, "camera": camera_summary(d),
                   "practical_significance": significance, "pixel_error": error,
                   "clustering": clustering(d, groups, "view")})
    if args.leave_one_out:
        with steps("leave one view out", "two fits per view and model"):
            report["leave_one_out"] = leave_one_group_out(d, view, groups, "view", HELD_OUT)
    camera = report["camera"]
    lines = [format_text(report), "", RMS_CONVENTION,
             "camera (final model; Zhang's alpha, beta, gamma, u0, v0): " + ", ".join(
                 f"{k} = {v['value']:.6g} ± {v['stderr']:.2g}{_unit(v['unit'])}"
                 for k, v in camera.items() if v["stderr"] > 0),
             format_significance(significance),
             *([format_leave_one_out(report["leave_one_out"], significance)]
               if args.leave_one_out else []),
             format_clustering(report["clustering"]),
             f"pixel error left: sigma u {error['sigma_u']:.4f} px, v {error['sigma_v']:.4f} px;"
             f" remaining distortion up to {error['distortion_bound']:.4f} px "
             f"({error['distortion_source'] or 'none tested'}, at its MDB)"]
    if det is not None:
        lines[:0] = [*det.lines(), ""]
        report["detection"] = det.to_json()
    text = "\n".join(lines)
    record = {"model": str(args.model), "views": str(args.views), "alpha": args.alpha,
              "pixel_sigma_px": sigma} if det is None else {
        "images": list(det.images), "board": f"{det.board.cols}x{det.board.rows}",
        "square_mm": det.board.square, "charuco": det.board.charuco,
        "marker_mm": det.board.marker, "alpha": args.alpha, "pixel_sigma_px": sigma}
    if args.report:
        from montecarlo.output.diagnosis import (  # matplotlib: only for reports
            write_html_report,
            write_report,
        )

        with OutputDir(args.report, "diagnose", inputs=inputs) as staging:
            write_report(staging, d, view, report)
            md = ["# Diagnosis", "", "```", text, "```", "", "![residuals](residuals.png)", "",
                  "![gap](gap.png)", ""]
            if args.leave_one_out:
                md += markdown_leave_one_out(report["leave_one_out"], significance)
            extra = {} if det is None else _image_figures(Path(staging), det, d, md)
            atomic_write_bytes(Path(staging) / "report.md", "\n".join(md).encode())
            write_provenance(staging, "diagnose", **record)
            write_html_report(staging, d, view, extra=extra)
    if args.emit_errors:
        toml = cam.errors_toml(error, source, sigma, d.after.effects)
        atomic_write_bytes(Path(args.emit_errors), toml.encode())
    if emit_json(args, {**report, "provenance": provenance("diagnose", **record)}):
        steps.report(to_stderr=True)
        return 0
    print(text)
    if args.report:
        print(f"report written to {args.report}/ (report.md, report.html, diagnosis.json, "
              "residuals.png, gap.png" + (", image_residuals_*.png, contact_sheet.png, "
                                         "model.csv, views.csv" if det else "") + ")")
    if args.emit_errors:
        print(f"pixel error for a ground study written to {args.emit_errors} "
              "(use: montecarlo size|run ... --errors FILE)")
    steps.report(to_stderr=False)
    return 0


# ---------------------------------------------------------------- corners found in photographs


def board_size(text: str) -> tuple[int, int]:
    """argparse type of ``--board COLSxROWS``."""
    from montecarlo.camera_calibration.detect import parse_board

    try:
        return parse_board(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def detection_options(p: argparse.ArgumentParser, required: bool) -> None:
    """``--board``, ``--square-mm``, ``--charuco``, ``--marker-mm``."""
    p.add_argument("--board", type=board_size, required=required, metavar="COLSxROWS",
                   help="inner corners across and down (where four squares meet), as OpenCV "
                   "counts them: 9x6 for a board of 10x7 squares")
    p.add_argument("--square-mm", type=positive, required=required, metavar="S",
                   help="side of a square [mm]")
    p.add_argument("--charuco", metavar="DICT", help="a ChArUco board with markers from this "
                   "OpenCV dictionary (e.g. DICT_5X5_100); partly seen boards keep their ids")
    p.add_argument("--marker-mm", type=positive, metavar="M",
                   help="side of a ChArUco marker [mm] (with --charuco)")


def _board(args: argparse.Namespace) -> Board:
    from montecarlo.camera_calibration.detect import Board

    if args.charuco and args.marker_mm is None:
        raise InputError("--marker-mm: needed with --charuco (the side of a marker [mm])")
    if args.marker_mm is not None and not args.charuco:
        raise InputError("--marker-mm: only with --charuco")
    if args.marker_mm is not None and args.marker_mm >= args.square_mm:
        raise InputError(f"--marker-mm: {args.marker_mm:g} is not smaller than --square-mm "
                         f"{args.square_mm:g}")
    return Board(*args.board, args.square_mm, args.charuco, args.marker_mm)


@dataclass(frozen=True)
class Detected:
    """The board found in the photographs: the detections, the images where it was not,
    the views as calibration data (model in mm) and the model points."""

    board: Board
    images: tuple[str, ...]
    found: tuple[Detection, ...]
    missing: tuple[Path, ...]
    size: tuple[int, int]
    data: CameraData
    model_xy: np.ndarray

    def to_json(self) -> dict[str, object]:
        return {"board": self.board.describe(), "images": len(self.images),
                "found": [str(d.path) for d in self.found],
                "not_found": [str(p) for p in self.missing],
                "ids_by_colour": [d.path.stem for d in self.found if d.by_colour],
                "corners": self.data.n, "image_size_px": list(self.size)}

    def lines(self) -> list[str]:
        """What was found, which images were left out, and how ids were told."""
        w, h = self.size
        n = len(self.images)
        out = [f"{self.board.describe()}: found in {len(self.found)} of {n} images "
               f"({w}x{h} px), {self.data.n} corners"]
        out.append("board not found (left out): " + (", ".join(str(p) for p in self.missing)
                                                     if self.missing else "none"))
        partial = [f"{d.path.stem} ({len(d.ids)} of {self.board.n})" for d in self.found
                   if len(d.ids) < self.board.n]
        if partial:
            out.append("partly seen (ids from the markers): " + ", ".join(partial))
        if self.board.charuco:
            out.append("ids: from the ChArUco markers")
        elif self.board.symmetric:
            out.append("ids: this board looks the same turned by 180° (or 90°): id 0 is the "
                       "grid corner nearest each image's top-left; the calibration is "
                       "unaffected, but an id names the same physical corner only while the "
                       "board turns less than 90° between views")
        else:
            out.append("ids: id 0 told by the board's colours in every view (the first inner "
                       "square, between ids 0, 1, "
                       f"{self.board.cols}, {self.board.cols + 1}, is the dark one)")
        return out


def detect_views(args: argparse.Namespace, steps: Steps) -> Detected:
    """Find the board of ``args`` in ``args.images``; InputError when the views cannot make a
    calibration (no image shows the board, fewer than three do, two images share a name)."""
    from montecarlo.camera_calibration.detect import charuco_model_points, detect, view_label
    from montecarlo.io.camera_csv import MIN_VIEWS, CameraData

    board = _board(args)
    images = tuple(str(p) for p in args.images)
    seen: dict[str, str] = {}
    for path in images:
        label = view_label(path)
        if label in seen:
            raise InputError(f"{path}: its name {label!r} is also that of {seen[label]} (a "
                             "view is named by its file name)")
        if any(c in label for c in ',"\n'):
            raise InputError(f"{path}: a view's name may not hold a comma or quote")
        seen[label] = path
    with steps("finding the corners", f"OpenCV on {len(images)} images"):
        found, missing, size = detect(list(images), board)
    if not found:
        raise InputError(f"--board {args.board[0]}x{args.board[1]}: no "
                         f"{board.describe()} found in any of the {len(images)} images "
                         f"({images[0]}, ...); count the inner corners (9x6 for 10x7 squares)")
    if len(found) < MIN_VIEWS:
        raise InputError(f"--board {args.board[0]}x{args.board[1]}: found in "
                         f"{len(found)} of {len(images)} images "
                         f"({', '.join(d.path.name for d in found)}), at least {MIN_VIEWS} "
                         "needed for a calibration")
    model = charuco_model_points(board) if board.charuco else board.model_points()
    ids = np.concatenate([d.ids for d in found])
    data = CameraData(
        tuple(view_label(d.path) for d in found), tuple(str(int(k)) for k in ids),
        np.repeat(np.arange(len(found)), [len(d.ids) for d in found]), model[ids] * 1e-3,
        np.concatenate([d.pixels for d in found]), np.arange(len(ids)) + 2, "mm")
    return Detected(board, images, tuple(found), tuple(missing), size, data, model)


def write_detected(directory: Path, det: Detected) -> list[str]:
    """``model.csv``, ``views.csv`` and ``contact_sheet.png`` into ``directory``."""
    from montecarlo.io.camera_csv import write_camera_csv
    from montecarlo.output.camera_images import contact_sheet

    ids = [str(k) for k in range(len(det.model_xy))]
    write_camera_csv(directory / "model.csv", directory / "views.csv", ids, det.model_xy,
                     "mm", det.data)
    contact_sheet(det.images, det.found, det.board.describe(),
                  directory / "contact_sheet.png")
    return ["model.csv", "views.csv", "contact_sheet.png"]


def _cmd_camera_detect(args: argparse.Namespace) -> int:
    steps = Steps()
    out = OutputDir(args.out, "camera-detect", inputs=tuple(args.images))
    out.check()
    det = detect_views(args, steps)
    with out as staging:
        names = write_detected(Path(staging), det)
        write_provenance(Path(staging), "camera-detect", images=list(det.images),
                         board=f"{det.board.cols}x{det.board.rows}",
                         square_mm=det.board.square, charuco=det.board.charuco,
                         marker_mm=det.board.marker)
    print("\n".join(det.lines()))
    print(f"wrote {args.out}/: {', '.join(names)} ({len(det.model_xy)} model points in mm, "
          f"{det.data.n} corners in {len(det.data.views)} views)")
    print(f"next: montecarlo diagnose camera {args.out}/model.csv {args.out}/views.csv "
          "--pixel-sigma-px S")
    steps.report(to_stderr=False)
    return 0


def add_commands(sub: argparse._SubParsersAction) -> None:
    cam = sub.add_parser("camera", help="camera calibration targets in photographs")
    csub = cam.add_subparsers(dest="camera_command", required=True, parser_class=Parser)
    p = csub.add_parser("detect", help="find a chessboard or ChArUco board's corners in "
                        "photographs (OpenCV); write model.csv, views.csv and a contact sheet")
    p.add_argument("images", nargs="+", help="image files, one view each, all of one size")
    detection_options(p, required=True)
    p.add_argument("--out", required=True, metavar="DIR", help="directory to write (or an "
                   "earlier result of this command to replace)")
    p.set_defaults(func=_cmd_camera_detect)


def add_diagnose_parser(dsub: argparse._SubParsersAction,
                        basic: Callable[[argparse.ArgumentParser], None]) -> None:
    """``diagnose camera``: from the two CSV files, or from photographs (``--images``)."""
    p = dsub.add_parser("camera", help="camera calibration from a planar target in several "
                        "views: pinhole against distortion, skew, aspect ratio, bad corners")
    p.add_argument("model", nargs="?", help="CSV of the target's points: id, X, Y, unit (m, "
                   "cm, mm, in)")
    p.add_argument("views", nargs="?", help="CSV of the observed image points: view, id, u, v "
                   "[px]")
    p.add_argument("--images", nargs="+", metavar="IMAGE", help="photographs of the board "
                   "instead of the CSV files: find the corners first (as camera detect), with "
                   "--board and --square-mm")
    detection_options(p, required=False)
    p.add_argument("--pixel-sigma-px", type=positive_or_auto, required=True, metavar="S",
                   help="standard deviation of each image coordinate of a corner [px]"
                   + AUTO_HELP)
    p.add_argument("--report", metavar="DIR", help="write report.md, diagnosis.json, "
                   "residuals.csv and plots (residuals against radius and image position, gap; "
                   "with --images also the residuals drawn on each image, the corners found "
                   "and the two CSV files)")
    p.add_argument("--emit-errors", metavar="FILE.toml", help="write the [errors] pixel entry "
                   "of a ground study (for montecarlo size|run --errors)")
    p.add_argument("--leave-one-out", action="store_true", help="out-of-sample evidence: "
                   "refit the final model (and it without each named effect) on all views but "
                   "one, predict that view's corners (its pose fitted to it alone, the "
                   "intrinsics held), for each view; an effect predicts when leaving it out "
                   "raises the prediction error (paired t test over the views at --alpha); "
                   "slow: two fits per view and model")
    basic(p)
    p.set_defaults(func=diagnose_camera)
