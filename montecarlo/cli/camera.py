"""``diagnose camera``: planar-target camera calibration on the discrepancy workflow."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from montecarlo.cli.common import check_json_option, emit_json, write_provenance
from montecarlo.cli.steps import LIBRARIES, Steps, fit_why
from montecarlo.errors import InputError
from montecarlo.io.files import OutputDir, writable_file

if TYPE_CHECKING:
    from montecarlo.discrepancy.engine import Diagnosis


def _unit(unit: str) -> str:
    return "" if unit == "1" else f" {unit}"


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


def diagnose_camera(args: argparse.Namespace) -> int:
    """``diagnose camera MODEL.csv VIEWS.csv``: the pinhole model against distortion, skew,
    aspect ratio and bad corners; the final camera, practical significance, pixel error left."""
    steps = Steps()
    with steps("loading", LIBRARIES):
        from montecarlo.camera_calibration.calibrate import CalibrationError
        from montecarlo.discrepancy import camera_effects as cam
        from montecarlo.discrepancy.engine import diagnose
        from montecarlo.discrepancy.fit import FitError
        from montecarlo.discrepancy.significance import (
            format_significance,
            practical_significance,
        )
        from montecarlo.discrepancy.view import format_text, to_json
        from montecarlo.io.camera_csv import read_camera_csv
        from montecarlo.io.files import atomic_write_bytes
        from montecarlo.output.provenance import provenance

    inputs = (Path(args.model), Path(args.views))
    if args.report:
        OutputDir(args.report, "diagnose", inputs=inputs).check()
    check_json_option(args)
    if args.emit_errors:
        writable_file(args.emit_errors, args.force)
    data = read_camera_csv(args.model, args.views)
    source = f"{args.model}, {args.views}"
    sigma = args.pixel_sigma_px
    estimated: dict[str, float] | None = None
    try:
        if sigma == "auto":
            with steps("estimating the pixel sigma", fit_why(2 * data.n,
                                                             13 + 6 * len(data.views))):
                estimated = cam.estimate_pixel_sigma(data)
            sigma = estimated["sigma"]
        with steps("the diagnosis", fit_why(2 * data.n, 4 + 6 * len(data.views))):
            d = diagnose(cam.camera_problem(data, sigma), args.alpha)
    except (FitError, CalibrationError) as exc:
        raise InputError(f"{args.views}: {exc}") from None
    view = cam.report_view(data, sigma)
    report = to_json(d, view, source)
    significance = practical_significance(d, view, cam.INTRINSIC_REPORTED)
    error = cam.pixel_error(d, data, sigma)
    report.update({"rms_convention": RMS_CONVENTION, "camera": camera_summary(d),
                   "practical_significance": significance, "pixel_error": error,
                   "pixel_sigma_estimated": estimated})
    camera = report["camera"]
    head = [] if estimated is None else [
        f"pixel sigma estimated from the data (every candidate fitted, {estimated['dof']} "
        f"dof): {estimated['sigma']:.4g} px, 95 % interval [{estimated['low']:.4g}, "
        f"{estimated['high']:.4g}] px; the tests below take it as known (chi-square in "
        "place of F)", ""]
    lines = [*head, format_text(report), "", RMS_CONVENTION,
             "camera (final model; Zhang's alpha, beta, gamma, u0, v0): " + ", ".join(
                 f"{k} = {v['value']:.6g} ± {v['stderr']:.2g}{_unit(v['unit'])}"
                 for k, v in camera.items() if v["stderr"] > 0),
             format_significance(significance),
             f"pixel error left: sigma u {error['sigma_u']:.4f} px, v {error['sigma_v']:.4f} px;"
             f" remaining distortion up to {error['distortion_bound']:.4f} px "
             f"({error['distortion_source'] or 'none tested'}, at its MDB)"]
    text = "\n".join(lines)
    record = {"model": str(args.model), "views": str(args.views), "alpha": args.alpha,
              "pixel_sigma_px": sigma}
    if args.report:
        from montecarlo.output.diagnosis import (  # matplotlib: only for reports
            write_html_report,
            write_report,
        )

        with OutputDir(args.report, "diagnose", inputs=inputs) as staging:
            write_report(staging, d, view, report)
            atomic_write_bytes(Path(staging) / "report.md", "\n".join(
                ["# Diagnosis", "", "```", text, "```", "", "![residuals](residuals.png)", "",
                 "![gap](gap.png)", ""]).encode())
            write_provenance(staging, "diagnose", **record)
            write_html_report(staging, d, view)
    if args.emit_errors:
        toml = cam.errors_toml(error, source, sigma, d.after.effects)
        atomic_write_bytes(Path(args.emit_errors), toml.encode())
    if emit_json(args, {**report, "provenance": provenance("diagnose", **record)}):
        steps.report(to_stderr=True)
        return 0
    print(text)
    if args.report:
        print(f"report written to {args.report}/ (report.md, report.html, diagnosis.json, "
              "residuals.png, gap.png)")
    if args.emit_errors:
        print(f"pixel error for a ground study written to {args.emit_errors} "
              "(use: montecarlo size|run ... --errors FILE)")
    steps.report(to_stderr=False)
    return 0
