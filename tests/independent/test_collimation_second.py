"""Tests of collimation_second.py against things it does not compute itself: scipy's Rotation,
hand-derived closed forms, finite differences of small-angle derivatives derived by hand, and the
qualitative statements of section 2 of the seed text checked numerically.

Kept as its author wrote it but for two changes that let it run under this repository's pytest
configuration: ``import collimation_second as cs`` became ``from . import collimation_second as
cs`` (the tests are a package here), and ``json.load(open(json_path, ...))`` in
``test_written_files`` became a ``with open(...)`` block (the unclosed file's ResourceWarning is
an error under ``filterwarnings = error``).
"""
import csv
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation as Rot

from . import collimation_second as cs

AS = 1.0 / 3600.0  # arc-second in degrees
QUIET = dict(theodolite_sigma_arcsec=0.0, ins_heading_sigma_arcsec=0.0, ins_pitch_sigma_arcsec=0.0,
             ins_roll_sigma_arcsec=0.0, mount_roll_jitter_arcsec=0.0, mirror_tolerance_arcsec=0.0)


def sim(**kw):
    args = dict(QUIET)
    args.update(kw)
    header, rows, truth = cs.simulate(**args)
    return header, {r[0]: r for r in rows}, truth


def ang_diff(a, b):
    return (np.asarray(a) - np.asarray(b) + 180.0) % 360.0 - 180.0


# ---------------------------------------------------------------- rotations vs scipy
@pytest.mark.parametrize("seq,sp", [("heading-pitch-roll", "ZYX"), ("heading-roll-pitch", "ZXY")])
def test_attitude_matrix_and_angles_match_scipy(seq, sp):
    rng = np.random.default_rng(1)
    for _ in range(50):
        psi, th, ph = rng.uniform(-np.pi, np.pi), rng.uniform(-1.4, 1.4), rng.uniform(-1.4, 1.4)
        angles = [psi, th, ph] if sp == "ZYX" else [psi, ph, th]
        R = Rot.from_euler(sp, angles).as_matrix()
        assert np.allclose(cs.attitude_matrix(psi, th, ph, seq), R, atol=1e-13)
        p2, t2, f2 = cs.attitude_angles(R, seq)
        e = Rot.from_matrix(R).as_euler(sp)
        ref = (e[0], e[1], e[2]) if sp == "ZYX" else (e[0], e[2], e[1])
        assert np.allclose([p2, t2, f2], ref, atol=1e-10)


@pytest.mark.parametrize("seq,sp", [("heading-pitch-roll", "ZYX"), ("heading-roll-pitch", "ZXY")])
def test_solve_pointing_puts_optical_axis_on_mirror_direction(seq, sp):
    rng = np.random.default_rng(2)
    for _ in range(200):
        az, el = rng.uniform(-np.pi, np.pi), rng.uniform(-1.3, 1.3)
        d = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)])  # NED
        g, l, phi = rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), rng.uniform(-0.2, 0.2)
        u = Rot.from_euler("ZY", [g, l]).apply([1.0, 0.0, 0.0])   # intrinsic Rz(g) Ry(l)
        assert np.allclose(u, cs.optical_axis(g, l))
        psi, th = cs.solve_pointing(d, phi, u, seq)
        angles = [psi, th, phi] if sp == "ZYX" else [psi, phi, th]
        assert np.allclose(Rot.from_euler(sp, angles).apply(u), d, atol=1e-12)
        assert abs(th) <= np.pi / 2


def test_offset_sign_definition():
    # gamma>0 right of roll axis (east when heading north), lambda>0 above (NED z negative)
    u = cs.optical_axis(np.radians(0.1), 0.0)
    assert u[1] > 0
    u = cs.optical_axis(0.0, np.radians(0.1))
    assert u[2] < 0


