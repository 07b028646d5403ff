"""The measured-data readers and writers of ``montecarlo.io``: every refusal is one line naming
file, row, column and value (checked in full below), values are converted to the units stated
in the data format (checked against hand values), and the writers' text is the format's.
"""

import json
import math

import numpy as np
import pytest

from montecarlo.errors import InputError
from montecarlo.geometry.camera import Camera
from montecarlo.io import camera_csv, collimation_csv, ground_csv, stabilization_csv
from montecarlo.io.table import read_table
from montecarlo.seed001.simulate import Record


def _write(tmp_path, text, name="data.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _refused(call, *args, **kwargs):
    with pytest.raises(InputError) as info:
        call(*args, **kwargs)
    message = str(info.value)
    assert "\n" not in message
    return message


# --------------------------------------------------------------------------------------------
# table.py
# --------------------------------------------------------------------------------------------

def test_table_messages_in_full(tmp_path):
    p = _write(tmp_path, "a, b ,a\n1,2,3\n")
    assert _refused(read_table, p, ["a"]) == f"{p}: column 'a' appears 2 times in the header"
    p = _write(tmp_path, "a,c\n1,2\n")
    assert _refused(read_table, p, ["a", "b"]) == f"{p}: missing column 'b' (have: a, c)"
    p = _write(tmp_path, "a,name\n1,x\n2,y\n")
    assert _refused(read_table, p, ["a"], text=["name", "kind"]) == (
        f"{p}: missing column 'kind' (have: a, name)")
    assert _refused(read_table, p, ["a"], min_rows=3) == f"{p}: 2 data rows, at least 3 needed"
    assert read_table(p, ["a"], min_rows=2)["a"].tolist() == [1.0, 2.0]
    p = _write(tmp_path, "a\n1\ninf\n")
    assert _refused(read_table, p, ["a"]) == (
        f"{p}: row 3, column 'a': 'inf' is not a finite number")
    assert _refused(read_table, tmp_path, ["a"]) == f"{tmp_path}: is a directory, not a CSV file"
    missing = tmp_path / "none.csv"
    assert _refused(read_table, missing, ["a"]) == f"{missing}: no such file"
    inside_a_file = p / "x.csv"
    assert _refused(read_table, inside_a_file, ["a"]) == (
        f"{inside_a_file}: cannot read (Not a directory)")
    empty = _write(tmp_path, "", "empty.csv")
    assert _refused(read_table, empty, ["a"]) == (
        f"{empty}: not a readable CSV file (No columns to parse from file)")


def test_table_reads_a_quoted_value_after_the_separator_space(tmp_path):
    """``a, "x, y"``: the space after the comma is skipped, so the quotes hold the comma."""
    p = _write(tmp_path, 'a, name\n1, "x, y"\n')
    assert read_table(p, ["a"], text=["name"])["name"].tolist() == ["x, y"]


def test_table_ranges_are_closed_intervals_and_name_the_first_bad_row(tmp_path):
    """[0, 1]: both ends accepted; -0.5 (below) and 1.5 (above) refused at their own rows."""
    p = _write(tmp_path, "a,b\n0,5\n1,5\n")
    t = read_table(p, ["a", "b"], ranges={"a": (0.0, 1.0)})
    assert t["a"].tolist() == [0.0, 1.0] and t["a"].dtype == np.float64
    p = _write(tmp_path, "a,b\n0.5,5\n-0.5,5\n2,5\n")
    assert _refused(read_table, p, ["a", "b"], ranges={"a": (0.0, 1.0)}) == (
        f"{p}: row 3, column 'a': -0.5 is outside [0, 1]")
    p = _write(tmp_path, "a,b\n0.5,5\n1.5,5\n")
    assert _refused(read_table, p, ["a", "b"], ranges={"a": (0.0, 1.0)}) == (
        f"{p}: row 3, column 'a': 1.5 is outside [0, 1]")
    # no range given: any finite value
    assert read_table(p, ["a", "b"])["b"].tolist() == [5.0, 5.0]


def test_table_optional_and_text_columns(tmp_path):
    p = _write(tmp_path, "a,name,opt,extra\n1, x ,2,keep\n3,y,4,this\n")
    t = read_table(p, ["a"], optional_numeric=["opt", "absent"], text=["name"])
    assert t["opt"].tolist() == [2.0, 4.0] and t["opt"].dtype == np.float64
    assert t["name"].tolist() == ["x", "y"] and t["extra"].tolist() == ["keep", "this"]
    assert "absent" not in t.columns
    p = _write(tmp_path, "a,opt\n1,2\n3,x\n")
    assert _refused(read_table, p, ["a"], optional_numeric=["opt"]) == (
        f"{p}: row 3, column 'opt': 'x' is not a finite number")
    p = _write(tmp_path, "a,opt\n1,2\n3,7\n")
    assert _refused(read_table, p, ["a"], optional_numeric=["opt"],
                    ranges={"opt": (0.0, 5.0)}) == f"{p}: row 3, column 'opt': 7 is outside [0, 5]"
    p = _write(tmp_path, "a,name\n1,x\n2,\n")
    assert _refused(read_table, p, ["a"], text=["name"]) == (
        f"{p}: row 3, column 'name': empty value")
    p = _write(tmp_path, "a,name,set\n1,x,pitch\n2,y,roll\n")
    assert _refused(read_table, p, ["a"], text=["name", "set"],
                    choices={"set": ("pitch", "azimuth")}) == (
        f"{p}: row 3, column 'set': 'roll' is not one of azimuth, pitch")
    # choices for one column leave the others free
    t = read_table(p, ["a"], text=["name", "set"], choices={"name": ("x", "y")})
    assert t["set"].tolist() == ["pitch", "roll"]


# --------------------------------------------------------------------------------------------
# stabilization_csv.py
# --------------------------------------------------------------------------------------------

STAB_HEADER = "t_s,gyro_x,gyro_y,gyro_z,eta_rad,eps_rad,los_x_px,los_z_px\n"


def _stab_rows(n=10, change=None):
    rows = []
    for i in range(n):
        row = {"t_s": 0.1 * i, "gyro_x": 0.01, "gyro_y": -0.02, "gyro_z": 0.03,
               "eta_rad": 0.1, "eps_rad": 0.2, "los_x_px": 1.5, "los_z_px": -2.5}
        row.update((change or {}).get(i, {}))
        rows.append(",".join(str(v) for v in row.values()))
    return STAB_HEADER + "\n".join(rows) + "\n"


def test_stabilization_csv_reads_columns_into_the_record(tmp_path):
    p = _write(tmp_path, _stab_rows(12, {3: {"gyro_y": -100.0}, 4: {"gyro_z": 100.0},
                                           5: {"eps_rad": math.radians(89.0)},
                                           6: {"eta_rad": -4 * math.pi + 1e-9}}))
    r = stabilization_csv.read_csv(p)
    assert r.t.tolist() == pytest.approx([0.1 * i for i in range(12)], abs=1e-15)
    assert r.gyro.shape == (12, 3) and r.gyro[0].tolist() == [0.01, -0.02, 0.03]
    assert r.gyro[3, 1] == -100.0 and r.gyro[4, 2] == 100.0
    assert r.eta[0] == 0.1 and r.eps[0] == 0.2 and r.eps[5] == math.radians(89.0)
    assert r.los_px.shape == (12, 2) and r.los_px[0].tolist() == [1.5, -2.5]


@pytest.mark.parametrize(("change", "n", "needle"), [
    ({}, 9, "9 data rows, at least 10 needed"),
    ({3: {"t_s": 0.5}, 4: {"t_s": 0.5}}, 10,
     "row 6, column 't_s': 0.5 is not after the previous time 0.5"),
    ({4: {"t_s": 0.2}}, 10, "row 6, column 't_s': 0.2 is not after the previous time "
                            "0.30000000000000004"),
    ({2: {"eps_rad": -1.56}}, 10, "row 4, column 'eps_rad': -1.56 is beyond +-1.5533 rad "
                                  "(eq. (4) divides by cos(eps))"),
    ({1: {"gyro_x": 100.5}}, 10, "row 3, column 'gyro_x': 100.5 is outside [-100, 100]"),
    ({1: {"gyro_y": -101}}, 10, "row 3, column 'gyro_y': -101 is outside [-100, 100]"),
    ({1: {"gyro_z": 101}}, 10, "row 3, column 'gyro_z': 101 is outside [-100, 100]"),
    ({1: {"eta_rad": 12.6}}, 10, "row 3, column 'eta_rad': 12.6 is outside [-12.5664, 12.5664]"),
    ({1: {"t_s": 2e9}}, 10, "row 3, column 't_s': 2000000000.0 is outside [-1e+09, 1e+09]"),
    ({1: {"los_x_px": 2e6}}, 10, "row 3, column 'los_x_px': 2000000.0 is outside "
                                 "[-1e+06, 1e+06]"),
    ({1: {"los_z_px": -2e6}}, 10, "row 3, column 'los_z_px': -2000000.0 is outside "
                                  "[-1e+06, 1e+06]"),
    # just beyond each end: a limit moved by one unit would accept these
    ({0: {"t_s": -1000000000.5}}, 10, "row 2, column 't_s': -1000000000.5 is outside "
                                      "[-1e+09, 1e+09]"),
    ({9: {"t_s": 1000000000.5}}, 10, "row 11, column 't_s': 1000000000.5 is outside "
                                     "[-1e+09, 1e+09]"),
    ({1: {"los_x_px": -1000000.5}}, 10, "row 3, column 'los_x_px': -1000000.5 is outside "
                                        "[-1e+06, 1e+06]"),
    ({1: {"los_x_px": 1000000.5}}, 10, "row 3, column 'los_x_px': 1000000.5 is outside "
                                       "[-1e+06, 1e+06]"),
    ({1: {"los_z_px": -1000000.5}}, 10, "row 3, column 'los_z_px': -1000000.5 is outside "
                                        "[-1e+06, 1e+06]"),
    ({1: {"los_z_px": 1000000.5}}, 10, "row 3, column 'los_z_px': 1000000.5 is outside "
                                       "[-1e+06, 1e+06]"),
])
def test_stabilization_csv_refusals_in_full(tmp_path, change, n, needle):
    """Limits: |gyro| <= 100 rad/s, |eta| <= 4 pi = 12.5664 rad, |eps| <= 89 deg = 1.5533 rad
    (eq. (4) divides by cos(eps)), |t| <= 1e9 s, |los| <= 1e6 px; times strictly increasing."""
    p = _write(tmp_path, _stab_rows(n, change))
    assert _refused(stabilization_csv.read_csv, p) == f"{p}: {needle}"


def test_stabilization_csv_text_by_hand(tmp_path):
    """Header, then one row per sample with 12 significant digits."""
    record = Record(t=np.array([0.0, 0.02]), gyro=np.array([[1e-3, -2.5e-3, 1 / 3],
                                                            [0.0, 1.0, 2.0]]),
                    eta=np.array([0.1, 0.2]), eps=np.array([-0.3, 0.4]),
                    los_px=np.array([[1.25, -3.0], [100.0, 2e-7]]))
    p = tmp_path / "run.csv"
    stabilization_csv.write_csv(p, record)
    assert p.read_text() == (STAB_HEADER + "0,0.001,-0.0025,0.333333333333,0.1,-0.3,1.25,-3\n"
                             "0.02,0,1,2,0.2,0.4,100,2e-07\n")
    assert [f.name for f in tmp_path.iterdir()] == ["run.csv"]
    bad = tmp_path / "no" / "run.csv"
    assert _refused(stabilization_csv.write_csv, bad, record).startswith(f"{bad}: cannot write (")


# --------------------------------------------------------------------------------------------
# ground_csv.py
# --------------------------------------------------------------------------------------------

def _camera():
    return Camera.from_degrees(40.0, 30.0, 640, 480)


GROUND = "target,x_m,y_m,z_m,px,pz\nT1,1.0,100.0,2.0,3.5,-4.5\nT2,-1,50,0,0,0\n"


def test_ground_csv_reads_positions_pixels_times_and_sessions(tmp_path):
    p = _write(tmp_path, GROUND)
    d = ground_csv.read_ground_csv(p, _camera())
    assert d.targets == ("T1", "T2") and d.n == 2
    assert d.positions.tolist() == [[1.0, 100.0, 2.0], [-1.0, 50.0, 0.0]]
    assert d.pixels.tolist() == [[3.5, -4.5], [0.0, 0.0]]
    assert d.t is None and d.session is None and d.sessions() == ("",)
    p = _write(tmp_path, "target,x_m,y_m,z_m,px,pz,t_s,session\n"
               "T1,1,100,2,0,0,5,B\nT2,1,100,2,0,0,6,A\nT1,1,100,2,0,0,7,B\n")
    d = ground_csv.read_ground_csv(p, _camera(), min_rows=3)
    assert d.t.tolist() == [5.0, 6.0, 7.0] and d.session == ("B", "A", "B")
    assert d.sessions() == ("B", "A")


def test_ground_csv_refusals_in_full(tmp_path):
    cam = _camera()
    p = _write(tmp_path, GROUND)
    assert _refused(ground_csv.read_ground_csv, p, cam, min_rows=3) == (
        f"{p}: 2 data rows, at least 3 needed")
    assert _refused(ground_csv.read_ground_csv, p, cam, min_rows=3, need="three angles") == (
        f"{p}: 2 data rows, at least 3 needed (three angles)")
    assert ground_csv.read_ground_csv(p, cam, min_rows=2).n == 2
    p = _write(tmp_path, GROUND + "T3,0,0,0,1,1\n")
    assert _refused(ground_csv.read_ground_csv, p, cam) == (
        f"{p}: row 4, column 'x_m': target at the sensor origin (0, 0, 0) has no direction")
    p = _write(tmp_path, "target,x_m,y_m,z_m,px,pz,session\nT1,1,100,2,0,0,S\nT2,1,9,2,0,0, \n")
    assert _refused(ground_csv.read_ground_csv, p, cam) == (
        f"{p}: row 3, column 'session': empty value")
    p = _write(tmp_path, "target,x_m,y_m,z_m,px,pz,t_s\nT1,1,100,2,0,0,1.5\nT1,1,9,2,0,0,1.5\n")
    assert _refused(ground_csv.read_ground_csv, p, cam) == (
        f"{p}: row 3, column 'target': 'T1' at t_s = 1.5 repeats row 2 (a target is observed "
        "once per session and time)")
    p = _write(tmp_path, "target,x_m,y_m,z_m,px,pz\nT1,1,100,2,0,0\nT1,1,9,2,0,0\n")
    assert _refused(ground_csv.read_ground_csv, p, cam) == (
        f"{p}: row 3, column 'target': 'T1' repeats row 2 (a target is observed once per "
        "session and time)")
    for column, value, limit in (("x_m", "2e6", "[-1e+06, 1e+06]"),
                                 ("y_m", "-2e6", "[-1e+06, 1e+06]"),
                                 ("z_m", "2e6", "[-1e+06, 1e+06]"),
                                 ("t_s", "2e9", "[-1e+09, 1e+09]")):
        row = {"target": "T9", "x_m": "1", "y_m": "100", "z_m": "2", "px": "0", "pz": "0",
               "t_s": "0"}
        row[column] = value
        p = _write(tmp_path, ",".join(row) + "\n" + ",".join(row.values()) + "\n")
        assert _refused(ground_csv.read_ground_csv, p, cam) == (
            f"{p}: row 2, column '{column}': {value} is outside {limit}")
    p = _write(tmp_path, "target,x_m,y_m,z_m,px,pz\nT1,1,100,2,0,0\n ,1,9,2,0,0\n")
    assert _refused(ground_csv.read_ground_csv, p, cam) == (
        f"{p}: row 3, column 'target': empty value")
    for value in ("-1000000000.5", "1000000000.5"):
        p = _write(tmp_path, f"target,x_m,y_m,z_m,px,pz,t_s\nT1,1,100,2,0,0,{value}\n")
        assert _refused(ground_csv.read_ground_csv, p, cam) == (
            f"{p}: row 2, column 't_s': {value} is outside [-1e+09, 1e+09]")
    # the detector's edges themselves are on it: |px| = 320, |pz| = 240
    p = _write(tmp_path, "target,x_m,y_m,z_m,px,pz\nT1,1,100,2,-320,240\n")
    assert ground_csv.read_ground_csv(p, cam).pixels.tolist() == [[-320.0, 240.0]]
    p = _write(tmp_path, "target,x_m,y_m,z_m,px,pz\nT1,1,100,2,-320.5,0\n")
    assert _refused(ground_csv.read_ground_csv, p, cam) == (
        f"{p}: row 2, column 'px': -320.5 is outside the detector (|px| <= 320 px)")


def test_ground_layout_json_and_the_written_file_by_hand(tmp_path):
    d = ground_csv.GroundData(("A", "B"), np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]),
                              np.array([[0.5, -0.25], [1.0, 2.0]]), np.array([10.0, 20.0]),
                              ("S1", "S2"))
    assert d.layout() == {"target": ["A", "B"], "x_m": [1.0, 4.0], "y_m": [2.0, 5.0],
                          "z_m": [3.0, 6.0], "t_s": [10.0, 20.0], "session": ["S1", "S2"]}
    back = ground_csv.GroundData.from_layout(json.dumps(d.layout()))
    assert back.targets == ("A", "B") and back.positions.tolist() == d.positions.tolist()
    assert back.pixels.tolist() == [[0.0, 0.0], [0.0, 0.0]] and back.t.tolist() == [10.0, 20.0]
    assert back.session == ("S1", "S2")
    bare = ground_csv.GroundData.from_layout(json.dumps({"x_m": [1, 2], "y_m": [3, 4],
                                                         "z_m": [5, 6], "session": [7, 8]}))
    assert bare.targets == ("T1", "T2") and bare.t is None and bare.session == ("7", "8")
    assert bare.positions.dtype == np.float64 and bare.pixels.shape == (2, 2)
    plain = ground_csv.GroundData(("A",), np.array([[1.0, 2.0, 3.0]]), np.array([[0.5, 1.0]]))
    assert plain.layout() == {"target": ["A"], "x_m": [1.0], "y_m": [2.0], "z_m": [3.0]}
    back = ground_csv.GroundData.from_layout(json.dumps(plain.layout()))
    assert back.t is None and back.session is None
    whole = ground_csv.GroundData.from_layout(json.dumps({"x_m": [1], "y_m": [3], "z_m": [5],
                                                          "t_s": [7]}))
    assert whole.t.dtype == np.float64 and whole.t.tolist() == [7.0]
    p = tmp_path / "g.csv"
    ground_csv.write_ground_csv(p, d)
    assert p.read_text() == ("target,x_m,y_m,z_m,px,pz,t_s,session\n"
                             "A,1.0000,2.0000,3.0000,0.500000,-0.250000,10.0,S1\n"
                             "B,4.0000,5.0000,6.0000,1.000000,2.000000,20.0,S2\n")
    ground_csv.write_ground_csv(p, plain)
    assert p.read_text() == "target,x_m,y_m,z_m,px,pz\nA,1.0000,2.0000,3.0000,0.500000,1.000000\n"


