"""``diagnose ground | collimation --leave-one-out`` on data made by ``montecarlo synth``,
against references the command does not compute: scipy's paired t test on the per-group mean
squares it reports, and a direct refit (scipy.optimize.least_squares) of the model on all
targets (mirrors) but one, predicting the one left out."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from scipy import optimize, stats

from montecarlo.discrepancy import collimation_effects as ce
from montecarlo.discrepancy import ground_effects as ge
from montecarlo.discrepancy.fit import fit_model
from montecarlo.discrepancy.groups import label_groups
from montecarlo.discrepancy.out_of_sample import leave_one_group_out
from montecarlo.geometry.camera import Camera
from montecarlo.io.collimation_csv import MirrorData
from montecarlo.io.ground_csv import GroundData
from tests.forked_cli import montecarlo_cli

PIXEL_SIGMA = 0.3
GROUND = ["--fov-deg", "90", "90", "--pixels", "512", "512", "--pixel-sigma-px",
          str(PIXEL_SIGMA), "--survey-sigma-m", "0"]
CAMERA = Camera.from_degrees(90.0, 90.0, 512, 512)
ARCSEC = math.pi / (180 * 3600)
ANGLE_SIGMA = 2.83  # arcsec, hypot(2, 2) of synth collimation's defaults


def _ground_data(path) -> GroundData:
    t = pd.read_csv(path)
    return GroundData(tuple(t["target"]), t[["x_m", "y_m", "z_m"]].to_numpy(),
                      t[["px", "pz"]].to_numpy(), t["t_s"].to_numpy(), None)


def _mirror_data(path) -> MirrorData:
    t = pd.read_csv(path)
    deg = {c: np.radians(t[c].to_numpy()) for c in ("theodolite_az_deg", "theodolite_el_deg",
                                                    "ins_az_deg", "ins_el_deg")}
    return MirrorData(tuple(t["mirror"]), tuple(t["set"]), deg["theodolite_az_deg"],
                      deg["theodolite_el_deg"], deg["ins_az_deg"], deg["ins_el_deg"], None)


def _check_t_test(loo: dict, effect: str) -> None:
    """The reported test is scipy's one-sided paired t test on the reported mean squares."""
    final, without = loo["models"]["final model"], loo["models"][f"without {effect}"]
    groups = loo["groups"]
    a = np.array([without["per_group"][g]["mean_square_sigma2"] for g in groups])
    b = np.array([final["per_group"][g]["mean_square_sigma2"] for g in groups])
    ref = stats.ttest_rel(a, b, alternative="greater")
    test = without["test"]
    assert test["t"] == pytest.approx(ref.statistic, rel=1e-9)
    assert test["p_value"] == pytest.approx(ref.pvalue, rel=1e-9)
    assert test["worse_without"] == int(np.sum(a > b)) and test["groups"] == len(groups)
    assert test["verdict"] == ("predicts" if ref.pvalue < loo["alpha"] else "does not predict")


def _ground_prediction(data: GroundData, left: str, names: list[str]) -> np.ndarray:
    """Image residuals [px] of target ``left`` predicted by the mounting (and ``names``)
    fitted by least squares on every other target (refraction 0.13, as synth and the base
    model have it)."""
    keys = ["psi", "theta", "gamma", *names]
    train = np.array([t != left for t in data.targets])

    def subset(mask: np.ndarray) -> GroundData:
        return GroundData(tuple(np.array(data.targets)[mask]), data.positions[mask],
                          data.pixels[mask], None, None)

    def residual(x: np.ndarray, part: GroundData) -> np.ndarray:
        predicted = ge.predict_pixels(dict(zip(keys, x, strict=True)), part, CAMERA, 0.13)
        return np.ravel(part.pixels - predicted)

    start = np.array([*np.radians([30.0, 20.0, 10.0]), *[0.0] * len(names)])
    fit = optimize.least_squares(residual, start, args=(subset(train),), xtol=1e-14,
                                 ftol=1e-14, gtol=1e-14)
    return residual(fit.x, subset(~train))


