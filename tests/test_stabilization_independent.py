"""The seed 001 estimator and diagnosis, run as a user runs them, on recordings of a simulator
written blind.

``tests/independent/stabilization_second.py`` was written by another author from the patent text
(CN102288133B) and the brief beside it (``stabilization_second_brief.md``, which holds the data
format) only: every scenario number in it (rocking, gimbal start, camera, noise, angles) is its
author's, its kinematics are its own (scipy's ODE solver on eq. (4), its own rotations and
pinhole). Each recording is written to a CSV and a truth JSON, read by
``montecarlo stabilization estimate --json`` and ``montecarlo diagnose stabilization --json``
(the command-line entry point, in this process) with the options taken from the truth file, and
compared with the truth file.

Chosen independently, its conventions are the estimator's: passive matrices, the IMU
``R_y(δgy) R_x(δgx) R_z(δgz)``, the camera ``R_y(δpy) R_x(ε + δpx) R_z(η + δpz)`` with δpy the roll
about the LOS, the image ``f (x/y, z/y)`` with f = (pixels/2)/tan(fov/2), the target fixed where
the LOS points at t = 0, and the same reading of the misprinted δpx column of eq. (5) row 3
(first test).

Where its choices differ from the estimator's model:

- gyro noise: its default loop (``continuous``) drives the gimbal with the noise-free rate and
  adds the noise to the recorded column only; the estimator's model has the loop driven by the
  noisy rate. Either way the residual is the same random walk of the integrated gyro noise
  (here in the estimator's attitude, there in the LOS), of density ``σ/√rate``, which is the
  ``--gyro-arw-deg-per-rt-h`` given.
- encoder noise: it adds white noise to the recorded η and ε; the estimator has no such term
  (at its default 5e-6 rad it is 0.06 px beside 0.3 px of image noise).
- its ``zoh`` loop (a sampled controller holding the rates) leaves a drift of tens of pixels
  without installation angles; the estimator reads the gimbal angles as recorded, so it needs
  no model of the loop (slow test).
- without installation angles the camera roll δpy is not determined, and the diagnosis
  reports it as a large angle (a strict xfail, slow).
- frames with the target out of view are written as NaN; the reader refuses them.
- a recording with an image axis the other way round is named so, and effects fitted to it as
  it is are named beside (a strict xfail).
- no gyro bias: the three biases' truth is zero.

Tolerances come from the estimator's σ: with honest σ each ``(estimate - truth) / σ`` is
standard normal, so all 8 parameters of a run (the four combinations, δpy, three gyro biases)
lie within ``Φ⁻¹(1 - 0.001/16) = 3.84 σ`` with probability at least 0.999. Over ``m`` runs,
``Σ z²`` of each parameter is χ²_m, checked on both sides (slow tests).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats

from montecarlo.cli import main
from montecarlo.seed001.linear_model import los_rate_matrix, patent_eq6_matrix
from tests.independent import stabilization_second as second

DEG = math.pi / 180.0
ARCMIN = DEG / 60.0
DEG_PER_H = DEG / 3600.0
PARAMETERS = ("delta_px", "delta_gx", "delta_gy", "delta_z", "delta_py", "bias_x", "bias_y",
              "bias_z")
Z_RUN = stats.norm.ppf(1.0 - 0.001 / (2 * len(PARAMETERS)))
FAST = {"duration_s": 20.0, "rate_hz": 50.0}
"""A run of 20 s at 50 Hz; everything else is the second simulator's default scenario."""
SHORT = {"duration_s": 8.0, "rate_hz": 25.0}
"""A run of 8 s at 25 Hz for the diagnoses of other conventions (each refits up to four
times)."""
EXAMPLE = {"delta_g": (0.3 * DEG, -0.4 * DEG, 0.5 * DEG),
           "delta_p": (0.6 * DEG, 0.2 * DEG, -0.35 * DEG)}
"""The second simulator's example installation angles (its header)."""


