"""[imu] grade presets of the air and stabilisation studies."""

from __future__ import annotations

import math

import pytest

from montecarlo.errors import InputError
from montecarlo.systems import study_from_dict

DEG_PER_H = math.pi / 180.0 / 3600.0  # [rad/s]
MG = 9.80665e-3                        # [m/s^2]
# docs/reference/air.md, "IMU grades": gyro bias [deg/h] and accelerometer bias [mg] per grade
TABLE = {"consumer": (100.0, 10.0), "industrial": (0.1, 0.1), "tactical": (1.0, 1.0),
         "navigation": (0.01, 0.03)}


def _air(**tables):
    return study_from_dict({"study": {"name": "g", "system": "air", "trials": 10, "seed": 1},
                            "params": {"ta_source": "kalman"}, **tables})


@pytest.mark.parametrize("grade", TABLE)
def test_air_grade_sets_the_documented_figures(grade):
    p = _air(imu={"grade": grade}).points[0].prepared.params
    gyro, accel = TABLE[grade]
    assert p["gyro_drift"] == pytest.approx(gyro * DEG_PER_H, rel=1e-12)
    assert p["accel_bias"] == pytest.approx(accel * MG, rel=1e-12)


def test_an_explicit_number_overrides_the_preset():
    st = _air(imu={"grade": "tactical"},
              params={"ta_source": "kalman", "gyro_drift_deg_per_h": 0.5})
    p = st.points[0].prepared.params
    assert p["gyro_drift"] == pytest.approx(0.5 * DEG_PER_H, rel=1e-12)
    assert p["accel_bias"] == pytest.approx(1.0 * MG, rel=1e-12)  # still the grade's
    assert "sets accel_bias_g" in st.points[0].prepared.description[-1]


def test_no_grade_keeps_the_defaults():
    default = _air().points[0].prepared.params
    assert default["gyro_drift"] == pytest.approx(0.05 * DEG_PER_H, rel=1e-12)


def test_stabilization_grade_and_sweep():
    st = study_from_dict({"study": {"name": "s", "system": "stabilization", "trials": 4,
                                    "seed": 1},
                          "sweep": [{"imu.grade": ["consumer", "navigation"]}]})
    biases = [gp.prepared.params["gyro_bias"] / DEG_PER_H for gp in st.points]
    assert biases == pytest.approx([100.0, 0.01], rel=1e-12)


def test_unknown_grade_is_one_line():
    with pytest.raises(InputError, match=r"imu\.grade: .*'navigation' \(got 'military'\)"):
        _air(imu={"grade": "military"})
    with pytest.raises(InputError, match=r"imu\.class: unknown key"):
        _air(imu={"class": "tactical"})
