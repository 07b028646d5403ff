"""``montecarlo synth`` and ``montecarlo diagnose`` run as subprocesses, as users run them."""

import json

import numpy as np
import pandas as pd
import pytest

from montecarlo.cli import main
from tests.forked_cli import montecarlo_cli

FIXED_KEYS = {"system", "detected", "named_effects", "confounded_groups", "absorbed", "gap",
              "rms_unit"}
GROUND = ["--fov-deg", "90", "90", "--pixels", "512", "512", "--pixel-sigma-px", "0.3",
          "--survey-sigma-m", "0.01"]


def run_cli(*args):
    return montecarlo_cli(*args)


def test_ground_hidden_focal_scale_is_named_and_the_gap_shrinks(tmp_path):
    data, out, truth = tmp_path / "g.csv", tmp_path / "d.json", tmp_path / "truth.json"
    sim = run_cli("synth", "ground", data, "--seed", 11, "--at-mdb", "focal_scale=3",
                  "--truth", truth)
    assert sim.returncode == 0, sim.stderr
    truth.unlink()  # the diagnosis must not need (or read) how the data were made
    diag = run_cli("diagnose", "ground", data, *GROUND, "--json", out)
    assert diag.returncode == 0, diag.stderr
    assert "named: focal_scale" in diag.stdout
    report = json.loads(out.read_text())
    assert set(report) >= FIXED_KEYS
    assert report["system"] == "ground" and report["detected"] is True
    assert [e["name"] for e in report["named_effects"]] == ["focal_scale"]
    effect = report["named_effects"][0]
    assert set(effect) >= {"name", "parameters", "stderr", "p_value"}
    assert set(effect["parameters"]) == {"s"} and effect["p_value"] < 0.01
    assert "detector_rotation" in report["absorbed"]
    gap = report["gap"]
    assert gap["before"]["chi2_red"] > gap["after"]["chi2_red"]
    assert gap["before"]["p_value"] < 0.01 <= gap["after"]["p_value"]
    assert gap["after"]["rms"] < gap["before"]["rms"] and report["rms_unit"] == "px"


def test_collimation_axis_offsets_named_collimation_absorbed_with_report(tmp_path):
    data, rep = tmp_path / "c.csv", tmp_path / "rep"
    sim = run_cli("synth", "collimation", data, "--seed", 2, "--effect",
                  "axis_misalignment=180,-120", "--readings", "absolute")
    assert sim.returncode == 0, sim.stderr
    diag = run_cli("diagnose", "collimation", data, "--angle-sigma-arcsec", "2.83", "--report",
                   rep, "--trials", 8, "--readings", "absolute")
    assert diag.returncode == 0, diag.stderr
    report = json.loads((rep / "diagnosis.json").read_text())
    assert report["named_effects"][0]["name"] == "axis_misalignment"
    p, se = report["named_effects"][0]["parameters"], report["named_effects"][0]["stderr"]
    assert abs(p["axis_az"] - 180) < 4 * se["axis_az"]
    assert abs(p["axis_el"] + 120) < 4 * se["axis_el"]
    assert {"theodolite_collimation", "ins_bias"} <= set(report["absorbed"])
    assert report["rms_unit"] == "arcsec"
    assert len(report["monte_carlo"]["before"]) > 0
    for name in ("residuals.png", "gap.png"):
        size = (rep / name).stat().st_size
        assert 10_000 < size < 200_000
    assert "Monte Carlo" in (rep / "report.md").read_text()
    # the residual plot's numbers: their rms is the report's gap rms
    table = pd.read_csv(rep / "residuals.csv")
    for when in ("before", "after"):
        cols = [c for c in table.columns if f" {when} [arcsec]" in c]
        assert len(cols) == 2
        rms = np.sqrt(np.mean(table[cols].to_numpy() ** 2))
        assert rms == pytest.approx(report["gap"][when]["rms"], rel=1e-6)


def test_null_data_report_no_missing_effect(tmp_path, capsys):
    data, out = tmp_path / "n.csv", tmp_path / "n.json"
    assert main(["synth", "ground", str(data), "--seed", "5"]) == 0
    assert main(["diagnose", "ground", str(data), *GROUND, "--json", str(out)]) == 0
    assert "no missing effect" in capsys.readouterr().out
    report = json.loads(out.read_text())
    assert report["detected"] is False and report["named_effects"] == []
    assert report["gap"]["before"] == report["gap"]["after"]


