"""Self-checks of the simulated seed 003 procedure against hand-worked and independent results."""

import csv
import io
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from .collimation_procedure import (
    ARCSEC,
    DEG,
    direction,
    euler_readings,
    main,
    paper_like_layout,
    pitch_to_60_layout,
    point_ins,
    simulate_procedure,
)

ROOT = Path(__file__).resolve().parents[2]
NOISE_FREE = {"sigma_theodolite_arcsec": 0.0, "sigma_ins_arcsec": 0.0}
TOL_DEG = 1e-9 / 3600.0
"""1e-9 arcsec [deg]: round-off of a few rotations."""


def rows(text: str) -> dict[str, dict[str, float | str]]:
    """Rows of a simulated CSV by mirror, numbers as floats [deg]."""
    return {r["mirror"]: {k: (v if k in ("mirror", "set") else float(v)) for k, v in r.items()}
            for r in csv.DictReader(io.StringIO(text))}


def matrix(row) -> np.ndarray:
    """C_b^n of a CSV row's INS heading, pitch, (roll) [deg]."""
    return Rotation.from_euler(
        "ZXY", [-row["ins_az_deg"], row["ins_el_deg"], row.get("ins_roll_deg", 0.0)],
        degrees=True).as_matrix()


def relative_from_absolute(table, side: float = 1.0) -> dict[str, np.ndarray]:
    """Heading, pitch, roll [deg] relative to the reference, from the absolute rows; ``side``
    is +1 with the roll mirror on the right, -1 on the left."""
    center = next(matrix(r) for r in table.values() if r["set"] == "reference_center")
    roll = next(matrix(r) for r in table.values() if r["set"] == "reference_roll")
    y = center[:, 1]
    x = roll[:, 1] - np.dot(roll[:, 1], y) * y
    x *= side / np.linalg.norm(x)
    ref = np.column_stack([x, y, np.cross(x, y)])
    return {m: euler_readings(ref.T @ matrix(r)) / DEG for m, r in table.items()}


def wrap_deg(a):
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


@pytest.mark.parametrize("seed", range(20))
def test_pointing_satisfies_the_autocollimation_equation_and_the_roll(seed):
    rng = np.random.default_rng(seed)
    u = direction(*rng.normal(0.0, 600 * ARCSEC, 2))
    v = direction(rng.uniform(-np.pi, np.pi), rng.uniform(-1.2, 1.2))
    roll = rng.normal(0.0, 2 * DEG)
    c = point_ins(u, v, roll)
    np.testing.assert_allclose(c @ c.T, np.eye(3), atol=1e-14)
    assert np.linalg.det(c) == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_allclose(c @ u, v, rtol=0.0, atol=1e-12)
    assert euler_readings(c)[2] == pytest.approx(roll, abs=1e-12)
    assert abs(euler_readings(c)[1]) < np.pi / 2


def test_pointing_agrees_with_a_numerical_solution():
    """Least squares over heading and pitch at the given roll, started from the normal's angles."""
    rng = np.random.default_rng(21)
    u = direction(400 * ARCSEC, -300 * ARCSEC)
    for _ in range(5):
        az, el, roll = rng.uniform(-np.pi, np.pi), rng.uniform(-1.0, 1.0), rng.normal(0, DEG)
        v = direction(az, el)

        def miss(x, v=v, roll=roll):
            return Rotation.from_euler("ZXY", [-x[0], x[1], roll]).apply(u) - v

        fit = least_squares(miss, [az, el], xtol=1e-15, ftol=1e-15, gtol=1e-15)
        expected = Rotation.from_euler("ZXY", [-fit.x[0], fit.x[1], roll]).as_matrix()
        np.testing.assert_allclose(point_ins(u, v, roll), expected, atol=1e-10)


def test_pointing_refuses_an_unreachable_normal():
    with pytest.raises(ValueError, match="no attitude"):
        point_ins(np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]), 0.0)


def test_centre_reference_reads_zero_heading_and_pitch_whatever_the_rolls():
    text = simulate_procedure(paper_like_layout(), 300.0, -450.0, rng=np.random.default_rng(1),
                              roll_sigma_deg=2.0, record_roll=True, **NOISE_FREE)
    relative = relative_from_absolute(rows(text))
    np.testing.assert_allclose(relative["C"][:2], 0.0, atol=TOL_DEG)
    assert abs(relative["C"][2]) > 0.01  # the rolls differ, yet heading and pitch are zero


