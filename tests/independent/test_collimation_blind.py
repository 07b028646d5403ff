"""Self-checks of collimation_blind.py (run: python -m pytest tests/independent -q -p no:cacheprovider).

First-order behaviour, derived by hand (reading conventions of the module; s = +1 cw / -1 ccw,
k = +1 right / -1 left roll mirror; a, e = mirror azimuth relative to the central mirror and
elevation; gamma, lambda small; phi = mount (INS) roll at the pointing):

 * Optical axis in body ~ x + g*y - l*z (FRD; -z is up).  Rolling by phi mixes the offsets:
   g' = g cos(phi) + s l sin(phi),  l' = l cos(phi) - s g sin(phi).
   For C = Rz(psi) Ry(theta), C (x + g' y - l' z) ~ dir(psi + g'/cos(theta), theta + l'), so
   autocollimation on (h, e) gives ABSOLUTE INS heading = h + offset - g'/cos(e), pitch = e - l'.
   => on horizontal azimuth mirrors a pitch offset is only a constant pitch bias -l; an azimuth
   offset on pitch mirrors shows as heading differences -g (1/cos e - 1) (about -g at e = 60 deg,
   the text's "在β=60°时,偏差...几乎与偏差γ相等").
 * RELATIVE readings (roll 0): the reference frame is the level frame yawed by -g, pitched by -l
   and rolled by +k l (its y axis is the INS axis at the roll mirror, l below the horizon).
   Undoing this small rotation (delta = (-k l, l, s g) about x, y, z) moves a direction (A, E) by
   dE = dy cos A - dx sin A and dA = dz + tan E (dx cos A + dy sin A), hence
     rel pitch   = e - l (1 - cos a - k s sin a)
     rel heading = a - g (1/cos e - 1) - s k l tan(e) cos(a) + l tan(e) sin(a).
   => a pitch offset shows on horizontal azimuth mirrors as a pitch error (2 l at a = 180 deg, the
   text's "在α=180°时,偏差Δβ几乎是偏差λ的两倍"), and as a heading error - s k l tan e on the pitch
   mirrors; an azimuth offset shows on pitch mirrors as -g (1/cos e - 1).
"""
import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from . import collimation_blind as cb

AS = 1.0 / 3600.0  # degrees per arcsec
COMBOS = [(side, sense) for side in ("right", "left") for sense in ("cw", "ccw")]


def d180(x):
    return (x + 180.0) % 360.0 - 180.0


def test_rotations_against_scipy():
    rng = np.random.default_rng(0)
    for _ in range(50):
        psi, theta, phi = rng.uniform(-3, 3), rng.uniform(-1.4, 1.4), rng.uniform(-3, 3)
        m = cb.euler_to_matrix(psi, theta, phi)
        ref = Rotation.from_euler("ZYX", [psi, theta, phi]).as_matrix()
        assert np.allclose(m, ref, atol=1e-13)
        back = cb.matrix_to_euler(m)
        assert np.allclose(Rotation.from_euler("ZYX", back).as_matrix(), ref, atol=1e-12)
        az, el = rng.uniform(-3, 3), rng.uniform(-1.4, 1.4)
        v = Rotation.from_euler("ZY", [az, el]).apply([1.0, 0, 0])
        assert np.allclose(cb.direction(az, el), v, atol=1e-13)
    # physical meaning in NED: heading 90 cw -> east; pitch up -> negative down; roll + -> right down
    assert np.allclose(cb.euler_to_matrix(math.pi / 2, 0, 0)[:, 0], [0, 1, 0], atol=1e-15)
    assert cb.euler_to_matrix(0, math.radians(10), 0)[2, 0] < 0
    assert cb.euler_to_matrix(0, 0, math.radians(10))[2, 1] > 0


def test_solve_attitude_exact():
    rng = np.random.default_rng(1)
    for _ in range(100):
        u = cb.optical_axis_body(*rng.normal(0, 5e-3, 2), s=1)
        d = cb.direction(rng.uniform(-3, 3), rng.uniform(-0.5, 0.5))
        phi = rng.normal(0, 0.3)
        psi, theta = cb.solve_attitude(d, u, phi)
        assert np.allclose(cb.euler_to_matrix(psi, theta, phi) @ u, d, atol=1e-14)


@pytest.mark.parametrize("side,sense", COMBOS)
def test_pipeline_against_scipy(side, sense):
    """Noise-free absolute INS attitude maps the optical axis onto the mirror line of sight."""
    s = 1 if sense == "cw" else -1
    g, l = 37.0, -23.0
    rows, t = cb.simulate(g, l, roll_mirror_side=side, azimuth_sense=sense, mount_roll_sigma_deg=2.0,
                          theodolite_sigma_arcsec=0, ins_sigma_arcsec=0, write_roll=True,
                          ins_heading_offset_deg=0.0, rng=3)
    u_b = Rotation.from_euler("ZY", [s * g * AS, l * AS], degrees=True).apply([1.0, 0, 0])
    for p in t["pointings"]:
        h, pit, r = p["ins_true"]
        att = Rotation.from_euler("ZYX", [s * h, pit, r], degrees=True)
        los_h = t["theodolite_zero_heading_deg"] + p["theodolite_true"][0]
        los = Rotation.from_euler("ZY", [s * los_h, p["theodolite_true"][1]], degrees=True).apply([1.0, 0, 0])
        assert np.allclose(att.apply(u_b), los, atol=1e-13)
    az_r = [p for p in t["pointings"] if p["mirror"] == "R"][0]["theodolite_true"][0]
    az_c = t["pointings"][0]["theodolite_true"][0]
    expected = 90.0 if (side == "right") == (sense == "cw") else -90.0
    assert abs(d180(az_r - az_c) - expected) < 1e-9