# ---------------------------------------------------------------- hand-derived cases
def test_zero_offsets_readings_equal_mirror_geometry():
    H, zero, roll = 37.5, 123.4, 0.4
    az_m, pi_m = (-45.0, 20.0, 70.0), (-30.0, 60.0)
    _, r, _ = sim(azimuth_offset_arcsec=0, pitch_offset_arcsec=0, azimuth_mirrors_deg=az_m,
                  pitch_mirrors_deg=pi_m, setup_heading_deg=H, mount_roll_deg=roll,
                  theodolite_az_zero_deg=zero)
    for i, a in enumerate(az_m):
        row = r[f"A{i + 1}"]
        assert abs(ang_diff(row[2], H + a - zero)) < 1e-9 and abs(row[3]) < 1e-9
        assert abs(ang_diff(row[4], H + a)) < 1e-9 and abs(row[5]) < 1e-9 and abs(row[6] - roll) < 1e-9
    for j, b in enumerate(pi_m):
        row = r[f"P{j + 1}"]
        assert abs(ang_diff(row[2], H - zero)) < 1e-9 and abs(row[3] - b) < 1e-9
        assert abs(ang_diff(row[4], H)) < 1e-9 and abs(row[5] - b) < 1e-9
    assert abs(ang_diff(r["REF_R"][4], H + 90)) < 1e-9
    for mode in ("mirror_frame", "center_attitude"):
        _, r, _ = sim(azimuth_offset_arcsec=0, pitch_offset_arcsec=0, azimuth_mirrors_deg=az_m,
                      pitch_mirrors_deg=pi_m, mount_roll_deg=roll, include_reference_rows=False,
                      reference_axes=mode)
        assert "REF_C" not in r and "REF_R" not in r
        if mode == "mirror_frame":   # reference = fixture frame; INS keeps its roll relative to it
            for i, a in enumerate(az_m):
                assert np.allclose(r[f"A{i + 1}"][4:], [a, 0.0, roll], atol=1e-9)
            for j, b in enumerate(pi_m):
                assert np.allclose(r[f"P{j + 1}"][4:], [0.0, b, roll], atol=1e-9)
        else:  # reference rolled by the INS roll: line of sight Rx(-roll)(cos a, sin a, 0)
            f = np.radians(roll)
            for i, a in enumerate(az_m):
                ar = np.radians(a)
                h = np.degrees(np.arctan2(np.cos(f) * np.sin(ar), np.cos(ar)))
                p = -np.degrees(np.arcsin(-np.sin(f) * np.sin(ar)))
                assert np.allclose(r[f"A{i + 1}"][4:6], [h, p], atol=1e-9)


def test_pure_azimuth_offset_closed_form():
    g, H = 180.0 * AS, 10.0
    _, r, _ = sim(azimuth_offset_arcsec=180.0, pitch_offset_arcsec=0.0, mount_roll_deg=0.0,
                  setup_heading_deg=H, azimuth_mirrors_deg=(30.0,), pitch_mirrors_deg=(40.0,))
    # level mirror: heading = az - gamma exactly, pitch 0
    assert abs(ang_diff(r["A1"][4], H + 30.0 - g)) < 1e-10 and abs(r["A1"][5]) < 1e-10
    # mirror at elevation b: sin(theta) = sin(b)/cos(g); heading = az - atan2(sin g, cos th cos g)
    gr, b = np.radians(g), np.radians(40.0)
    th = np.arcsin(np.sin(b) / np.cos(gr))
    psi = H - np.degrees(np.arctan2(np.sin(gr), np.cos(th) * np.cos(gr)))
    assert abs(ang_diff(r["P1"][4], psi)) < 1e-10 and abs(r["P1"][5] - np.degrees(th)) < 1e-10


def test_pure_pitch_offset_closed_form():
    lam, H = -108.0 * AS, 200.0
    _, r, _ = sim(azimuth_offset_arcsec=0.0, pitch_offset_arcsec=-108.0, mount_roll_deg=0.0,
                  setup_heading_deg=H, azimuth_mirrors_deg=(50.0,), pitch_mirrors_deg=(25.0,))
    # optical axis in the x-z plane: pitch = elevation - lambda, heading = azimuth
    assert abs(ang_diff(r["A1"][4], H + 50.0)) < 1e-10 and abs(r["A1"][5] + lam) < 1e-10
    assert abs(ang_diff(r["P1"][4], H)) < 1e-10 and abs(r["P1"][5] - (25.0 - lam)) < 1e-10