def test_a_measured_mirror_at_the_centre_reads_zero_on_a_level_mount():
    layout = [*paper_like_layout(), ("A0", "azimuth", 0.0, 0.0)]
    text = simulate_procedure(layout, 600.0, 600.0, rng=np.random.default_rng(2),
                              reference_rows=False, **NOISE_FREE)
    r = rows(text)["A0"]
    np.testing.assert_allclose([r["ins_az_deg"], r["ins_el_deg"]], 0.0, atol=TOL_DEG)


@pytest.mark.parametrize("roll_mirror", ["right", "left"])
def test_zero_offsets_level_mount_read_mirror_angles_relative_to_the_centre(roll_mirror):
    rng = np.random.default_rng(3)
    az_c = 10.0
    roll_az = az_c + (90.0 if roll_mirror == "right" else -90.0) + 15.0 / 3600.0
    measured = [(f"M{i}", "pitch", az, el) for i, (az, el) in
                enumerate(zip(rng.uniform(-60, 60, 8), rng.uniform(-5, 60, 8), strict=True))]
    layout = [("C", "reference_center", az_c, 0.0), ("R", "reference_roll", roll_az, 0.0),
              *measured]
    text = simulate_procedure(layout, 0.0, 0.0, rng=rng, roll_mirror=roll_mirror,
                              reference_rows=False, record_roll=True, **NOISE_FREE)
    table = rows(text)
    for mirror, _, az, el in measured:
        r = table[mirror]
        assert r["ins_az_deg"] == pytest.approx(az - az_c, abs=TOL_DEG)
        assert r["ins_el_deg"] == pytest.approx(el, abs=TOL_DEG)
        assert r["ins_roll_deg"] == pytest.approx(0.0, abs=TOL_DEG)
        assert r["theodolite_az_deg"] == pytest.approx(az, abs=TOL_DEG)
        assert r["theodolite_el_deg"] == pytest.approx(el, abs=TOL_DEG)


def test_relative_readings_do_not_depend_on_the_heading_of_the_theodolite_zero():
    def run(heading, reference_rows):
        return rows(simulate_procedure(
            pitch_to_60_layout(), 250.0, -120.0, rng=np.random.default_rng(4),
            sigma_theodolite_arcsec=2.0, sigma_ins_arcsec=3.0, roll_sigma_deg=1.0,
            record_roll=True, reference_rows=reference_rows,
            heading_of_theodolite_zero_deg=heading))

    keys = ["theodolite_az_deg", "theodolite_el_deg", "ins_az_deg", "ins_el_deg", "ins_roll_deg"]
    base, base_abs = run(0.0, False), run(0.0, True)
    for heading in (40.0, 179.99, -123.0):
        other, other_abs = run(heading, False), run(heading, True)
        for m in base:
            np.testing.assert_allclose([other[m][k] for k in keys], [base[m][k] for k in keys],
                                       rtol=0.0, atol=TOL_DEG)
        for m in base_abs:  # absolute headings turn with the zero, nothing else does
            shift = wrap_deg(other_abs[m]["ins_az_deg"] - base_abs[m]["ins_az_deg"] - heading)
            assert shift == pytest.approx(0.0, abs=TOL_DEG)
            for k in ("ins_el_deg", "ins_roll_deg"):
                assert other_abs[m][k] == pytest.approx(base_abs[m][k], abs=TOL_DEG)


@pytest.mark.parametrize("roll_mirror", ["right", "left"])
def test_relative_and_absolute_files_describe_the_same_readings(roll_mirror):
    def run(reference_rows):
        return rows(simulate_procedure(
            paper_like_layout(roll_mirror), -500.0, 350.0, rng=np.random.default_rng(5),
            roll_sigma_deg=1.5, record_roll=True, roll_mirror=roll_mirror,
            reference_rows=reference_rows, **NOISE_FREE))

    absolute, relative = run(True), run(False)
    assert {r["set"] for r in relative.values()} == {"azimuth", "pitch"}
    assert set(absolute) == set(relative) | {"C", roll_mirror[0].upper()}
    derived = relative_from_absolute(absolute, 1.0 if roll_mirror == "right" else -1.0)
    for m, r in relative.items():
        np.testing.assert_allclose([r["ins_az_deg"], r["ins_el_deg"], r["ins_roll_deg"]],
                                   derived[m], rtol=0.0, atol=TOL_DEG)