def test_the_flag_is_in_the_help() -> None:
    out = subprocess.run([sys.executable, "-m", "montecarlo", "diagnose", "ground", "--help"],
                         capture_output=True, text=True, check=True).stdout
    assert "--leave-one-out" in out
    assert "--leave-one-out" in montecarlo_cli("diagnose", "collimation", "--help").stdout


def test_ground_distortion_predicts_the_left_out_targets(tmp_path) -> None:
    data, out = tmp_path / "g.csv", tmp_path / "d.json"
    assert montecarlo_cli("synth", "ground", data, "--seed", 7, "--survey-sigma-m", 0,
                          "--effect", "radial_distortion=-0.008").returncode == 0
    run = montecarlo_cli("diagnose", "ground", data, *GROUND, "--leave-one-out", "--json", out)
    assert run.returncode == 0, run.stderr
    report = json.loads(out.read_text())
    loo = report["leave_one_out"]
    assert [e["name"] for e in report["named_effects"]] == ["radial_distortion"]
    assert loo["kind"] == "target" and len(loo["groups"]) == 36
    assert loo["models"]["without radial_distortion"]["verdict"] == "predicts"
    assert [e["name"] for e in report["practical_significance"]] == ["radial_distortion"]
    _check_t_test(loo, "radial_distortion")
    measured = _ground_data(data)
    for left in ("T01", "T22"):
        for label, names in (("final model", ["k1"]), ("without radial_distortion", [])):
            e = _ground_prediction(measured, left, names)
            got = loo["models"][label]["per_group"][left]
            assert got["rms"] == pytest.approx(np.sqrt(np.mean(e ** 2)), rel=1e-5, abs=1e-7)
            assert got["mean_square_sigma2"] == pytest.approx(
                np.mean((e / PIXEL_SIGMA) ** 2), rel=1e-5, abs=1e-9)


def test_ground_null_data_name_nothing_and_give_no_table(tmp_path) -> None:
    """Null data: nothing named, one line instead of the table. With an effect the data do
    not carry forced into the model, it does not predict."""
    data = tmp_path / "n.csv"
    assert montecarlo_cli("synth", "ground", data, "--seed", 3, "--survey-sigma-m", 0
                          ).returncode == 0
    run = montecarlo_cli("diagnose", "ground", data, *GROUND, "--leave-one-out")
    assert run.returncode == 0, run.stderr
    assert ("leave one target out: no table: the diagnosis named no effect, so none is left "
            "out") in run.stdout
    assert "out-of-sample evidence" not in run.stdout
    measured = _ground_data(data)
    problem = ge.ground_problem(measured, CAMERA, PIXEL_SIGMA)
    d = SimpleNamespace(problem=problem, after=fit_model(problem, ["radial_distortion"]),
                        alpha=0.01)
    loo = leave_one_group_out(d, ge.report_view(measured, CAMERA, PIXEL_SIGMA, 0.0),  # type: ignore[arg-type]
                              label_groups(measured.targets), "target")
    assert loo["models"]["without radial_distortion"]["verdict"] == "does not predict"
    _check_t_test(loo, "radial_distortion")
    e = _ground_prediction(measured, "T05", ["k1"])
    assert loo["models"]["final model"]["per_group"]["T05"]["rms"] == pytest.approx(
        np.sqrt(np.mean(e ** 2)), rel=1e-5)


def test_ground_two_targets_give_no_table(tmp_path) -> None:
    data, renamed = tmp_path / "g.csv", tmp_path / "two.csv"
    assert montecarlo_cli("synth", "ground", data, "--seed", 7, "--effect",
                          "radial_distortion=-0.008").returncode == 0
    table = pd.read_csv(data)
    table["target"] = ["A" if i % 2 else "B" for i in range(len(table))]
    table.to_csv(renamed, index=False)
    run = montecarlo_cli("diagnose", "ground", renamed, *GROUND, "--leave-one-out")
    assert run.returncode == 0, run.stderr
    assert "named: radial_distortion" in run.stdout
    assert ("leave one target out: no table: 2 targets, at least 3 needed (the paired t test "
            "over targets needs 2 degrees of freedom)") in run.stdout


