"""Self-checks for camera_blind.py (blind second author)."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from . import camera_blind as cb

INTR = dict(fx=800.0, fy=810.0, cx=320.0, cy=240.0, skew=0.5)
DIST = dict(k1=-0.2, k2=0.05, k3=0.01, p1=0.001, p2=0.002)


def test_optical_axis_hits_principal_point():
    u, v, *_ = cb.project(np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 7.0]]), np.eye(3), np.zeros(3),
                          **INTR, **DIST)
    assert np.allclose(u, 320.0) and np.allclose(v, 240.0)


def test_hand_derived_distortion():
    """x=0.3, y=0.4: r2=0.25, r4=0.0625, r6=0.015625.
    radial = 1 - 0.2*0.25 + 0.05*0.0625 + 0.01*0.015625 = 0.95328125
    xd = 0.3*radial + 2*0.001*0.12 + 0.002*(0.25+0.18) = 0.285984375+0.00024+0.00086 = 0.287084375
    yd = 0.4*radial + 0.001*(0.25+0.32) + 2*0.002*0.12 = 0.3813125+0.00057+0.00048 = 0.3823625
    u = 800*xd + 0.5*yd + 320 = 229.6675 + 0.19118125 + 320 = 549.85868125
    v = 810*yd + 240 = 309.713625 + 240 = 549.713625
    """
    xd, yd = cb.distort(0.3, 0.4, **DIST)
    assert xd == pytest.approx(0.287084375, abs=1e-14)
    assert yd == pytest.approx(0.3823625, abs=1e-14)
    u, v, *_ = cb.project(np.array([[0.3, 0.4, 1.0]]), np.eye(3), np.zeros(3), **INTR, **DIST)
    assert u[0] == pytest.approx(549.85868125, abs=1e-9)
    assert v[0] == pytest.approx(549.713625, abs=1e-9)


def _undistort(xd, yd, k1, k2, k3, p1, p2, iters=200):
    x, y = xd.copy(), yd.copy()
    for _ in range(iters):  # fixed-point inversion of the Brown-Conrady model
        r2 = x * x + y * y
        rad = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
        x = (xd - 2 * p1 * x * y - p2 * (r2 + 2 * x * x)) / rad
        y = (yd - p1 * (r2 + 2 * y * y) - 2 * p2 * x * y) / rad
    return x, y


@pytest.mark.parametrize("dist", [dict(k1=0, k2=0, k3=0, p1=0, p2=0),
                                  dict(k1=-0.25, k2=0.08, k3=-0.01, p1=0.001, p2=-0.0015)])
def test_against_homography(dist):
    """Independent route: H = K [r1 r2 t] maps (X, Y, 1) to undistorted pixels (Zhang)."""
    intr = dict(fx=700.0, fy=690.0, cx=330.0, cy=235.0, skew=0.8)
    m, vr, tr = cb.generate(**intr, **dist, noise_px=0.0, rng=3, n_views=6)
    XY = {i: (X, Y) for i, X, Y, _ in m}
    K = np.array(tr["K"])
    Kinv = np.linalg.inv(K)
    for vw in tr["views"]:
        R, t = np.array(vw["R"]), np.array(vw["t"])
        H = K @ np.column_stack([R[:, 0], R[:, 1], t])
        rows = [r for r in vr if r[0] == vw["view"]]
        assert len(rows) == vw["n_points"]
        XY1 = np.array([[*XY[r[1]], 1.0] for r in rows])
        h = XY1 @ H.T
        u_ideal, v_ideal = h[:, 0] / h[:, 2], h[:, 1] / h[:, 2]
        uv1 = np.array([[r[2], r[3], 1.0] for r in rows])
        n = uv1 @ Kinv.T   # distorted normalised coordinates
        x, y = _undistort(n[:, 0], n[:, 1], **dist)
        uu = K[0, 0] * x + K[0, 1] * y + K[0, 2]
        vv = K[1, 1] * y + K[1, 2]
        assert np.max(np.abs(uu - u_ideal)) < 1e-6
        assert np.max(np.abs(vv - v_ideal)) < 1e-6


def test_visibility_and_pose_ranges():
    m, vr, tr = cb.generate(k1=-0.3, k2=0.1, rng=11)
    uv = np.array([[r[2], r[3]] for r in vr])
    assert 5 <= tr["n_views"] <= 8 and len(m) == 256
    sig = 5 * tr["noise_px"]
    assert uv[:, 0].min() > -0.5 - sig and uv[:, 0].max() < 639.5 + sig
    assert uv[:, 1].min() > -0.5 - sig and uv[:, 1].max() < 479.5 + sig
    for vw in tr["views"]:
        R = np.array(vw["R"])
        tilt = np.degrees(np.arccos(R[2, 2]))
        assert 10 - 1e-9 <= tilt <= 45 + 1e-9 and tilt == pytest.approx(vw["tilt_deg"])
        assert vw["n_points"] >= 128 and vw["t"][2] > 0
        assert np.allclose(R @ R.T, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)


def _residuals(vr, tr):
    _, P = cb.target_points(16, 16, 10.0)
    res = {}
    for vw in tr["views"]:
        u, v, *_ = cb.project(P, vw["R"], vw["t"], **tr["intrinsics"], **tr["distortion"])
        for r in vr:
            if r[0] == vw["view"]:
                res[(r[0], r[1])] = (r[2] - u[r[1]], r[3] - v[r[1]])
    return res


def test_noise_statistics():
    s = 0.5
    _, vr0, tr0 = cb.generate(noise_px=0.0, rng=5, n_views=8, k1=0.1)
    _, vr1, tr1 = cb.generate(noise_px=s, rng=5, n_views=8, k1=0.1)
    assert tr0["views"] == tr1["views"]
    d = np.array([[a[2] - b[2], a[3] - b[3]] for a, b in zip(vr1, vr0)])
    n = d.shape[0]
    assert n > 1000
    for c in range(2):
        assert abs(d[:, c].mean()) < 4 * s / np.sqrt(n)
        assert d[:, c].std(ddof=1) == pytest.approx(s, rel=0.08)
    # residuals against the truth file's poses agree with the same noise
    r = np.array(list(_residuals(vr1, tr1).values()))
    assert np.allclose(np.sort(r.ravel()), np.sort(d.ravel()), atol=1e-9)


def test_blunders_recorded_where_injected():
    _, vr, tr = cb.generate(noise_px=0.0, blunders=7, blunder_px=15.0, rng=8, n_views=5)
    res = _residuals(vr, tr)
    bl = {(b["view"], b["id"]): b for b in tr["blunders"]}
    assert len(bl) == 7
    for key, (du, dv) in res.items():
        if key in bl:
            assert np.hypot(du, dv) == pytest.approx(15.0, abs=1e-9)
            assert (du, dv) == pytest.approx((bl[key]["du"], bl[key]["dv"]), abs=1e-9)
        else:
            assert np.hypot(du, dv) < 1e-9


def test_csv_headers_and_cli(tmp_path):
    out = tmp_path / "run"
    subprocess.run([sys.executable, cb.__file__, str(out), "--seed", "4", "--k1", "-0.1",
                    "--p1", "0.001", "--noise-px", "0.2", "--blunders", "3", "--blunder-px",
                    "10", "--views", "6"], check=True, capture_output=True)
    lm = (out / "model.csv").read_text().splitlines()
    lv = (out / "views.csv").read_text().splitlines()
    assert lm[0] == "id,X,Y,unit" and lv[0] == "view,id,u,v"
    assert lm[1] == "0,0.0,0.0,mm" and len(lm) == 257
    tr = json.loads((out / "truth.json").read_text())
    assert tr["n_views"] == 6 and len(tr["blunders"]) == 3 and tr["noise_px"] == 0.2
    assert tr["distortion"]["k1"] == -0.1 and tr["seed"] == 4
    assert len(lv) - 1 == tr["n_observations"]
    ids = {int(l.split(",")[0]) for l in lm[1:]}
    assert all(int(l.split(",")[1]) in ids for l in lv[1:])
    # same seed through the API gives the same data
    m, vr, tr2 = cb.generate(k1=-0.1, p1=0.001, noise_px=0.2, blunders=3, blunder_px=10.0,
                             n_views=6, rng=4)
    assert lv[1] == "{},{},{!r},{!r}".format(*vr[0])
    # prefix form of write()
    pm, pv, pt = cb.write(str(tmp_path / "x_"), m, vr, tr2)
    assert os.path.basename(pm) == "x_model.csv" and os.path.exists(pt)