def test_attitude_angles_follow_the_stated_conventions():
    heading, pitch, roll = 0.3, 0.2, 0.1
    c = Rotation.from_euler("ZXY", [-heading, pitch, roll]).as_matrix()
    np.testing.assert_allclose(c[:, 1], direction(heading, pitch), atol=1e-15)
    assert c[2, 0] < 0.0  # positive roll: right side down
    np.testing.assert_allclose(euler_readings(c), [heading, pitch, roll], atol=1e-15)


def test_positive_gamma_turns_the_optical_axis_right():
    """By hand (level mount, lam = 0, h_t = 0): u = direction(gamma, 0) lands on a horizontal
    normal at azimuth a when the INS heads a - gamma; the reference is the centre pointing turned
    by -gamma, so each azimuth mirror reads exactly its azimuth."""
    gamma = 100.0
    args = {"rng": np.random.default_rng(6), "heading_of_theodolite_zero_deg": 0.0, **NOISE_FREE}
    absolute = rows(simulate_procedure(paper_like_layout(), gamma, 0.0, **args))
    assert absolute["C"]["ins_az_deg"] == pytest.approx(-gamma / 3600.0, abs=TOL_DEG)
    assert absolute["A1"]["ins_az_deg"] == pytest.approx(-30.0 - gamma / 3600.0, abs=TOL_DEG)
    assert absolute["R"]["ins_az_deg"] == pytest.approx(90.0 - gamma / 3600.0, abs=TOL_DEG)
    assert absolute["C"]["ins_el_deg"] == pytest.approx(0.0, abs=TOL_DEG)
    relative = rows(simulate_procedure(paper_like_layout(), gamma, 0.0, reference_rows=False,
                                       **args))
    for m, az in zip(["A1", "A2", "A3", "A4", "A5"], [-30, -15, 15, 30, 45], strict=True):
        assert relative[m]["ins_az_deg"] == pytest.approx(az, abs=TOL_DEG)
        assert relative[m]["ins_el_deg"] == pytest.approx(0.0, abs=TOL_DEG)


def test_positive_lam_turns_the_optical_axis_up():
    """By hand (level mount, gamma = 0, h_t = 0, s = sin lam): the centre pointing has pitch -lam,
    y_R = (0, cos lam, -s) and x_R = (1, -s^2, -s cos lam)/sqrt(1 + s^2); a pitch mirror at
    elevation b is autocollimated with the INS axis d = direction(0, b - lam), so it reads heading
    atan2(x_R.d, y_R.d) = atan2(-s sin b / sqrt(1 + s^2), cos b) (to the left) and pitch
    asin(sin b / sqrt(1 + s^2)). With z_R = (s, s, cos lam)/sqrt(1 + s^2), a horizontal mirror at
    azimuth a (INS axis direction(a, -lam)) reads pitch
    asin(s cos lam (sin a + cos a - 1)/sqrt(1 + s^2)). The centre pointing, relative to R, has
    roll -atan(s): the reference's x axis is the INS axis at the roll mirror, pitched down."""
    lam = 600.0
    args = {"rng": np.random.default_rng(7), "heading_of_theodolite_zero_deg": 0.0, **NOISE_FREE}
    absolute = rows(simulate_procedure(paper_like_layout(), 0.0, lam, **args))
    assert absolute["C"]["ins_el_deg"] == pytest.approx(-lam / 3600.0, abs=TOL_DEG)
    assert absolute["C"]["ins_az_deg"] == pytest.approx(0.0, abs=TOL_DEG)
    centre_roll = relative_from_absolute(absolute)["C"][2]
    assert centre_roll == pytest.approx(-np.rad2deg(np.arctan(np.sin(lam * ARCSEC))), abs=TOL_DEG)
    relative = rows(simulate_procedure(pitch_to_60_layout(), 0.0, lam, reference_rows=False,
                                       **args))
    s, b = np.sin(lam * ARCSEC), np.deg2rad(60.0)
    heading = np.arctan2(-s * np.sin(b) / np.sqrt(1 + s**2), np.cos(b))
    pitch = np.arcsin(np.sin(b) / np.sqrt(1 + s**2))
    assert relative["P5"]["ins_az_deg"] == pytest.approx(np.rad2deg(heading), abs=TOL_DEG)
    assert relative["P5"]["ins_el_deg"] == pytest.approx(np.rad2deg(pitch), abs=TOL_DEG)
    assert relative["P5"]["ins_az_deg"] * 3600 == pytest.approx(-lam * np.tan(b), rel=1e-3)
    for m, a in zip(["A1", "A2", "A3", "A4", "A5"], np.deg2rad([-30, -15, 15, 30, 45]),
                    strict=True):
        pitch = np.arcsin(s * np.cos(lam * ARCSEC) * (np.sin(a) + np.cos(a) - 1)
                          / np.sqrt(1 + s**2))
        assert relative[m]["ins_el_deg"] == pytest.approx(np.rad2deg(pitch), abs=TOL_DEG)