# --------------------------------------------------------------------------------------------
# collimation_csv.py
# --------------------------------------------------------------------------------------------

MIRROR_HEAD = "mirror,set,theodolite_az_deg,theodolite_el_deg,ins_az_deg,ins_el_deg"


def test_mirror_csv_reads_degrees_as_radians(tmp_path):
    """90 deg = pi/2, -45 deg = -pi/4, 30 deg = pi/6, 180 deg = pi (hand values)."""
    p = _write(tmp_path, MIRROR_HEAD + ",ins_roll_deg\nA1,azimuth,90,-45,30,0,180\n"
               "P1,pitch,-360,90,360,-90,-180\n")
    d = collimation_csv.read_mirror_csv(p)
    assert d.mirror == ("A1", "P1") and d.sets == ("azimuth", "pitch")
    np.testing.assert_allclose(d.theodolite_az, [np.pi / 2, -2 * np.pi], rtol=1e-15)
    np.testing.assert_allclose(d.theodolite_el, [-np.pi / 4, np.pi / 2], rtol=1e-15)
    np.testing.assert_allclose(d.ins_az, [np.pi / 6, 2 * np.pi], rtol=1e-15)
    np.testing.assert_allclose(d.ins_el, [0.0, -np.pi / 2], rtol=1e-15)
    np.testing.assert_allclose(d.ins_roll, [np.pi, -np.pi], rtol=1e-15)
    np.testing.assert_allclose(d.roll, [np.pi, -np.pi], rtol=1e-15)
    p = _write(tmp_path, MIRROR_HEAD + "\nA1,azimuth,1,2,3,4\n")
    d = collimation_csv.read_mirror_csv(p)
    assert d.ins_roll is None and d.roll.tolist() == [0.0]


