"""``diagnose camera`` on data of the blind second generator (blind_camera_acceptance.py).

The acceptance figures (right name at 3 MDB >= 95 %, nothing named in >= 98 % of null sets,
the bad corner flagged in >= 90 %) are measured by the slow test and recorded in
docs/reference/camera.md; the fast test diagnoses one small set of each kind.
"""

from __future__ import annotations

import pytest

from montecarlo.camera_calibration.calibrate import calibrate

from . import blind_camera_acceptance as bca


@pytest.mark.parametrize("scenario", ["radial", "bad_corner"])
def test_one_small_blind_set(scenario):
    """A 5 x 5 target of the blind generator at 3 MDB: the right name or corner, only it."""
    row = bca.one_set(scenario, 11, grid=5)
    if scenario == "radial":
        assert row["named"] == ["radial_k1"] and not row["flagged"], row
    else:
        assert row["named"] == [] and row["flagged"] == [row["right_corner"]], row


def test_reader_takes_the_generators_millimetres():
    """The blind model file is in mm (X = col * pitch from 0); the reader gives metres."""
    data, truth = bca.blind_data(3, 0.0, grid=5)
    pitch_m = truth["target"]["pitch"] / 1000.0
    assert truth["target"]["unit"] == "mm"
    assert sorted(set(data.points[:, 0].round(12))) == pytest.approx(
        [k * pitch_m for k in range(5)], abs=1e-12)


def test_our_model_reproduces_the_blind_camera():
    """Noise-free blind views (fx 600, fy 606, skew 0.4 px, principal point at the image
    centre (319.5, 239.5) with pixel centres at integers, k1 -0.2, k2 0.05, p1 0.001,
    p2 -0.0015; 6 x 6 target in mm) through the CSV files: our calibration with k1, k2, p1,
    p2, skew and aspect returns the generator's camera to round-off (f = fx, a = fy/fx - 1,
    gamma = skew): the two forward models are the same, pixel origin included."""
    truth = dict(fx=600.0, fy=606.0, skew=0.4, k1=-0.2, k2=0.05, p1=0.001, p2=-0.0015)
    data, _ = bca.blind_data(5, 0.0, grid=6, **truth)
    cal = calibrate(data.points, data.pixels, data.view, len(data.views),
                    ("k1", "k2", "p1", "p2"), skew=True, aspect=True, sigma=0.2)
    p = cal.params
    assert p["f"] == pytest.approx(600.0, abs=1e-8)
    assert p["a"] == pytest.approx(606.0 / 600.0 - 1.0, abs=1e-12)
    assert p["gamma"] == pytest.approx(0.4, abs=1e-8)
    assert (p["cx"], p["cy"]) == pytest.approx((319.5, 239.5), abs=1e-8)
    for k in ("k1", "k2", "p1", "p2"):
        assert p[k] == pytest.approx(truth[k], abs=1e-10)


@pytest.mark.slow
def test_blind_acceptance(figures):
    """100 sets per scenario, 6 x 6 target, 0.2 px, 3 MDB (docs/reference/camera.md has the
    figures)."""
    table = bca.run(100, grid=6, n_jobs=2)
    for scenario, key, low, high in (("radial", "right_named", 0.95, None),
                                     ("tangential", "right_named", 0.95, None),
                                     ("null", "anything_named", None, 0.02),
                                     ("bad_corner", "right_corner_flagged", 0.90, None)):
        figures.record(f"{scenario}.{key}", table[scenario][key], low, high)
    assert table["radial"]["right_named"] >= 0.95
    assert table["tangential"]["right_named"] >= 0.95
    assert table["null"]["anything_named"] <= 0.02
    assert table["bad_corner"]["right_corner_flagged"] >= 0.90