@pytest.mark.parametrize("side,sign", [("right", -1.0), ("left", 1.0)])
def test_roll_mirror_measures_fixture_roll(side, sign):
    # text 3.1: the side mirror "表征惯导的横滚": a fixture rolled right-down by R puts the right-hand
    # mirror's line of sight R below the horizon, the left-hand one R above (hand derivation).
    R = 0.2
    _, r, _ = sim(azimuth_offset_arcsec=0, pitch_offset_arcsec=0, fixture_roll_deg=R,
                  roll_mirror_side=side, setup_heading_deg=0.0)
    assert abs(r["REF_R"][5] - sign * R) < 1e-9
    assert abs(ang_diff(r["REF_R"][4], 90.0 if side == "right" else -90.0)) < 1e-6
    assert abs(r["REF_R"][3] - sign * R) < 1e-9        # the theodolite sees the same elevation


def test_tilted_fixture_relative_readings_are_fixture_angles():
    _, r, _ = sim(azimuth_offset_arcsec=0, pitch_offset_arcsec=0, fixture_pitch_deg=0.3,
                  fixture_roll_deg=-0.5, include_reference_rows=False, roll_mirror_side="left",
                  azimuth_mirrors_deg=(-30.0, 40.0), pitch_mirrors_deg=(20.0,))
    assert np.allclose(r["A1"][4:6], [-30.0, 0.0], atol=1e-9)
    assert np.allclose(r["A2"][4:6], [40.0, 0.0], atol=1e-9)
    assert np.allclose(r["P1"][4:6], [0.0, 20.0], atol=1e-9)


# ---------------------------------------------------------------- statements of section 2
@pytest.mark.parametrize("mode", ["mirror_frame", "center_attitude"])
def test_azimuth_offset_hardly_changes_azimuth_mirror_readings(mode):
    # "当惯导轴与自准直光轴在方位向存在偏差时...测量出的惯导姿态变化几乎和反射镜姿态变化一致"
    alphas = (10.0, 45.0, 120.0, 180.0)
    _, r, _ = sim(azimuth_offset_arcsec=0.1 * 3600, pitch_offset_arcsec=0.0, mount_roll_deg=0.0,
                  azimuth_mirrors_deg=alphas, include_reference_rows=False, reference_axes=mode)
    for i, a in enumerate(alphas):
        assert abs(ang_diff(r[f"A{i + 1}"][4], a)) < 1e-9 and abs(r[f"A{i + 1}"][5]) < 1e-9


@pytest.mark.parametrize("mode", ["mirror_frame", "center_attitude"])
@pytest.mark.parametrize("lam_deg", [0.02, 0.05, 0.1])
def test_pitch_offset_doubles_at_alpha_180(mode, lam_deg):
    # "在α=180°时,偏差Δβ几乎是偏差λ的两倍"  (sign: relative pitch = -2 lambda with A3)
    _, r, _ = sim(azimuth_offset_arcsec=0.0, pitch_offset_arcsec=lam_deg * 3600, mount_roll_deg=0.0,
                  azimuth_mirrors_deg=(30.0, 90.0, 180.0), include_reference_rows=False,
                  reference_axes=mode)
    dbeta = [r[f"A{i}"][5] for i in (1, 2, 3)]
    assert abs(dbeta[2] / lam_deg + 2.0) < 1e-3
    assert abs(dbeta[2]) > abs(dbeta[0])        # deviation grows with the mirror angle


def test_pitch_offset_hardly_changes_pitch_mirror_readings():
    # "当惯导轴与自准直光轴在俯仰向存在偏差时,用2面垂直成夹角的反射镜...几乎和反射镜姿态变化一致"
    betas = (15.0, 30.0, 60.0)
    _, r, _ = sim(azimuth_offset_arcsec=0.0, pitch_offset_arcsec=0.1 * 3600, mount_roll_deg=0.0,
                  pitch_mirrors_deg=betas, include_reference_rows=False, reference_axes="center_attitude")
    for j, b in enumerate(betas):
        assert abs(r[f"P{j + 1}"][4]) < 1e-9 and abs(r[f"P{j + 1}"][5] - b) < 1e-9