@pytest.mark.parametrize(("rows", "kwargs", "needle"), [
    ("A1,azimuth,1,2,3,4\n", {"min_mirrors": 2}, "1 data rows, at least 2 needed"),
    ("A1,azimuth,1,2,3,4\n", {"min_mirrors": 2, "need": "a fit"},
     "1 data rows, at least 2 needed (a fit)"),
    ("A1,azimuth,400,2,3,4\n", {}, "row 2, column 'theodolite_az_deg': 400 is outside [-360, 360]"),
    ("A1,azimuth,1,2,-361,4\n", {}, "row 2, column 'ins_az_deg': -361 is outside [-360, 360]"),
    ("A1,azimuth,1,91,3,4\n", {}, "row 2, column 'theodolite_el_deg': 91 is outside [-90, 90]"),
    ("A1,azimuth,1,2,3,-91\n", {}, "row 2, column 'ins_el_deg': -91 is outside [-90, 90]"),
    ("A1,roll,1,2,3,4\n", {}, "row 2, column 'set': 'roll' is not one of azimuth, pitch"),
    ("A1,reference_center,1,2,3,4\n", {"sets": ("azimuth", *collimation_csv.REFERENCE_SETS)},
     "column 'set': a 'reference_center' row without a 'reference_roll' row (give both "
     "reference mirrors or neither)"),
    ("A1,reference_roll,1,2,3,4\n", {"sets": collimation_csv.REFERENCE_SETS},
     "column 'set': a 'reference_roll' row without a 'reference_center' row (give both "
     "reference mirrors or neither)"),
    ("R,reference_roll,1,2,3,4\nC,reference_center,1,2,3,4\nS,reference_roll,1,2,3,4\n",
     {"sets": collimation_csv.REFERENCE_SETS},
     "row 4, column 'set': a second 'reference_roll' row (the first is row 2)"),
    ("A1,azimuth,1,2,3,4\nA2,azimuth,1,2,3,4\nA1,azimuth,1,2,3,4\n", {},
     "row 4, column 'mirror': 'A1' in set 'azimuth' repeats row 2 (each mirror is read once)"),
])
def test_mirror_csv_refusals_in_full(tmp_path, rows, kwargs, needle):
    p = _write(tmp_path, MIRROR_HEAD + "\n" + rows)
    assert _refused(collimation_csv.read_mirror_csv, p, **kwargs) == f"{p}: {needle}"