GROUND_OK = "target,x_m,y_m,z_m,px,pz\n" + "".join(
    f"T{i},{x},50,{z},{-100 + 40 * i},{30 * (i % 3)}\n"
    for i, (x, z) in enumerate([(-20, 0), (-10, 5), (0, -5), (10, 3), (20, 8)]))
COLLIMATION_OK = ("mirror,set,theodolite_az_deg,theodolite_el_deg,ins_az_deg,ins_el_deg\n"
                  "A1,azimuth,0,0,30,0\nA2,azimuth,45,0,75,0\nP1,pitch,0,30,30,30\n")


@pytest.mark.parametrize(("system", "text", "where"), [
    ("ground", GROUND_OK.replace("px,pz", "px,pzz"), "missing column 'pz'"),
    ("ground", GROUND_OK.replace("T2,0,50", "T2,zero,50"), "row 4, column 'x_m'"),
    ("ground", GROUND_OK.replace("T3,10,50,3", "T3,10,NaN,3"), "row 5, column 'y_m'"),
    ("ground", "\n".join(GROUND_OK.splitlines()[:4]) + "\n", "3 data rows, at least 4"),
    ("collimation", COLLIMATION_OK.replace("P1,pitch", "P1,roll"), "row 4, column 'set'"),
    ("collimation", COLLIMATION_OK.replace(",30,30,30", ",30,,30"), "row 4, column 'ins_az_deg'"),
    ("collimation", COLLIMATION_OK.replace("ins_el_deg", "ins_pitch"), "missing column 'ins_el"),
    ("collimation", "\n".join(COLLIMATION_OK.splitlines()[:2]) + "\n", "1 data rows, at least 3"),
])
def test_malformed_csv_exits_2_with_one_line(tmp_path, capsys, system, text, where):
    data, out = tmp_path / "bad.csv", tmp_path / "out.json"
    data.write_text(text)
    flags = GROUND if system == "ground" else ["--angle-sigma-arcsec", "2"]
    code = main(["diagnose", system, str(data), *flags, "--json", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and str(data) in err and where in err
    assert not out.exists()


def test_malformed_csv_as_a_subprocess(tmp_path):
    data = tmp_path / "bad.csv"
    data.write_text(GROUND_OK.replace("T1,-10", "T1,inf"))
    proc = run_cli("diagnose", "ground", data, *GROUND)
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and "row 3, column 'x_m'" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_synth_rejects_unknown_effects(capsys, tmp_path):
    assert main(["synth", "ground", str(tmp_path / "x.csv"), "--effect", "warp=1"]) == 2
    assert "unknown effect" in capsys.readouterr().err
    assert main(["synth", "collimation", str(tmp_path / "x.csv"), "--effect",
                 "axis_misalignment=1"]) == 2
    assert "needs 2 finite value(s)" in capsys.readouterr().err
    assert not (tmp_path / "x.csv").exists()


LONG = ["--fov-deg", "30", "22.5", "--pixels", "1920", "1440", "--pixel-sigma-px", "0.2",
        "--survey-sigma-m", "0.005"]


def test_refraction_differs_from_the_stated_standard(tmp_path, capsys):
    """Targets at 0.5-3 km seen through k = 2: against the standard 0.13 the refraction
    candidate is named with dk near 2 - 0.13; told k = 2, the base model fits (curvature is
    in the base model in both cases, so no negative refraction stands in for it)."""
    data, out = tmp_path / "far.csv", tmp_path / "d.json"
    assert main(["synth", "ground", str(data), "--seed", "3", *LONG, "--ranges-m", "500",
                 "1000", "2000", "3000", "--mounting-deg", "-20", "10", "-5",
                 "--refraction-k", "2"]) == 0
    assert main(["diagnose", "ground", str(data), *LONG, "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert report["base_physics"] == {"earth_curvature": True, "refraction_k": 0.13}
    assert [e["name"] for e in report["named_effects"]] == ["refraction"]
    dk, err = (report["named_effects"][0][k]["dk"] for k in ("parameters", "stderr"))
    assert abs(dk - 1.87) < 3 * err
    assert main(["diagnose", "ground", str(data), *LONG, "--refraction-k", "2",
                 "--json", str(out)]) == 2  # the first report is kept
    assert main(["diagnose", "ground", str(data), *LONG, "--refraction-k", "2",
                 "--json", str(out), "--force"]) == 0
    report = json.loads(out.read_text())
    assert report["named_effects"] == [] and report["gap"]["before"]["p_value"] > 0.01
    capsys.readouterr()
    assert main(["diagnose", "ground", str(data), *LONG, "--refraction-k", "9"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--refraction-k" in err and "'9'" in err