@pytest.mark.parametrize("mode", ["mirror_frame", "center_attitude"])
@pytest.mark.parametrize("g_deg", [0.02, 0.05, 0.1])
def test_azimuth_offset_equals_heading_deviation_at_beta_60(mode, g_deg):
    # "在β=60°时,偏差...几乎与偏差γ相等": closed form g - atan2(sin g, cos th cos g), sin th = sin b / cos g
    _, r, _ = sim(azimuth_offset_arcsec=g_deg * 3600, pitch_offset_arcsec=0.0, mount_roll_deg=0.0,
                  pitch_mirrors_deg=(60.0,), include_reference_rows=False, reference_axes=mode)
    g = np.radians(g_deg)
    th = np.arcsin(np.sin(np.radians(60.0)) / np.cos(g))
    expect = np.degrees(g - np.arctan2(np.sin(g), np.cos(th) * np.cos(g)))
    assert abs(r["P1"][4] - expect) < 1e-10
    assert abs(abs(r["P1"][4]) / g_deg - 1.0) < 1e-3
    assert abs(r["P1"][5] - np.degrees(th)) < 1e-10


# ---------------------------------------------------------------- finite differences
def _fd(param, value_of, h=1.0, **kw):
    """central difference [deg/deg] of a relative reading with respect to an offset [arcsec]."""
    lo = value_of(sim(**{param: -h}, **kw)[1])
    hi = value_of(sim(**{param: +h}, **kw)[1])
    return (hi - lo) / (2 * h * AS)


@pytest.mark.parametrize("alpha", [-60.0, 30.0, 120.0, 180.0])
@pytest.mark.parametrize("side", ["right", "left"])
def test_fd_pitch_reading_vs_lambda(alpha, side):
    # hand small-angle derivation: reference from body at centre (pitch -lam) -> -(1-cos a);
    # mirror_frame also rolls the reference by +-lam -> + or - sin a
    kw = dict(azimuth_offset_arcsec=0.0, mount_roll_deg=0.0, azimuth_mirrors_deg=(alpha,),
              include_reference_rows=False, roll_mirror_side=side)
    a = np.radians(alpha)
    d = _fd("pitch_offset_arcsec", lambda r: r["A1"][5], reference_axes="center_attitude", **kw)
    assert abs(d + (1 - np.cos(a))) < 1e-4
    d = _fd("pitch_offset_arcsec", lambda r: r["A1"][5], reference_axes="mirror_frame", **kw)
    assert abs(d - (-(1 - np.cos(a)) + (1 if side == "right" else -1) * np.sin(a))) < 1e-4


@pytest.mark.parametrize("beta", [-30.0, 15.0, 45.0, 60.0])
def test_fd_heading_reading_vs_gamma(beta):
    # hand derivation: relative heading at elevation b = g (1 - 1/cos b) to first order
    d = _fd("azimuth_offset_arcsec", lambda r: r["P1"][4], pitch_offset_arcsec=0.0, mount_roll_deg=0.0,
            pitch_mirrors_deg=(beta,), include_reference_rows=False)
    assert abs(d - (1 - 1 / np.cos(np.radians(beta)))) < 1e-4


def test_fd_absolute_reading_vs_offsets_with_roll():
    # INS rolled by phi: u ~ (1, g, -l) -> Rx(phi) u ~ (1, g c + l s, g s - l c), so to first
    # order heading = az - (g c + l s) and pitch = el - (l c - g s) for a level mirror
    phi = 20.0
    kw = dict(mount_roll_deg=phi, azimuth_mirrors_deg=(0.0,), setup_heading_deg=0.0)
    p = np.radians(phi)
    dh_dg = _fd("azimuth_offset_arcsec", lambda r: ang_diff(r["A1"][4], 0.0), pitch_offset_arcsec=0.0, **kw)
    dp_dg = _fd("azimuth_offset_arcsec", lambda r: r["A1"][5], pitch_offset_arcsec=0.0, **kw)
    dh_dl = _fd("pitch_offset_arcsec", lambda r: ang_diff(r["A1"][4], 0.0), azimuth_offset_arcsec=0.0, **kw)
    dp_dl = _fd("pitch_offset_arcsec", lambda r: r["A1"][5], azimuth_offset_arcsec=0.0, **kw)
    assert np.allclose([dh_dg, dh_dl, dp_dg, dp_dl], [-np.cos(p), -np.sin(p), np.sin(p), -np.cos(p)],
                       atol=1e-4)