def test_mirror_csv_roll_range(tmp_path):
    p = _write(tmp_path, MIRROR_HEAD + ",ins_roll_deg\nA1,azimuth,1,2,3,4,181\n")
    assert _refused(collimation_csv.read_mirror_csv, p) == (
        f"{p}: row 2, column 'ins_roll_deg': 181 is outside [-180, 180]")


def test_reference_rows_are_located_for_the_procedure(tmp_path):
    sets = ("azimuth", "pitch", *collimation_csv.REFERENCE_SETS)
    p = _write(tmp_path, MIRROR_HEAD + "\nA1,azimuth,1,2,3,4\nR,reference_roll,1,2,3,4\n"
               "C,reference_center,1,2,3,4\n")
    d = collimation_csv.read_mirror_csv(p, min_mirrors=3, sets=sets)
    proc = collimation_csv.procedure_data(d)
    assert (proc.center, proc.roll_mirror) == (2, 1)
    np.testing.assert_allclose(proc.theodolite_az, np.radians([1.0] * 3), rtol=1e-15)
    np.testing.assert_allclose(proc.theodolite_el, np.radians([2.0] * 3), rtol=1e-15)
    np.testing.assert_allclose(proc.ins_az, np.radians([3.0] * 3), rtol=1e-15)
    np.testing.assert_allclose(proc.ins_el, np.radians([4.0] * 3), rtol=1e-15)
    assert proc.ins_roll is None
    p = _write(tmp_path, MIRROR_HEAD + ",ins_roll_deg\nA1,azimuth,1,2,3,4,90\n")
    proc = collimation_csv.procedure_data(collimation_csv.read_mirror_csv(p))
    np.testing.assert_allclose(proc.ins_roll, [np.pi / 2], rtol=1e-15)
    p = _write(tmp_path, MIRROR_HEAD + "\nA1,azimuth,1,2,3,4\n")
    proc = collimation_csv.procedure_data(collimation_csv.read_mirror_csv(p))
    assert proc.center is None and proc.roll_mirror is None