@pytest.mark.parametrize("side,sense", COMBOS)
def test_zero_offsets_absolute(side, sense):
    rows, t = cb.simulate(0, 0, roll_mirror_side=side, azimuth_sense=sense, mount_roll_sigma_deg=3.0,
                          theodolite_sigma_arcsec=0, ins_sigma_arcsec=0, write_roll=True,
                          ins_heading_offset_deg=0.37, rng=5)
    assert [r["set"] for r in rows[:2]] == ["reference_center", "reference_roll"]
    const = t["theodolite_zero_heading_deg"] + 0.37
    for r, p in zip(rows, t["pointings"]):
        assert abs(d180(r["ins_az_deg"] - r["theodolite_az_deg"] - const)) < 1e-9
        assert abs(r["ins_el_deg"] - r["theodolite_el_deg"]) < 1e-9
        assert abs(r["ins_roll_deg"] - p["mount_roll_deg"]) < 1e-12


@pytest.mark.parametrize("side,sense", COMBOS)
def test_zero_offsets_relative(side, sense):
    for zero in (None, 123.4):
        rows, t = cb.simulate(0, 0, roll_mirror_side=side, azimuth_sense=sense, reference_rows=False,
                              mount_roll_sigma_deg=3.0, theodolite_sigma_arcsec=0, ins_sigma_arcsec=0,
                              theodolite_zero_heading_deg=zero, ins_heading_offset_deg=1.5, rng=6)
        assert len(rows) == 10 and not any(r["set"].startswith("reference") for r in rows)
        az_c = t["pointings"][0]["theodolite_true"][0]
        for r in rows:
            assert abs(d180(r["ins_az_deg"] - (r["theodolite_az_deg"] - az_c))) < 1e-9
            assert abs(r["ins_el_deg"] - r["theodolite_el_deg"]) < 1e-9


@pytest.mark.parametrize("side,sense", COMBOS)
def test_reference_relations_exact_with_noise(side, sense):
    rows, t = cb.simulate(80, -60, roll_mirror_side=side, azimuth_sense=sense, mount_roll_sigma_deg=2.0,
                          theodolite_sigma_arcsec=2, ins_sigma_arcsec=20, rng=7)
    c, r = t["pointings"][0], t["pointings"][1]
    assert abs(c["ins_relative"][0]) < 1e-10 and abs(c["ins_relative"][1]) < 1e-10
    assert abs(r["ins_relative"][1]) < 1e-10
    expected = 90.0 if (side == "right") == (sense == "cw") else -90.0
    assert abs(r["ins_relative"][0] - expected) < 0.02
    # relative readings do not depend on central heading / theodolite zero / INS heading offset
    kw = dict(roll_mirror_side=side, azimuth_sense=sense, reference_rows=False,
              theodolite_sigma_arcsec=0, ins_sigma_arcsec=0, mount_rolls_deg=0.0)
    r1, _ = cb.simulate(80, -60, central_heading_deg=10, ins_heading_offset_deg=0, rng=1, **kw)
    r2, _ = cb.simulate(80, -60, central_heading_deg=250, ins_heading_offset_deg=2, rng=2, **kw)
    for a, b in zip(r1, r2):
        assert abs(a["ins_az_deg"] - b["ins_az_deg"]) < 1e-9 and abs(a["ins_el_deg"] - b["ins_el_deg"]) < 1e-9


@pytest.mark.parametrize("side,sense", COMBOS)
@pytest.mark.parametrize("g,l,phi", [(30.0, 0.0, 0.0), (0.0, 30.0, 0.0), (25.0, -40.0, 2.5), (-40.0, 15.0, -4.0)])
def test_first_order_absolute(side, sense, g, l, phi):
    s = 1 if sense == "cw" else -1
    azs = [-30, -15, 15, 30, 45, 90, 180]
    els = [4, 7.5, 11, 14.5, 18, 60]
    rows, t = cb.simulate(g, l, roll_mirror_side=side, azimuth_sense=sense, mount_rolls_deg=phi,
                          theodolite_sigma_arcsec=0, ins_sigma_arcsec=0, azimuths_deg=azs,
                          pitch_elevations_deg=els, ins_heading_offset_deg=0.2, rng=8)
    f = math.radians(phi)
    gp = g * math.cos(f) + s * l * math.sin(f)
    lp = l * math.cos(f) - s * g * math.sin(f)
    const = t["theodolite_zero_heading_deg"] + 0.2
    for r in rows:
        e = r["theodolite_el_deg"]
        dh = d180(r["ins_az_deg"] - r["theodolite_az_deg"] - const) / AS
        assert abs(dh - (-gp / math.cos(math.radians(e)))) < 0.02
        assert abs((r["ins_el_deg"] - e) / AS - (-lp)) < 0.02