# ---------------------------------------------------------------- relative file from absolute file
@pytest.mark.parametrize("seq,sp", [("heading-pitch-roll", "ZYX"), ("heading-roll-pitch", "ZXY")])
@pytest.mark.parametrize("mode", ["mirror_frame", "center_attitude"])
@pytest.mark.parametrize("side", ["right", "left"])
def test_relative_file_follows_from_absolute_file(seq, sp, mode, side):
    kw = dict(euler_sequence=seq, reference_axes=mode, roll_mirror_side=side, seed=7,
              fixture_pitch_deg=0.1, fixture_roll_deg=0.3, mount_roll_deg=2.0)
    _, absr, _ = cs.simulate(include_reference_rows=True, **kw)     # noisy defaults
    _, relr, _ = cs.simulate(include_reference_rows=False, **kw)

    def rot(row):
        h, p, r = np.radians(row[4:7])
        return Rot.from_euler(sp, [h, p, r] if sp == "ZYX" else [h, r, p])

    Rc, Rr = rot(absr[0]), rot(absr[1])
    if mode == "center_attitude":
        Rref = Rc
    else:
        x = Rc.apply([1, 0, 0])
        xr = Rr.apply([1, 0, 0])
        y = np.cross(np.cross(x, xr), x) * (1 if side == "right" else -1)
        y /= np.linalg.norm(y)
        Rref = Rot.from_matrix(np.column_stack([x, y, np.cross(x, y)]))
    assert len(relr) == len(absr) - 2
    for a, b in zip(absr[2:], relr):
        assert a[:4] == b[:4]                                  # same theodolite readings
        e = np.degrees((Rref.inv() * rot(a)).as_euler(sp))
        hpr = (e[0], e[1], e[2]) if sp == "ZYX" else (e[0], e[2], e[1])
        assert abs(ang_diff(b[4], hpr[0])) < 1e-9 and np.allclose(b[5:7], hpr[1:], atol=1e-9)


# ---------------------------------------------------------------- noise, seeds, conventions
def test_noise_statistics_and_exactness():
    n = 400
    az = tuple(np.linspace(-80, 80, n))
    pi = tuple(np.linspace(-50, 70, n))
    kw = dict(azimuth_mirrors_deg=az, pitch_mirrors_deg=pi, theodolite_sigma_arcsec=2.0,
              ins_heading_sigma_arcsec=8.0, ins_pitch_sigma_arcsec=3.0, ins_roll_sigma_arcsec=5.0, seed=5)
    _, rows, truth = cs.simulate(**kw)
    tr = truth["mirrors"]
    zero = truth["conventions"]["theodolite_az_zero_deg"]
    e_taz = [ang_diff(r[2], t["true_los_az_deg"] - zero) / AS for r, t in zip(rows, tr)]
    e_tel = [(r[3] - t["true_los_el_deg"]) / AS for r, t in zip(rows, tr)]
    e_h = [ang_diff(r[4], t["true_ins_heading_pitch_roll_deg"][0]) / AS for r, t in zip(rows, tr)]
    e_p = [(r[5] - t["true_ins_heading_pitch_roll_deg"][1]) / AS for r, t in zip(rows, tr)]
    e_r = [(r[6] - t["true_ins_heading_pitch_roll_deg"][2]) / AS for r, t in zip(rows, tr)]
    for e, s in ((e_taz, 2.0), (e_tel, 2.0), (e_h, 8.0), (e_p, 3.0), (e_r, 5.0)):
        assert abs(np.std(e) / s - 1) < 0.1 and abs(np.mean(e)) < 4 * s / np.sqrt(len(e))
    # zero noise: readings equal the truth
    _, rows0, truth0 = cs.simulate(**dict(kw, theodolite_sigma_arcsec=0, ins_heading_sigma_arcsec=0,
                                          ins_pitch_sigma_arcsec=0, ins_roll_sigma_arcsec=0))
    for r, t in zip(rows0, truth0["mirrors"]):
        assert abs(ang_diff(r[2], t["true_los_az_deg"] - zero)) < 1e-12
        assert abs(ang_diff(r[4], t["true_ins_heading_pitch_roll_deg"][0])) < 1e-12
        assert np.allclose(r[5:7], t["true_ins_heading_pitch_roll_deg"][1:], atol=1e-12)