def test_mirror_layout_json_and_the_written_file_by_hand(tmp_path):
    d = collimation_csv.MirrorData(("A", "P"), ("azimuth", "pitch"), np.radians([10.0, 20.0]),
                                   np.radians([0.0, 5.0]), np.radians([40.0, 50.0]),
                                   np.radians([1.0, 6.0]), np.radians([0.5, -0.5]))
    lay = d.layout()
    assert lay["mirror"] == ["A", "P"] and lay["set"] == ["azimuth", "pitch"]
    np.testing.assert_allclose(lay["theodolite_az"], np.radians([10.0, 20.0]), rtol=1e-15)
    np.testing.assert_allclose(lay["theodolite_el"], np.radians([0.0, 5.0]), rtol=1e-15)
    np.testing.assert_allclose(lay["ins_roll"], np.radians([0.5, -0.5]), rtol=1e-15)
    back = collimation_csv.MirrorData.from_layout(json.dumps(lay))
    assert back.mirror == ("A", "P") and back.sets == ("azimuth", "pitch")
    np.testing.assert_allclose(back.theodolite_az, np.radians([10.0, 20.0]), rtol=1e-15)
    whole = collimation_csv.MirrorData.from_layout(json.dumps(
        {"mirror": ["A"], "set": ["azimuth"], "theodolite_az": [1], "theodolite_el": [0],
         "ins_roll": [0]}))
    assert all(a.dtype == np.float64 for a in (whole.theodolite_az, whole.theodolite_el,
                                                 whole.ins_az, whole.ins_el, whole.ins_roll))
    assert back.ins_az.tolist() == [0.0, 0.0] and back.ins_el.tolist() == [0.0, 0.0]
    np.testing.assert_allclose(back.theodolite_el, np.radians([0.0, 5.0]), rtol=1e-15)
    np.testing.assert_allclose(back.ins_roll, np.radians([0.5, -0.5]), rtol=1e-15)
    p = tmp_path / "m.csv"
    collimation_csv.write_mirror_csv(p, d)
    assert p.read_text() == (MIRROR_HEAD + ",ins_roll_deg\n"
                             "A,azimuth,10.000000000,0.000000000,40.000000000,1.000000000,"
                             "0.500000000\n"
                             "P,pitch,20.000000000,5.000000000,50.000000000,6.000000000,"
                             "-0.500000000\n")
    flat = collimation_csv.MirrorData(("A",), ("azimuth",), np.radians([10.0]), np.zeros(1),
                                      np.zeros(1), np.zeros(1))
    assert flat.layout()["ins_roll"] is None
    assert collimation_csv.MirrorData.from_layout(json.dumps(flat.layout())).ins_roll is None
    collimation_csv.write_mirror_csv(p, flat)
    assert p.read_text() == (MIRROR_HEAD + "\nA,azimuth,10.000000000,0.000000000,0.000000000,"
                             "0.000000000\n")


