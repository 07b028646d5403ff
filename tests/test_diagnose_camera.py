"""``diagnose camera``: the DIA engine on planar-target calibration data.

Synthetic views from :mod:`montecarlo.camera_calibration.simulate`; the published data set of
Zhang (1998) in tests/data/camera (README there).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from montecarlo.camera_calibration.calibrate import calibrate
from montecarlo.camera_calibration.simulate import DEFAULT_CAMERA
from montecarlo.discrepancy import camera_effects as ce
from montecarlo.discrepancy.engine import diagnose
from montecarlo.discrepancy.noise import noise_scale
from montecarlo.discrepancy.significance import practical_significance
from montecarlo.io.camera_csv import read_camera_csv
from montecarlo.tools import camera_acceptance as ca

ROOT = Path(__file__).resolve().parents[1]
BAD = ROOT / "tests" / "data" / "bad_inputs"
CAMERA = ROOT / "tests" / "data" / "camera"
SIGMA = 0.2


def _diagnose(truth, seed=1, corner=None, grid=5):
    data = ca.views_data({**DEFAULT_CAMERA, **truth}, SIGMA, seed, grid, corner)
    return data, diagnose(ce.camera_problem(data, SIGMA))


@pytest.fixture(scope="module")
def radial():
    return _diagnose({"k1": -0.5})


def test_hidden_radial_distortion_is_named_and_k2_waits_for_k1(radial):
    _, d = radial
    assert d.detected and d.named == ["radial_k1"] and not d.outliers
    first = {t.name: t for t in d.steps[0].tests}
    assert first["radial_k2"].status == "unavailable"
    assert "radial_k1" in first["radial_k2"].reason
    assert d.after.params["k1"] == pytest.approx(-0.5, abs=4 * d.after.stderr["k1"])


def test_practical_significance_matches_an_independent_refit(radial):
    """RMS with and without radial_k1 against the model layer's own least squares
    (camera_calibration.calibrate: pinhole with and without k1, no skew, no aspect)."""
    data, d = radial
    view = ce.report_view(data, SIGMA)
    (entry,) = practical_significance(d, view, ce.INTRINSIC_REPORTED)
    with_k1 = calibrate(data.points, data.pixels, data.view, 5, ("k1",), False, False)
    without = calibrate(data.points, data.pixels, data.view, 5, (), False, False)
    assert entry["rms_with"] == pytest.approx(with_k1.rms, rel=1e-6)
    assert entry["rms_without"] == pytest.approx(without.rms, rel=1e-6)
    shift = max(abs(with_k1.params[k] - without.params[k]) / d.after.stderr[k]
                for k in ("f", "cx", "cy"))
    assert entry["largest_shift_sigma"] == pytest.approx(max(shift, 1.0), rel=1e-4)
    assert entry["label"] == "significant, important"


def test_no_effect_names_nothing():
    _, d = _diagnose({}, seed=5)
    assert not d.named and not d.outliers


def test_a_bad_corner_is_flagged():
    data, d = _diagnose({}, seed=2, corner=(30, (1.5, -1.5)))
    assert [t.name for t in d.outliers] == [f"outlier:{data.views[data.view[30]]}/"
                                           f"{data.point_id[30]}"]
    assert not d.named
    # the report gives the flagged corner's own residual: near the injected shift, row 31
    from montecarlo.discrepancy.view import to_json

    (flagged,) = to_json(d, ce.report_view(data, SIGMA), "x")["outliers"]
    assert flagged["observation"] == 31
    assert flagged["size"]["u"] == pytest.approx(1.5, abs=0.5)
    assert flagged["size"]["v"] == pytest.approx(-1.5, abs=0.5)


def _cli(*args, cwd):
    env = {"PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg", "PATH": "/usr/bin:/bin"}
    return subprocess.run([sys.executable, "-m", "montecarlo", *args], cwd=cwd,
                          capture_output=True, text=True, env=env, timeout=600)


@pytest.mark.slow
def test_cli_emits_errors_that_run_accepts(tmp_path):
    out = _cli("diagnose", "camera", str(BAD / "csv" / "valid_camera_model.csv"),
               str(BAD / "csv" / "valid_camera_views.csv"), "--pixel-sigma-px", "0.2",
               "--json", str(tmp_path / "d.json"), "--emit-errors", "e.toml", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "per image coordinate" in out.stdout
    report = json.loads((tmp_path / "d.json").read_text())
    assert "radial_k1" in [e["name"] for e in report["named_effects"]]
    err = report["pixel_error"]
    errors = tomllib.loads((tmp_path / "e.toml").read_text())
    assert set(errors) == {"errors"}
    expected = math.sqrt(max(err["sigma_u"], err["sigma_v"]) ** 2
                         + err["distortion_bound"] ** 2 / 3)
    assert errors["errors"]["pixel_px"] == {"dist": "normal",
                                            "sigma": pytest.approx(expected, rel=1e-5)}
    out = _cli("run", str(BAD / "studies" / "valid_ground.toml"), "--errors", "e.toml",
               "--trials", "200", "--quiet", "--out", "res", "--n-jobs", "1", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    prov = json.loads((tmp_path / "res" / "provenance.json").read_text())
    assert prov["study_source"]["errors"]["pixel_px"] == errors["errors"]["pixel_px"]


@pytest.mark.slow
def test_zhangs_data_pinhole_rejected_radial_named():
    """Zhang's five views at a stated 0.25 px: the pinhole fails (rms 0.789 px per
    coordinate), radial_k1 is named first and the final model passes the global test."""
    data = read_camera_csv(CAMERA / "zhang_model.csv", CAMERA / "zhang_views.csv")
    d = diagnose(ce.camera_problem(data, 0.25))
    assert d.detected and d.named[0] == "radial_k1"
    # chi2_red = sum(r^2) / sigma^2 / dof: 2560 coordinates, 33 parameters
    assert d.before.chi2_red == pytest.approx((0.7891 / 0.25) ** 2 * 2560 / 2527, rel=1e-3)
    assert d.after.p_value > 0.01


@pytest.mark.slow
def test_zhangs_data_at_0p25_px_names_k1_and_k2_at_his_values():
    """At a stated 0.25 px (the final model leaves 0.236 px per coordinate) the global test
    of the model with k1 passes, but k2's own test (T = 55.6 on 1 dof) is rejected in the
    detection family: k1 and k2 are named, at Zhang's -0.228601 +- 0.003, 0.190353 +- 0.03,
    alpha 832.5 +- 1.5 px (tests/data/camera/README.md); the data give a noise scale whose
    95 % interval excludes 1 (0.25 px is a little too large)."""
    data = read_camera_csv(CAMERA / "zhang_model.csv", CAMERA / "zhang_views.csv")
    d = diagnose(ce.camera_problem(data, 0.25))
    assert d.named[:2] == ["radial_k1", "radial_k2"] and not d.outliers
    p = d.after.params
    assert abs(p["k1"] + 0.228601) < 0.003 and abs(p["k2"] - 0.190353) < 0.03
    assert abs(p["f"] - 832.5) < 1.5
    scale = noise_scale(d.after)
    assert scale["verdict"] == "stated too large" and 0.93 < scale["factor"] < 0.97


@pytest.mark.slow
def test_zhangs_data_at_0p2_px_names_his_two_radial_terms():
    """At a stated 0.2 px both of Zhang's radial terms are named; k1, k2 within 1 sigma of
    his -0.228601, 0.190353 (the final model also has tangential terms, skew and four
    corners flagged, which move them; tests/data/camera/README.md)."""
    data = read_camera_csv(CAMERA / "zhang_model.csv", CAMERA / "zhang_views.csv")
    d = diagnose(ce.camera_problem(data, 0.2))
    assert d.named[:2] == ["radial_k1", "radial_k2"]
    p, s = d.after.params, d.after.stderr
    assert abs(p["k1"] + 0.228601) < s["k1"] and abs(p["k2"] - 0.190353) < s["k2"]


def test_acceptance_small():
    """One set of each effect scenario on a 5 x 5 target at 3 MDB: the right name."""
    inj = ca.injections(SIGMA, 5)
    for scenario in ("radial", "tangential"):
        row = ca.one_set(scenario, inj[scenario], SIGMA, 11, 5)
        assert row["named"] == [ca.RIGHT[scenario]], row


def test_acceptance_small_view_scenarios():
    """k2 at 3 MDB (k1 in the data) is named after k1; a view with three times the stated
    noise, or its corners all shifted by 3 MDB of the clustering's shift test, leaves residuals
    that cluster by view and names no lens term."""
    inj = ca.injections(SIGMA, 8)
    assert inj["radial_k2"]["k1"] == ca.K1 and inj["radial_k2"]["k2"] > 0
    row = ca.one_set("radial_k2", inj["radial_k2"], SIGMA, 12, 8)
    assert row["named"][:2] == ["radial_k1", "radial_k2"], row
    row = ca.one_set("view_noise", (0.0, 3.0), SIGMA, 12, 8)
    assert row["clustered"] and not row["named"], row
    assert inj["view_offset"][0] == pytest.approx(3 * ca.offset_mdb(SIGMA, 8))
    row = ca.one_set("view_offset", inj["view_offset"], SIGMA, 12, 8)
    assert row["clustered"] and not row["named"] and not row["flagged"], row


@pytest.mark.slow
def test_acceptance_large(figures):
    """100 sets per scenario (6 x 6 target, 0.2 px): docs/reference/camera.md records the
    figures."""
    table = ca.run(100, grid=6, n_jobs=2)
    for scenario, key, low, high in (("radial", "right_named", 0.95, None),
                                     ("tangential", "right_named", 0.95, None),
                                     ("null", "anything_named", None, 0.02),
                                     ("bad_corner", "right_corner_flagged", 0.90, None)):
        figures.record(f"{scenario}.{key}", table[scenario][key], low, high)
    assert table["radial"]["right_named"] >= 0.95
    assert table["tangential"]["right_named"] >= 0.95
    assert table["null"]["anything_named"] <= 0.02
    assert table["bad_corner"]["right_corner_flagged"] >= 0.90


@pytest.mark.slow
def test_the_readme_chain(tmp_path):
    """README, "From a camera calibration to a range size": the two commands as printed."""
    import re
    import shlex

    text = (ROOT / "README.md").read_text()
    block = re.search(r"```sh\n(\.venv/bin/montecarlo diagnose camera.*?)```", text, re.S)
    commands = re.sub(r"\\\n\s*", " ", block.group(1)).strip().splitlines()
    assert [shlex.split(c)[1] for c in commands] == ["diagnose", "size"]
    (tmp_path / "tests").symlink_to(ROOT / "tests")
    for command in commands:
        out = _cli(*shlex.split(command)[1:], cwd=tmp_path)
        assert out.returncode == 0, out.stderr[-2000:]
    errors = tomllib.loads((tmp_path / "camera_errors.toml").read_text())
    assert errors["errors"]["pixel_px"]["sigma"] == pytest.approx(0.356, abs=0.0005)
    assert (tmp_path / "results" / "sizing" / "answers.csv").is_file()


def test_summarise_counts_by_hand():
    """Shares of hand-made rows; rows of a generator that does not say whether the residuals
    clustered (the blind one's) have no ``clustered`` share."""
    row = {"scenario": "null", "flagged": [], "right_corner": None}
    rows = [{**row, "named": []}, {**row, "named": ["radial_k1"]}]
    assert ca.summarise(rows) == {"null": {"sets": 2, "anything_named": 0.5,
                                           "any_corner_flagged": 0.0}}
    view = {**row, "scenario": "view_offset"}
    rows = [{**view, "named": [], "clustered": True}, {**view, "named": ["tangential"],
                                                       "clustered": True},
            {**view, "named": [], "clustered": False}, {**view, "named": [], "clustered": True}]
    table = ca.summarise(rows)["view_offset"]
    assert (table["clustered"], table["clustered_no_lens_term"]) == (0.75, 0.5)