def test_seed_reproducibility():
    a = cs.simulate(seed=1)[1]
    assert a == cs.simulate(seed=1)[1]
    assert a != cs.simulate(seed=2)[1]
    assert sim(seed=1)[1] == sim(seed=2)[1]      # nothing random left -> seed irrelevant


def test_reporting_conventions():
    base = dict(mount_roll_deg=0.7, seed=4)
    _, a, _ = sim(**base)
    _, b, _ = sim(ins_heading_sense="ccw", ins_roll_positive="left_down", theodolite_az_sense="ccw",
                  theodolite_direction="outward_normal", **base)
    zero = 123.4
    for k in a:
        assert abs(ang_diff(b[k][4], -a[k][4])) < 1e-9 and abs(b[k][6] + a[k][6]) < 1e-12
        assert abs(b[k][5] - a[k][5]) < 1e-12
        # theodolite: ccw reading of the outward normal = zero - (true_az + 180)
        true_az = a[k][2] + zero
        assert abs(ang_diff(b[k][2], zero - (true_az + 180.0))) < 1e-9 and abs(b[k][3] + a[k][3]) < 1e-12
    # absolute heading in [0,360), relative heading in (-180,180]
    assert all(0 <= r[4] < 360 for r in a.values())
    _, rel, _ = sim(include_reference_rows=False, ins_heading_sense="ccw", **base)
    _, rel_cw, _ = sim(include_reference_rows=False, **base)
    assert all(abs(rel[k][4] + rel_cw[k][4]) < 1e-9 for k in rel)
    with pytest.raises(ValueError):
        cs.simulate(roll_mirror_side="up")


@pytest.mark.parametrize("ref", [True, False])
@pytest.mark.parametrize("roll", [True, False])
def test_written_files(tmp_path, ref, roll):
    csv_path, json_path = cs.generate(str(tmp_path), "cal", include_reference_rows=ref, include_roll=roll)
    with open(csv_path, encoding="utf-8") as f:
        rows = list(csv.reader(f))
    head = ["mirror", "set", "theodolite_az_deg", "theodolite_el_deg", "ins_az_deg", "ins_el_deg"]
    assert rows[0] == head + (["ins_roll_deg"] if roll else [])
    body = rows[1:]
    assert all(len(r) == len(rows[0]) for r in body)
    names = [r[0] for r in body]
    assert len(set(names)) == len(names)
    sets = [r[1] for r in body]
    assert set(sets) <= {"azimuth", "pitch", "reference_center", "reference_roll"}
    nref = sum(s.startswith("reference") for s in sets)
    assert nref == (2 if ref else 0)
    assert sets.count("azimuth") + sets.count("pitch") == 10          # text 3.2: 10 mirrors
    _, mem, _ = cs.simulate(include_reference_rows=ref, include_roll=roll)
    for r, m in zip(body, mem):
        assert np.allclose([float(x) for x in r[2:]], m[2:], atol=1e-8)
    with open(json_path, encoding="utf-8") as f:
        t = json.load(f)
    for key in ("offsets_arcsec", "offset_definition", "noise_arcsec_1sigma", "seed", "conventions",
                "hidden_errors"):
        assert key in t
    assert t["conventions"]["include_reference_rows"] == ref
    for v in t["hidden_errors"].values():
        assert "definition" in v and ("value" in v)