def _record(tmp_path, seed: int, delta_g=EXAMPLE["delta_g"], delta_p=EXAMPLE["delta_p"],
            name: str = "run", **kw):
    """One recording of the second simulator, written to files: (csv path, truth read back)."""
    csv, truth = tmp_path / f"{name}.csv", tmp_path / f"{name}.json"
    second.simulate_recording(csv, truth, delta_g, delta_p, seed=seed, **{**FAST, **kw})
    return csv, json.loads(truth.read_text())


def _options(truth: dict) -> list[str]:
    """The command-line options a user would give for this recording, from its truth file."""
    camera, noise = truth["camera"], truth["noise_1sigma"]
    density = noise["gyro_rad_s"] / math.sqrt(truth["scenario"]["rate_hz"])  # rad/s/√Hz
    return ["--fov-deg", repr(math.degrees(camera["fov_rad"])), "--pixels", str(camera["pixels"]),
            "--image-noise-px", repr(noise["image_px"]),
            "--gyro-arw-deg-per-rt-h", repr(density / DEG * 60.0), "-q"]


def _run(capsys, *args: str) -> dict:
    assert main([*args, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def _true_values(truth: dict) -> dict[str, float]:
    """The truth file's angles [arcmin] named as the estimator names them; biases 0 [deg/h]."""
    g, p = truth["delta_g_rad"], truth["delta_p_rad"]
    delta_z = p["pz"] - g["gz"]
    assert delta_z == truth["delta_z_rad (= dpz - dgz, patent eq. 6)"]
    return {"delta_px": p["px"] / ARCMIN, "delta_gx": g["gx"] / ARCMIN,
            "delta_gy": g["gy"] / ARCMIN, "delta_z": delta_z / ARCMIN,
            "delta_py": p["py"] / ARCMIN, "bias_x": 0.0, "bias_y": 0.0, "bias_z": 0.0}


def _z(estimate: dict, truth: dict) -> np.ndarray:
    """(estimate - truth) / σ of each parameter, in the estimate's units."""
    true = _true_values(truth)
    p = estimate["parameters"]
    assert estimate["units"]["delta_*"] == "arcmin" and estimate["units"]["bias_*"] == "deg/h"
    return np.array([(p[k]["value"] - true[k]) / p[k]["sigma"] for k in PARAMETERS])


def test_derived_linear_model_agrees_with_the_second_authors_kinematics():
    """First order in the angles, the camera's pitch and azimuth rates of the second simulator
    (central differences of its exact ``camera_rate``) are the package's derived eq. (6),
    column for column; δpz and -δgz give the same column (only δz = δpz - δgz enters). Both
    authors read the printed H₂,₁ (row 3 of eq. (5), the δpx column) the same way: the
    printed one differs from both by sin ε · η̇."""
    rng = np.random.default_rng(36)
    h = 1e-6
    for _ in range(10):
        eta, eps = rng.uniform(-1.0, 1.0, 2)
        w = rng.normal(size=3)

        def rate(dg=(0.0, 0.0, 0.0), dp=(0.0, 0.0, 0.0), eta=eta, eps=eps, w=w):
            return second.camera_rate(eta, eps, w, dg, dp)[[0, 2]]

        def column(**angles):
            plus = rate(**{k: np.multiply(v, h) for k, v in angles.items()})
            minus = rate(**{k: np.multiply(v, -h) for k, v in angles.items()})
            return (plus - minus) / (2 * h)

        theirs = np.column_stack([column(dp=(1, 0, 0)), column(dg=(1, 0, 0)),
                                  column(dg=(0, 1, 0)), column(dp=(0, 0, 1))])
        assert np.allclose(column(dg=(0, 0, -1)), theirs[:, 3], atol=1e-8)
        ours = los_rate_matrix(w, eta, eps)
        assert np.allclose(theirs, ours, atol=1e-8)
        printed = patent_eq6_matrix(w, eta, eps, as_printed=False)
        eta_dot = second.gimbal_rates(eta, eps, w)[0]
        assert printed[1, 0] - theirs[1, 0] == pytest.approx(np.sin(eps) * eta_dot, abs=1e-8)
        assert np.allclose(np.delete(printed, 0, axis=1), np.delete(theirs, 0, axis=1),
                           atol=1e-8)


def test_estimate_on_an_independent_recording(tmp_path, capsys):
    """All 8 parameters within 3.84 σ of the truth file; the four combinations also within
    the acceptance's max(5 %, 0.01°)."""
    path, truth = _record(tmp_path, 11)
    est = _run(capsys, "stabilization", "estimate", str(path), *_options(truth))
    assert est["converged"] and est["rows"] == 1001
    z = _z(est, truth)
    assert np.all(np.abs(z) < Z_RUN), dict(zip(PARAMETERS, z.round(2), strict=True))
    true = _true_values(truth)
    for k in PARAMETERS[:4]:
        error = abs(est["parameters"][k]["value"] - true[k])
        assert error <= max(0.05 * abs(true[k]), 0.6), (k, error)  # 0.01° = 0.6′


def test_diagnosis_of_an_independent_recording_names_nothing(tmp_path, capsys):
    """The estimator's model, in the conventions the recording shares, fits it: the global
    test passes (χ²_red inside its 99 % band, encoder noise and all), no effect is named and,
    every angle being small, the conventions are not checked."""
    path, truth = _record(tmp_path, 18)
    d = _run(capsys, "diagnose", "stabilization", str(path), *_options(truth))
    lo, hi = d["chi2_red_band_99"]["before"]
    assert lo < d["gap"]["before"]["chi2_red"] < hi
    assert d["named_effects"] == [] and not d["detected"]
    assert d["conventions"] == {"checked": False, "large_angles_deg": {}, "named": [],
                                "fits": {}}


@pytest.fixture(scope="module")
def null_diagnosis(tmp_path_factory) -> dict:
    """``diagnose stabilization`` of a recording without installation angles (20 s at 50 Hz)."""
    folder = tmp_path_factory.mktemp("null")
    path, truth = _record(folder, 12, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    out = folder / "diagnosis.json"
    assert main(["diagnose", "stabilization", str(path), *_options(truth), "--json",
                 str(out)]) == 0
    return json.loads(out.read_text())


@pytest.mark.slow
def test_diagnosis_of_a_null_recording_names_nothing(null_diagnosis):
    """No installation angle: the global test passes, no effect and no convention is named."""
    d = null_diagnosis
    lo, hi = d["chi2_red_band_99"]["before"]
    assert lo < d["gap"]["before"]["chi2_red"] < hi
    assert d["named_effects"] == [] and not d["detected"]
    assert d["conventions"]["named"] == []


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "without installation angles the image does not drift, so the camera roll delta_py (seen "
    "only through the turn it gives the drift) is not determined; the base fit leaves it far "
    "from zero (96 deg and -70 deg in the refits on one such recording), the check of small "
    "angles does not weigh its uncertainty, and the diagnosis reports 'installation angles not "
    "small: the recording's frames or signs differ' and refits four conventions"))
def test_a_null_recording_reports_no_large_angle(null_diagnosis):
    """A recording without installation angles should not be reported as in other frames or
    signs, nor refitted in four conventions."""
    assert null_diagnosis["conventions"]["large_angles_deg"] == {}
    assert not null_diagnosis["conventions"]["checked"]


def test_frames_out_of_view_are_refused_with_one_line(tmp_path, capsys):
    """The second simulator writes a frame whose target left the field as NaN pixels. The reader
    does not skip such rows: it refuses the file, exit code 2, naming the first such row and
    its column (one line, no traceback)."""
    path, truth = _record(tmp_path, 13, (0.0, 0.0, 0.0), (0.0, 0.0, 30 * DEG), fov_rad=1 * DEG,
                          **SHORT)
    assert truth["frames_out_of_view"] > 0
    rows = np.genfromtxt(path, delimiter=",", names=True)
    first = int(np.flatnonzero(np.isnan(rows["los_x_px"]))[0])
    assert main(["stabilization", "estimate", str(path), *_options(truth), "--json"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"error: {path}: row {first + 2}, column 'los_x_px': 'nan' is not a finite number"


def _other_convention(path, column: str, name: str):
    """The same recording with one column's sign flipped (another author's convention)."""
    data = np.genfromtxt(path, delimiter=",", names=True)
    data[column] = -data[column]
    out = path.with_name(f"{name}.csv")
    np.savetxt(out, np.column_stack([data[c] for c in second.HEADER.split(",")]),
               delimiter=",", header=second.HEADER, comments="", fmt="%.15g")
    return out


@pytest.fixture(scope="module")
def image_axis_diagnosis(tmp_path_factory) -> dict:
    """``diagnose stabilization`` of an 8 s run at 25 Hz with its image z axis pointing down."""
    folder = tmp_path_factory.mktemp("image_axis")
    path, truth = _record(folder, 14, **SHORT)
    other = _other_convention(path, "los_z_px", "other")
    out = folder / "diagnosis.json"
    assert main(["diagnose", "stabilization", str(other), *_options(truth), "--json",
                 str(out)]) == 0
    return json.loads(out.read_text())


def test_an_image_axis_the_other_way_is_named(image_axis_diagnosis):
    """Image z pointing down: the model does not fit (global test failed, χ²_red far above its
    band); the refits with z negated, and with x negated, pass with small angles and both are
    named (negating both image axes is a half turn of the image, which the model explains by
    negating the four combinations)."""
    d = image_axis_diagnosis
    assert d["detected"]
    assert d["gap"]["before"]["chi2_red"] > 10.0 * d["chi2_red_band_99"]["before"][1]
    c = d["conventions"]
    assert c["checked"] and c["named"] == ["los_x_px", "los_z_px"]
    for column in ("los_x_px", "los_z_px"):
        assert c["fits"][column]["p_value"] > 0.01 and not c["fits"][column]["large_angles_deg"]


@pytest.mark.xfail(strict=True, reason=(
    "the search for effects runs on the recording as it is, before and regardless of the "
    "convention check: on this run it also names gyro_scale_factor, servo_lag and "
    "gyro_time_delay (with los_x_px negated instead: servo_lag, inner_gimbal_mount, "
    "gyro_scale_factor, gyro_time_delay), effects fitted to data in another convention"))
def test_a_named_convention_comes_without_effects(image_axis_diagnosis):
    """When a single sign change makes the model fit, no effect should be named beside it."""
    assert image_axis_diagnosis["conventions"]["named"]
    assert image_axis_diagnosis["named_effects"] == []


@pytest.mark.slow
@pytest.mark.parametrize("column", ["eta_rad", "eps_rad"])
def test_a_gimbal_angle_counted_the_other_way_is_named(tmp_path, capsys, column):
    """η counted clockwise, or ε downwards: the diagnosis names the column whose refit passes
    the global test with small angles."""
    path, truth = _record(tmp_path, 15, **SHORT)
    other = _other_convention(path, column, "other")
    d = _run(capsys, "diagnose", "stabilization", str(other), *_options(truth))
    c = d["conventions"]
    assert c["checked"] and c["named"] == [column]
    assert c["fits"][column]["p_value"] > 0.01 and not c["fits"][column]["large_angles_deg"]
    assert d["detected"] or c["large_angles_deg"]


@pytest.mark.slow
def test_the_second_simulators_own_scenario_in_full(tmp_path, capsys):
    """Its defaults as they are (60 s at 100 Hz, 6001 rows) with its example angles: all 8
    parameters within 3.84 σ. The encoder noise the model lacks (5e-6 rad, 0.06 px) adds
    (f σ_enc)² (1 + cos² ε) / 2 to the image noise's variance per axis: χ²_red is 1.037 in
    expectation while the 99 % band reaches 1.034, so the global test fails about half the
    time at this size (with the simulator's seed 3: 1.0339 against 1.0336, detected). What
    the diagnosis must then do is what it does: name no effect and no convention, leaving the
    misfit unexplained."""
    path, truth = _record(tmp_path, 16, duration_s=60.0, rate_hz=100.0)
    est = _run(capsys, "stabilization", "estimate", str(path), *_options(truth))
    z = _z(est, truth)
    assert np.all(np.abs(z) < Z_RUN), dict(zip(PARAMETERS, z.round(2), strict=True))
    d = _run(capsys, "diagnose", "stabilization", str(path), *_options(truth))
    noise, f = truth["noise_1sigma"], truth["camera"]["focal_px"]
    eps = np.genfromtxt(path, delimiter=",", names=True)["eps_rad"]
    share = (f * noise["encoder_rad"] / noise["image_px"]) ** 2 * (1 + np.mean(np.cos(eps) ** 2))
    expected, spread = 1.0 + share / 2, math.sqrt(2.0 / (2 * est["rows"]))
    assert abs(d["gap"]["before"]["chi2_red"] - expected) < 4 * spread
    assert d["named_effects"] == [] and d["conventions"]["named"] == []


def _random_runs(tmp_path, capsys, m: int, seed: int, **kw) -> np.ndarray:
    """z of the 8 parameters on m recordings with angles drawn in ±0.6° (the order of the
    second simulator's example) and the gimbal anywhere in ±40° azimuth and 0-30° elevation."""
    rng = np.random.default_rng(seed)
    z = []
    for i in range(m):
        dg, dp = tuple(rng.uniform(-0.6, 0.6, 3) * DEG), tuple(rng.uniform(-0.6, 0.6, 3) * DEG)
        path, truth = _record(tmp_path, 1000 * seed + i, dg, dp, name=f"run{i}",
                              eta0_rad=rng.uniform(-40.0, 40.0) * DEG,
                              eps0_rad=rng.uniform(0.0, 30.0) * DEG, **kw)
        est = _run(capsys, "stabilization", "estimate", str(path), *_options(truth))
        z.append(_z(est, truth))
    return np.array(z)


def _chi2_sums(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Σ z² of each parameter over the runs, and the χ²_m quantiles at 0.001/16 and 1 - 0.001/16."""
    z2 = np.sum(np.square(z), axis=0)
    print({k: round(float(v), 2) for k, v in zip(PARAMETERS, z2 / len(z), strict=True)})
    return z2, stats.chi2.ppf([0.001 / 16, 1.0 - 0.001 / 16], len(z))


@pytest.mark.slow
def test_sigma_is_honest_on_independent_recordings(tmp_path, capsys):
    """20 recordings of 20 s at 50 Hz: Σ z² of each of the 8 parameters is χ²₂₀, inside its
    quantiles at 0.001/16 and 1 - 0.001/16 (too small is a failure as much as too large)."""
    z = _random_runs(tmp_path, capsys, 20, 2026)
    z2, (lo, hi) = _chi2_sums(z)
    assert np.all((lo < z2) & (z2 < hi)), dict(zip(PARAMETERS, (z2 / len(z)).round(2),
                                                   strict=True))


@pytest.mark.slow
def test_sigma_on_recordings_of_a_sampled_loop(tmp_path, capsys):
    """The second simulator's ``zoh`` loop: a controller sampled at the recording's rate, fed
    with the recorded (noisy) gyro and encoder values, rates held over each sample. Its LOS
    drifts without installation angles (44 px in 20 s at 50 Hz, 22 px in 60 s at 100 Hz,
    noise-free), but the estimator predicts the image from the recorded gimbal angles, so the
    same χ² check holds."""
    z = _random_runs(tmp_path, capsys, 20, 2027, loop="zoh")
    z2, (lo, hi) = _chi2_sums(z)
    assert np.all((lo < z2) & (z2 < hi)), dict(zip(PARAMETERS, (z2 / len(z)).round(2),
                                                   strict=True))
