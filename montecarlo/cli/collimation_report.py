"""Seed 003's fit reports: the text and JSON of ``collimation fit`` and ``collimation verify``."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING

from montecarlo.units import ARCSEC

if TYPE_CHECKING:
    from montecarlo.io.collimation_csv import MirrorData
    from montecarlo.seed003.conventions import Choice
    from montecarlo.seed003.fit import Fit
    from montecarlo.seed003.procedure import ProcedureData, ProcedureFit


def verification_report(check, mirrors: list[str], kind: str) -> dict[str, object]:
    """JSON-ready out-of-sample deviations (arc-seconds) and the 15″ verdict on them."""
    from montecarlo.seed003.procedure import CLAIM

    rows = []
    for i, name in enumerate(mirrors):
        rows.append({"mirror": name,
                     "axis_az_arcsec": float(check.offsets[i, 0] / ARCSEC),
                     "axis_el_arcsec": float(check.offsets[i, 1] / ARCSEC),
                     "deviation_az_arcsec": float(check.deviation_az[i] / ARCSEC),
                     "deviation_el_arcsec": float(check.deviation_el[i] / ARCSEC)})
    return {"kind": kind, "in_sample": False, "mirrors": rows,
            "claim_15_arcsec": {"max_deviation_arcsec": check.max_deviation / ARCSEC,
                                "holds": check.holds, "limit_arcsec": CLAIM / ARCSEC}}


def format_verification(report: Mapping[str, object]) -> str:
    """Text of an out-of-sample check (:func:`verification_report`)."""
    claim = report["claim_15_arcsec"]
    head = ("offsets fitted without the mirror, applied to it" if report["kind"] ==
            "leave-one-out" else f"offsets of {report.get('fit')} applied to {report.get('file')}")
    lines = [f"out-of-sample check ({report['kind']}): {head}",
             f"{'mirror':>8} {'γ used″':>9} {'λ used″':>9} {'dev az″':>8} {'dev el″':>8}"]
    for m in report["mirrors"]:
        lines.append(f"{m['mirror']:>8} {m['axis_az_arcsec']:9.1f} {m['axis_el_arcsec']:9.1f} "
                     f"{m['deviation_az_arcsec']:8.2f} {m['deviation_el_arcsec']:8.2f}")
    lines.append(f"largest out-of-sample deviation {claim['max_deviation_arcsec']:.2f}″ -> the "
                 "paper's 15″ claim " + ("holds" if claim["holds"] else "DOES NOT HOLD")
                 + " out of sample")
    return "\n".join(lines)


def fit_report(readings: MirrorData, result: Fit, source: str) -> dict[str, object]:
    """JSON-ready summary of a fit: parameters, sigmas and residuals in arc-seconds."""
    import numpy as np

    from montecarlo.seed003.fit import consistency_angles
    from montecarlo.seed003.model import EFFECTS, correct_readings

    roll = readings.ins_roll if readings.ins_roll is not None else np.zeros_like(readings.ins_az)
    params = result.params
    corr_az, corr_el, _ = correct_readings(readings.ins_az, readings.ins_el, roll,
                                           params["axis_az"], params["axis_el"])
    consistency = consistency_angles(params, readings.theodolite_az, readings.theodolite_el,
                                     readings.ins_az, readings.ins_el, roll)
    before, after = result.residuals_before / ARCSEC, result.residuals / ARCSEC
    mirrors = []
    for i, (name, kind) in enumerate(zip(readings.mirror, readings.sets, strict=True)):
        mirrors.append({
            "mirror": name, "set": kind,
            "residual_before_az_arcsec": before[i, 0], "residual_before_el_arcsec": before[i, 1],
            "residual_after_az_arcsec": after[i, 0], "residual_after_el_arcsec": after[i, 1],
            "consistency_after_arcsec": consistency[i] / ARCSEC,
            "corrected_ins_az_deg": math.degrees(corr_az[i]),
            "corrected_ins_el_deg": math.degrees(corr_el[i]),
        })

    def rms(r):
        return {"az": float(np.sqrt(np.mean(r[:, 0] ** 2))),
                "el": float(np.sqrt(np.mean(r[:, 1] ** 2))), "all": float(np.sqrt(np.mean(r ** 2)))}

    return {
        "system": "collimation",
        "file": source,
        "n_mirrors": len(readings.mirror),
        "roll": "reported" if readings.ins_roll is not None else "assumed zero (level mount)",
        "effects": [e for e in EFFECTS if set(EFFECTS[e]) <= set(result.names)],
        "unit": "arcsec",
        "parameters": {k: v / ARCSEC for k, v in params.items()},
        "stderr": {k: v / ARCSEC for k, v in result.stderr.items()},
        "covariance_arcsec2": (result.covariance / ARCSEC**2).tolist(),
        "sigma_arcsec": {"heading": result.sigma[0] / ARCSEC, "pitch": result.sigma[1] / ARCSEC},
        "sigma_source": result.sigma_source,
        "chi2": result.chi2, "dof": result.dof, "chi2_red": result.chi2_red,
        "passes_arcsec": [v / ARCSEC for v in result.passes],
        "mirrors": mirrors,
        "rms_arcsec": {"before": rms(before), "after": rms(after)},
    }


def format_report(report: Mapping[str, object]) -> str:
    """Human-readable text of :func:`fit_report`."""
    from montecarlo.seed003.model import EFFECTS

    p, se = report["parameters"], report["stderr"]
    sets = [m["set"] for m in report["mirrors"]]
    lines = [
        f"seed 003 axis calibration: {report['file']}, {report['n_mirrors']} mirrors "
        f"({sets.count('azimuth')} azimuth, {sets.count('pitch')} pitch); "
        f"INS roll {report['roll']}",
        f"residual sigma: heading {report['sigma_arcsec']['heading']:.2f}″, pitch "
        f"{report['sigma_arcsec']['pitch']:.2f}″ ({report['sigma_source']})",
        "optical axis relative to the INS axis (±1σ):",
        f"  axis_az  γ = {p['axis_az']:10.2f} ± {se['axis_az']:.2f} arc-seconds (right +)",
        f"  axis_el  λ = {p['axis_el']:10.2f} ± {se['axis_el']:.2f} arc-seconds (up +)",
        "reference terms:",
    ]
    for k in p:
        if k in EFFECTS["axis_misalignment"]:
            continue
        if k == "frame_heading":
            lines.append(f"  frame_heading = {p[k] / 3600:.6f}° ± {se[k]:.2f} arc-seconds")
        else:
            lines.append(f"  {k} = {p[k]:.2f} ± {se[k]:.2f} arc-seconds")
    lines += [
        "offset increment per pass (fit, correct, refit): "
        + ", ".join(f"{v:.4f}″" for v in report["passes_arcsec"]),
        f"chi2/dof = {report['chi2']:.2f}/{report['dof']} = {report['chi2_red']:.3f}",
        "",
        "per-mirror residuals, INS reading - model [arc-seconds]; consistency = angle between",
        "corrected optical axis and mirror normal:",
        f"{'mirror':>10} {'set':>8} {'before az':>10} {'before el':>10} {'after az':>9} "
        f"{'after el':>9} {'consistency':>11}",
    ]
    for m in report["mirrors"]:
        lines.append(
            f"{m['mirror']:>10} {m['set']:>8} {m['residual_before_az_arcsec']:10.2f} "
            f"{m['residual_before_el_arcsec']:10.2f} {m['residual_after_az_arcsec']:9.2f} "
            f"{m['residual_after_el_arcsec']:9.2f} {m['consistency_after_arcsec']:11.2f}")
    b, a = report["rms_arcsec"]["before"], report["rms_arcsec"]["after"]
    lines.append(f"{'RMS':>10} {'':>8} {b['az']:10.2f} {b['el']:10.2f} {a['az']:9.2f} "
                 f"{a['el']:9.2f}")
    lines.append(f"RMS of all residuals: before {b['all']:.2f}″, after {a['all']:.2f}″")
    return "\n".join(lines)


def reference_report(readings: MirrorData, data: ProcedureData, result: ProcedureFit,
                     source: str, free_roll: bool, roll_sigma: float,
                     choices: Mapping[str, Choice] | None = None) -> dict[str, object]:
    """JSON-ready summary of a fit of the paper's procedure (arc-seconds unless named).

    Corrected readings and theodolite angles are given in the frame of the file's theodolite
    readings: azimuth relative to the central reference mirror plus that mirror's theodolite
    azimuth (its row, or the fitted ``reference_az``), turned back to the file's azimuth sense.
    When the file's theodolite azimuths are relative to the central mirror, as in the paper's
    table, this is the frame of the paper's corrected column.
    """
    import numpy as np
    from scipy.stats import chi2

    from montecarlo.seed003.conventions import SENSES
    from montecarlo.seed003.procedure import (
        CLAIM,
        central_azimuth,
        corrected_and_theodolite,
        heading_floor,
        pitch_reach,
    )

    k = data.measured
    names = [readings.mirror[i] for i in k]
    sets = [readings.sets[i] for i in k]
    c_az, c_el, t_az, t_el, rel_roll = corrected_and_theodolite(data, result)
    sense = "same" if choices is None else choices["azimuth_sense"].chosen
    zero = central_azimuth(data, result)
    c_az, t_az = (SENSES[sense] * (a + zero) for a in (c_az, t_az))  # the file's frame
    before, after = result.residuals_before / ARCSEC, result.residuals / ARCSEC
    dev_az = np.degrees(np.angle(np.exp(1j * (c_az - t_az)))) * 3600.0
    dev_el = (c_el - t_el) / ARCSEC
    mirrors = []
    for i, name in enumerate(names):
        ok = abs(dev_az[i]) <= CLAIM / ARCSEC and abs(dev_el[i]) <= CLAIM / ARCSEC
        mirrors.append({
            "mirror": name, "set": sets[i],
            "theodolite_az_deg": math.degrees(t_az[i]), "theodolite_el_deg": math.degrees(t_el[i]),
            "roll_deg": math.degrees(rel_roll[i]),
            "residual_before_az_arcsec": before[i, 0], "residual_before_el_arcsec": before[i, 1],
            "residual_after_az_arcsec": after[i, 0], "residual_after_el_arcsec": after[i, 1],
            "corrected_ins_az_deg": math.degrees(c_az[i]),
            "corrected_ins_el_deg": math.degrees(c_el[i]),
            "deviation_az_arcsec": float(dev_az[i]), "deviation_el_arcsec": float(dev_el[i]),
            "verdict": "within 15″" if ok else "exceeds 15″",
        })

    def rms(r):
        return {"az": float(np.sqrt(np.mean(r[:, 0] ** 2))),
                "el": float(np.sqrt(np.mean(r[:, 1] ** 2))), "all": float(np.sqrt(np.mean(r ** 2)))}

    se = result.stderr
    not_determined = []
    for name in ("axis_az", "axis_el", "reference_az"):
        if name in se and 2 * se[name] > CLAIM:
            item = {"parameter": name, "stderr_arcsec": se[name] / ARCSEC}
            if name == "axis_az":
                pitch = np.array([s == "pitch" for s in sets])
                reach = pitch_reach(data, result, pitch, free_roll, roll_sigma)
                item["pitch_reach_deg"] = None if reach is None else math.degrees(reach)
            not_determined.append(item)
    floor = None
    if result.roll_source.startswith("assumed"):
        per_deg = heading_floor(data, result) * math.radians(1.0) / ARCSEC
        floor = {"arcsec_per_deg_roll": per_deg}
    worst = float(max(np.max(np.abs(dev_az)), np.max(np.abs(dev_el))))
    return {
        "system": "collimation",
        "file": source,
        "readings": "reference",
        "reference": "reference rows (absolute readings)" if data.has_reference
        else "no reference rows (readings relative to the reference)",
        "roll_mirror": ({"chosen": "right" if result.side > 0 else "left"} if choices is None
                        else choices["roll_mirror"].to_json()),
        "azimuth_sense": ({"chosen": "same"} if choices is None
                          else choices["azimuth_sense"].to_json()),
        "settings": {"free_roll": bool(free_roll), "roll_sigma_deg": math.degrees(roll_sigma)},
        "corrected_frame": "theodolite readings of the file (azimuth relative to the central "
                           "reference mirror + its theodolite azimuth)",
        "n_mirrors": int(k.size),
        "roll": result.roll_source,
        "roll_prior_deg": math.degrees(roll_sigma) if result.names[-1].startswith("roll")
        else None,
        "unit": "arcsec",
        "parameters": {n: v / ARCSEC for n, v in result.params.items()},
        "stderr": {n: v / ARCSEC for n, v in se.items()},
        "correlation": {"names": list(result.names), "matrix": result.correlation.tolist()},
        "covariance_arcsec2": (result.covariance / ARCSEC**2).tolist(),
        "sigma_arcsec": {"ins": result.sigma_ins / ARCSEC,
                         "theodolite": result.sigma_theodolite / ARCSEC},
        "sigma_source": result.sigma_source,
        "chi2": result.chi2, "dof": result.dof, "chi2_red": result.chi2_red,
        "chi2_p_value": float(chi2.sf(result.chi2, result.dof))
        if result.sigma_source == "given" else None,
        "not_determined": not_determined,
        "heading_floor": floor,
        "mirrors": mirrors,
        "rms_arcsec": {"before": rms(before), "after": rms(after)},
        "claim_15_arcsec": {"max_deviation_arcsec": worst, "holds": worst <= CLAIM / ARCSEC,
                            "in_sample": True},
    }


def format_reference_report(report: Mapping[str, object]) -> str:
    """Human-readable text of :func:`reference_report`."""
    p, se = report["parameters"], report["stderr"]
    sets = [m["set"] for m in report["mirrors"]]
    sig = report["sigma_arcsec"]
    lines = [
        f"seed 003 axis calibration, the paper's procedure: {report['file']}, "
        f"{report['n_mirrors']} mirrors ({sets.count('azimuth')} azimuth, "
        f"{sets.count('pitch')} pitch); {report['reference']}; roll mirror on the "
        f"{report['roll_mirror']['chosen']}; INS roll {report['roll']}",
        *_convention_lines(report),
        f"reading sigma: INS {sig['ins']:.2f}″, theodolite {sig['theodolite']:.2f}″ "
        f"({report['sigma_source']})",
        "optical axis relative to the INS axis (±1σ):",
        f"  axis_az  γ = {p['axis_az']:10.2f} ± {se['axis_az']:.2f} arc-seconds (right +)",
        f"  axis_el  λ = {p['axis_el']:10.2f} ± {se['axis_el']:.2f} arc-seconds (up +)",
    ]
    if "reference_az" in p:
        lines.append(f"  reference azimuth (central mirror, theodolite) = "
                     f"{p['reference_az'] / 3600:.6f}° ± {se['reference_az']:.2f} arc-seconds")
    rolls = [n for n in p if n.startswith("roll")]
    if rolls:
        lines.append(f"  {len(rolls)} rolls fitted (prior 1σ {report['roll_prior_deg']:.2f}°): "
                     + ", ".join(f"{p[n] / 3600:.3f}°" for n in rolls))
    corr = report["correlation"]
    i, j = corr["names"].index("axis_az"), corr["names"].index("axis_el")
    lines.append(f"correlation γ-λ {corr['matrix'][i][j]:+.3f}"
                 + ("" if "reference_az" not in corr["names"] else
                    f", γ-reference azimuth "
                    f"{corr['matrix'][i][corr['names'].index('reference_az')]:+.3f}"))
    lines.append(f"chi2/dof = {report['chi2']:.2f}/{report['dof']} = {report['chi2_red']:.3f}")
    if report["chi2_p_value"] is not None and report["chi2_p_value"] < 1e-3:
        lines.append(f"MISFIT: χ² p-value {report['chi2_p_value']:.1e} with the given sigmas; "
                     "check the reading model (--readings absolute if the INS readings are "
                     "absolute and the file has no reference rows), the roll and the sigmas")
    for item in report["not_determined"]:
        text = (f"NOT DETERMINED: {item['parameter']} (σ {item['stderr_arcsec']:.1f}″, 2σ above "
                "15″) by this mirror layout")
        if "pitch_reach_deg" in item:
            reach = item["pitch_reach_deg"]
            text += ("; no pitch mirrors up to 85° would bring σ_γ to 7.5″" if reach is None else
                     f"; pitch mirrors must reach about {reach:.0f}° for σ_γ ≤ 7.5″")
        lines.append(text)
    if report["heading_floor"] is not None:
        f = report["heading_floor"]["arcsec_per_deg_roll"]
        lines.append(f"INS roll not recorded: a level mount is assumed. A roll of 1° (1σ) at each "
                     f"pointing would scatter the relative headings by {f:.1f}″ RMS at these "
                     f"offsets ({2 * f:.1f}″ at 2°): the heading floor of this assumption. "
                     "Record ins_roll_deg or use --free-roll.")
    lines += [
        "",
        "per mirror [arc-seconds]: residuals (INS reading - model) before/after; corrected INS "
        "reading (optical axis) vs theodolite, both in the file's theodolite frame:",
        f"{'mirror':>8} {'set':>8} {'bef az':>8} {'bef el':>8} {'aft az':>7} {'aft el':>7} "
        f"{'theo az°':>10} {'theo el°':>9} {'corr az°':>10} {'corr el°':>9} {'dev az':>7} "
        f"{'dev el':>7}  verdict",
    ]
    for m in report["mirrors"]:
        lines.append(
            f"{m['mirror']:>8} {m['set']:>8} {m['residual_before_az_arcsec']:8.2f} "
            f"{m['residual_before_el_arcsec']:8.2f} {m['residual_after_az_arcsec']:7.2f} "
            f"{m['residual_after_el_arcsec']:7.2f} {m['theodolite_az_deg']:10.5f} "
            f"{m['theodolite_el_deg']:9.5f} {m['corrected_ins_az_deg']:10.5f} "
            f"{m['corrected_ins_el_deg']:9.5f} {m['deviation_az_arcsec']:7.2f} "
            f"{m['deviation_el_arcsec']:7.2f}  {m['verdict']}")
    b, a = report["rms_arcsec"]["before"], report["rms_arcsec"]["after"]
    lines.append(f"{'RMS':>8} {'':>8} {b['az']:8.2f} {b['el']:8.2f} {a['az']:7.2f} {a['el']:7.2f}")
    lines.append(f"RMS of all residuals: before {b['all']:.2f}″, after {a['all']:.2f}″")
    claim = report["claim_15_arcsec"]
    lines.append(f"largest deviation of a corrected reading from the theodolite: "
                 f"{claim['max_deviation_arcsec']:.2f}″ -> the paper's 15″ claim "
                 + ("holds" if claim["holds"] else "DOES NOT HOLD")
                 + " in sample (the offsets were fitted to these readings; check it on another "
                 "set: collimation verify, or --verify leave-one-out)")
    if "verification" in report:
        lines += ["", format_verification(report["verification"])]
    return "\n".join(lines)


def _convention_lines(report: Mapping[str, object]) -> list[str]:
    """How the roll-mirror side and the azimuth sense were decided (text report)."""
    out = []
    for key, label in (("roll_mirror", "roll mirror"), ("azimuth_sense", "azimuth sense")):
        c = report[key]
        chi2 = {k[5:]: v for k, v in c.items() if k.startswith("chi2_")}
        if not chi2:
            continue
        shown = ", ".join(f"{k} {'-' if v is None else f'{v:.4g}'}" for k, v in chi2.items())
        verdict = ("decided by the data" if c["decided"] else f"not decided: {c['reason']}")
        at = f" at {c['weights']}" if "weights" in c else ""  # (not in older reports)
        out.append(f"{label}: {c['chosen']} (stated {c['stated']}; χ²{at}: {shown}; "
                   f"{verdict})")
    return out