@pytest.mark.parametrize("side,sense", COMBOS)
@pytest.mark.parametrize("g,l", [(30.0, 0.0), (0.0, 30.0), (-45.0, 25.0)])
def test_first_order_relative(side, sense, g, l):
    s = 1 if sense == "cw" else -1
    k = 1 if side == "right" else -1
    azs = [-30, -15, 15, 30, 45, 180]
    els = [4, 7.5, 11, 14.5, 18, 60]
    rows, _ = cb.simulate(g, l, roll_mirror_side=side, azimuth_sense=sense, reference_rows=False,
                          theodolite_sigma_arcsec=0, ins_sigma_arcsec=0, azimuths_deg=azs,
                          pitch_elevations_deg=els, rng=9)
    for r in rows:
        a, e = math.radians(r["theodolite_az_deg"]), math.radians(r["theodolite_el_deg"])
        pe = math.degrees(e) - l * AS * (1 - math.cos(a) - k * s * math.sin(a))
        pa = (math.degrees(a) - g * AS * (1 / math.cos(e) - 1)
              - s * k * l * AS * math.tan(e) * math.cos(a) + l * AS * math.tan(e) * math.sin(a))
        assert abs(d180(r["ins_az_deg"] - pa)) / AS < 0.02, r
        assert abs(r["ins_el_deg"] - pe) / AS < 0.02, r
    a180 = [r for r in rows if r["mirror"] == "A6"][0]
    assert abs(a180["ins_el_deg"] / AS - (-2 * l)) < 0.02  # the text's "Δβ ≈ 2λ at α = 180°"


def test_noise_statistics():
    n = 600
    rows, t = cb.simulate(20, 10, theodolite_sigma_arcsec=(2.0, 3.0), ins_sigma_arcsec=(5.0, 4.0, 7.0),
                          azimuths_deg=np.linspace(-60, 60, n), pitch_elevations_deg=[], write_roll=True,
                          mount_roll_sigma_deg=1.0, rng=11)
    ps = t["pointings"]
    m = len(ps)
    th = np.array([[d180(p["theodolite"][0] - p["theodolite_true"][0]), p["theodolite"][1] - p["theodolite_true"][1]]
                   for p in ps]) / AS
    ins = np.array([[d180(p["ins"][0] - p["ins_true"][0]), p["ins"][1] - p["ins_true"][1], p["ins"][2] - p["ins_true"][2]]
                    for p in ps]) / AS
    for sample, sig in zip(np.hstack([th, ins]).T, [2.0, 3.0, 5.0, 4.0, 7.0]):
        assert abs(sample.std(ddof=1) - sig) < 4 * sig / math.sqrt(2 * (m - 1))
        assert abs(sample.mean()) < 4 * sig / math.sqrt(m)
    # rows carry exactly the noisy readings
    for r, p in zip(rows, ps):
        assert r["ins_az_deg"] == p["ins"][0] and r["theodolite_el_deg"] == p["theodolite"][1]


def test_mount_roll_options_and_csv(tmp_path):
    rows, t = cb.simulate(0, 0, mount_rolls_deg={"A1": 5.0}, write_roll=False, rng=1)
    assert [p["mount_roll_deg"] for p in t["pointings"]][2] == 5.0 and "ins_roll_deg" not in rows[0]
    with pytest.raises(ValueError):
        cb.simulate(0, 0, mount_rolls_deg=[1.0, 2.0], rng=1)
    out = tmp_path / "x.csv"
    cb.main([str(out), "--seed", "4", "--gamma-arcsec", "30", "--lambda-arcsec", "-20",
             "--roll-mirror-side", "left", "--azimuth-sense", "ccw", "--no-reference-rows", "--with-roll",
             "--mount-roll-sigma-deg", "1"])
    lines = out.read_text().splitlines()
    assert lines[0] == "mirror,set,theodolite_az_deg,theodolite_el_deg,ins_az_deg,ins_el_deg,ins_roll_deg"
    assert len(lines) == 11 and all(len(x.split(",")) == 7 for x in lines)
    truth = json.loads((tmp_path / "x.truth.json").read_text())
    assert truth["gamma_arcsec"] == 30 and truth["roll_mirror_side"] == "left" and truth["seed"] == 4
    assert truth["azimuth_sense"] == "ccw" and "conventions" in truth
    cb.main([str(out), "--seed", "4"])
    lines = out.read_text().splitlines()
    assert lines[0] == "mirror,set,theodolite_az_deg,theodolite_el_deg,ins_az_deg,ins_el_deg"
    assert lines[1].startswith("C,reference_center,") and lines[2].startswith("R,reference_roll,")