# --------------------------------------------------------------------------------------------
# camera_csv.py
# --------------------------------------------------------------------------------------------

MODEL = "id,X,Y,unit\np1,0,0,mm\np2,10,0,mm\np3,0,20,mm\np4,10,20,mm\n"


def _views(n_views=3, ids=("p1", "p2", "p3", "p4")):
    rows = [f"V{v},{i},{100 + 10 * k + v},{200 - k}" for v in range(n_views)
            for k, i in enumerate(ids)]
    return "view,id,u,v\n" + "\n".join(rows) + "\n"


def test_camera_csv_units_views_and_rows_by_hand(tmp_path):
    """mm -> m: (10, 20) mm is (0.01, 0.02) m; cm and in likewise (0.01, 0.0254 m)."""
    model, unit = camera_csv.read_model_csv(_write(tmp_path, MODEL, "model.csv"))
    assert unit == "mm" and set(model) == {"p1", "p2", "p3", "p4"}
    np.testing.assert_allclose(model["p4"], [0.01, 0.02], rtol=1e-15)
    for u, size in (("cm", 0.01), ("in", 0.0254), ("m", 1.0)):
        model, unit = camera_csv.read_model_csv(_write(tmp_path, MODEL.replace("mm", u), "m.csv"))
        assert unit == u
        np.testing.assert_allclose(model["p4"], [10 * size, 20 * size], rtol=1e-15)
    views = _write(tmp_path, _views(3), "views.csv")
    d = camera_csv.read_camera_csv(tmp_path / "model.csv", views)
    assert d.views == ("V0", "V1", "V2") and d.n == 12 and d.unit == "mm"
    assert d.view.tolist() == [0] * 4 + [1] * 4 + [2] * 4
    assert d.point_id[:4] == ("p1", "p2", "p3", "p4")
    assert d.rows.tolist() == list(range(2, 14))
    np.testing.assert_allclose(d.points[3], [0.01, 0.02], rtol=1e-15)
    assert d.pixels[5].tolist() == [111.0, 199.0]