def _collimation_prediction(data: MirrorData, left: str, names: list[str]) -> np.ndarray:
    """Heading and pitch residuals [arcsec] of mirror ``left`` predicted by the frame heading
    (and ``names``) fitted by least squares on every other mirror; the heading scale's
    reference (the mean INS heading of the file) as the model states it."""
    keys = ["frame_heading", *names]
    ref = float(np.angle(np.mean(np.exp(1j * data.ins_az))))
    train = np.array([m != left for m in data.mirror])

    def residual(x: np.ndarray, mask: np.ndarray) -> np.ndarray:
        part = MirrorData(tuple(np.array(data.mirror)[mask]), tuple(np.array(data.sets)[mask]),
                          data.theodolite_az[mask], data.theodolite_el[mask], data.ins_az[mask],
                          data.ins_el[mask], None)
        heading, pitch = ce.predict_readings(dict(zip(keys, x, strict=True)), part, ref)
        dh = np.angle(np.exp(1j * (part.ins_az - heading)))
        return np.concatenate([dh, part.ins_el - pitch]) / ARCSEC

    start = np.array([float(np.angle(np.mean(np.exp(1j * (data.ins_az - data.theodolite_az))))),
                      *[0.0] * len(names)])
    fit = optimize.least_squares(residual, start, args=(train,), xtol=1e-14, ftol=1e-14,
                                 gtol=1e-14)
    return residual(fit.x, ~train)


def test_collimation_axis_offsets_predict_the_left_out_mirrors(tmp_path) -> None:
    data, out, rep = tmp_path / "c.csv", tmp_path / "d.json", tmp_path / "rep"
    assert montecarlo_cli("synth", "collimation", data, "--seed", 2, "--readings", "absolute",
                          "--effect", "axis_misalignment=180,-120").returncode == 0
    run = montecarlo_cli("diagnose", "collimation", data, "--readings", "absolute",
                         "--angle-sigma-arcsec", ANGLE_SIGMA, "--leave-one-out", "--json", out,
                         "--report", rep, "--trials", 0)
    assert run.returncode == 0, run.stderr
    report = json.loads(out.read_text())
    loo = report["leave_one_out"]
    assert [e["name"] for e in report["named_effects"]] == ["axis_misalignment"]
    assert loo["kind"] == "mirror" and len(loo["groups"]) == 14
    assert loo["models"]["without axis_misalignment"]["verdict"] == "predicts"
    _check_t_test(loo, "axis_misalignment")
    measured = _mirror_data(data)
    for left in ("A1", "P7"):
        for label, names in (("final model", ["axis_az", "axis_el"]),
                             ("without axis_misalignment", [])):
            e = _collimation_prediction(measured, left, names)
            got = loo["models"][label]["per_group"][left]
            assert got["rms"] == pytest.approx(np.sqrt(np.mean(e ** 2)), rel=1e-5, abs=1e-6)
            assert got["mean_square_sigma2"] == pytest.approx(
                np.mean((e / ANGLE_SIGMA) ** 2), rel=1e-5, abs=1e-9)
    md = (rep / "report.md").read_text()
    assert "## Out-of-sample evidence: leave one mirror out" in md
    assert "| axis_misalignment |" in md and "predicts | significant, important |" in md


def test_collimation_refuses_leave_one_out_on_the_procedures_readings(tmp_path) -> None:
    data = tmp_path / "c.csv"
    assert montecarlo_cli("synth", "collimation", data, "--seed", 2).returncode == 0
    run = montecarlo_cli("diagnose", "collimation", data, "--angle-sigma-arcsec", ANGLE_SIGMA,
                         "--leave-one-out")
    assert run.returncode == 2 and run.stdout == ""
    assert run.stderr.strip().splitlines() == [
        "error: --leave-one-out: only with --readings absolute (under the procedure every "
        "relative reading shares the reference readings' errors, so one mirror cannot be left "
        "out on its own)"]