def test_reading_noise_has_the_requested_spread():
    """Twin runs share the rolls; their differences are the INS noise, whose sample standard
    deviation over n draws lies within 5 sigma / sqrt(2 n) of sigma."""
    sigma, diffs = 3.0, []
    for seed in range(200):
        kwargs = {"roll_sigma_deg": 1.0, "record_roll": True, "reference_rows": False}
        noisy = rows(simulate_procedure(paper_like_layout(), 100.0, 100.0,
                                        rng=np.random.default_rng(seed),
                                        sigma_theodolite_arcsec=2.0, sigma_ins_arcsec=sigma,
                                        **kwargs))
        clean = rows(simulate_procedure(paper_like_layout(), 100.0, 100.0,
                                        rng=np.random.default_rng(seed), **NOISE_FREE, **kwargs))
        diffs += [(noisy[m][k] - clean[m][k]) * 3600.0 for m in noisy
                  for k in ("ins_az_deg", "ins_el_deg", "ins_roll_deg")]
    assert abs(np.std(diffs) / sigma - 1.0) < 5.0 / np.sqrt(2 * len(diffs))
    assert abs(np.mean(diffs)) < 5.0 * sigma / np.sqrt(len(diffs))


def test_csv_columns_and_sets():
    text = simulate_procedure(paper_like_layout(), 10.0, 10.0, rng=np.random.default_rng(8),
                              sigma_theodolite_arcsec=2.0, sigma_ins_arcsec=2.0)
    header, *body = list(csv.reader(io.StringIO(text)))
    assert header == ["mirror", "set", "theodolite_az_deg", "theodolite_el_deg", "ins_az_deg",
                      "ins_el_deg"]
    assert [r[1] for r in body] == ["reference_center", "reference_roll"] + ["azimuth"] * 5 \
        + ["pitch"] * 5


def test_a_roll_mirror_on_the_wrong_side_is_refused():
    with pytest.raises(ValueError, match="not on the left"):
        simulate_procedure(paper_like_layout("right"), 0.0, 0.0, rng=np.random.default_rng(9),
                           roll_mirror="left", **NOISE_FREE)


def test_cli_writes_what_the_function_returns(tmp_path):
    out = tmp_path / "cal.csv"
    assert main([str(out), "--gamma-arcsec", "120", "--lam-arcsec", "-80", "--seed", "11",
                 "--sigma-ins-arcsec", "2", "--layout", "pitch60", "--record-roll"]) == 0
    expected = simulate_procedure(pitch_to_60_layout(), 120.0, -80.0,
                                  rng=np.random.default_rng(11), sigma_theodolite_arcsec=2.0,
                                  sigma_ins_arcsec=2.0, record_roll=True)
    assert out.read_text() == expected


def test_cli_refuses_a_negative_sigma_with_exit_code_2(tmp_path, capsys):
    out = tmp_path / "cal.csv"
    with pytest.raises(SystemExit) as stop:
        main([str(out), "--gamma-arcsec", "1", "--lam-arcsec", "1", "--seed", "1",
              "--sigma-ins-arcsec", "-2"])
    assert stop.value.code == 2
    assert "--sigma-ins-arcsec must be >= 0, got -2.0" in capsys.readouterr().err
    assert not out.exists()


def test_module_runs_as_a_script(tmp_path):
    out = tmp_path / "cal.csv"
    done = subprocess.run([sys.executable, "-m", "tests.independent.collimation_procedure",
                           str(out), "--gamma-arcsec", "30", "--lam-arcsec", "30", "--seed", "1",
                           "--sigma-ins-arcsec", "1", "--no-reference-rows"],
                          cwd=ROOT, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert len(rows(out.read_text())) == 10