def test_camera_csv_refusals_in_full(tmp_path):
    m = _write(tmp_path, MODEL, "model.csv")
    bad = _write(tmp_path, MODEL.replace("p3,0,20,mm", "p3,0,20,cm"), "bad.csv")
    assert _refused(camera_csv.read_model_csv, bad) == (
        f"{bad}: row 4, column 'unit': 'cm' differs from the first row's 'mm' (one unit per file)")
    bad = _write(tmp_path, MODEL.replace("p1,0,0,mm", "p1,0,0,cm"), "bad.csv")
    assert _refused(camera_csv.read_model_csv, bad) == (
        f"{bad}: row 3, column 'unit': 'mm' differs from the first row's 'cm' (one unit per file)")
    bad = _write(tmp_path, MODEL + "p2,1,1,mm\n", "bad.csv")
    assert _refused(camera_csv.read_model_csv, bad) == (
        f"{bad}: row 6, column 'id': 'p2' repeats row 3")
    bad = _write(tmp_path, "id,X,Y,unit\np1,0,0,m\np2,1,0,m\np3,0,1,m\n", "bad.csv")
    assert _refused(camera_csv.read_model_csv, bad) == f"{bad}: 3 data rows, at least 4 needed"
    bad = _write(tmp_path, MODEL.replace("p3,0,20,mm", "p3,0,20,ft"), "bad.csv")
    assert _refused(camera_csv.read_model_csv, bad) == (
        f"{bad}: row 4, column 'unit': 'ft' is not one of cm, in, m, mm")
    v = _write(tmp_path, _views(3) + "V0,p9,1,1\n", "v.csv")
    assert _refused(camera_csv.read_camera_csv, m, v) == (
        f"{v}: row 14, column 'id': 'p9' is not a point of {m}")
    v = _write(tmp_path, _views(3) + "V1,p2,1,1\n", "v.csv")
    assert _refused(camera_csv.read_camera_csv, m, v) == (
        f"{v}: row 14, column 'id': 'p2' already seen in view 'V1' (row 7)")
    v = _write(tmp_path, _views(3) + "V3,p2,1,1\nV3,p1,1,1\nV3,p3,1,1\n", "v.csv")
    assert _refused(camera_csv.read_camera_csv, m, v) == (
        f"{v}: row 14, column 'view': view 'V3' has 3 points, at least 4 needed (a homography)")
    v = _write(tmp_path, _views(2), "v.csv")
    assert _refused(camera_csv.read_camera_csv, m, v) == (
        f"{v}: column 'view': 2 views (V0, V1), at least 3 needed")
    v = _write(tmp_path, _views(3).replace("V1,p1,101,200", "V1,p1,2e6,200"), "v.csv")
    assert _refused(camera_csv.read_camera_csv, m, v) == (
        f"{v}: row 6, column 'u': 2e6 is outside [-1e+06, 1e+06]")
    v = _write(tmp_path, _views(3).replace("V1,p1,101,200", "V1,p1,101,-2e6"), "v.csv")
    assert _refused(camera_csv.read_camera_csv, m, v) == (
        f"{v}: row 6, column 'v': -2e6 is outside [-1e+06, 1e+06]")
    for column, value in (("u", "-1000000.5"), ("u", "1000000.5"), ("v", "-1000000.5"),
                          ("v", "1000000.5")):
        new = f"V1,p1,{value},200" if column == "u" else f"V1,p1,101,{value}"
        v = _write(tmp_path, _views(3).replace("V1,p1,101,200", new), "v.csv")
        assert _refused(camera_csv.read_camera_csv, m, v) == (
            f"{v}: row 6, column '{column}': {value} is outside [-1e+06, 1e+06]")
    v = _write(tmp_path, "view,id,u,v\n", "v.csv")
    assert _refused(camera_csv.read_camera_csv, m, v) == f"{v}: 0 data rows, at least 1 needed"


def test_camera_csv_written_files_by_hand(tmp_path):
    m = _write(tmp_path, MODEL, "model.csv")
    d = camera_csv.read_camera_csv(m, _write(tmp_path, _views(3), "views.csv"))
    out_m, out_v = tmp_path / "m2.csv", tmp_path / "v2.csv"
    camera_csv.write_camera_csv(out_m, out_v, ["a", "b"], np.array([[1.0, 2.5], [1 / 3, 0.0]]),
                                "cm", d)
    assert out_m.read_text() == "id,X,Y,unit\na,1,2.5,cm\nb,0.3333333333,0,cm\n"
    lines = out_v.read_text().splitlines()
    assert lines[0] == "view,id,u,v" and len(lines) == 13
    assert lines[1] == "V0,p1,100,200" and lines[6] == "V1,p2,111,199"
    bad = tmp_path / "missing" / "v.csv"
    assert _refused(camera_csv.write_camera_csv, out_m, bad, ["a"], np.zeros((1, 2)), "m",
                    d).startswith(f"{bad}: cannot write (")
