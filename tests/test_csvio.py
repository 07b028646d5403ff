"""Strict CSV reading: one-line messages naming file, row and column."""

import pytest

from montecarlo.errors import InputError
from montecarlo.io.table import read_table


def _write(tmp_path, text):
    p = tmp_path / "data.csv"
    p.write_text(text)
    return p


def test_reads_numbers_and_text(tmp_path):
    p = _write(tmp_path, "name, a, b\nx, 1.5, 2\ny, -3, 4e-3\n")
    t = read_table(p, ["a", "b"], text=["name"], choices={"name": {"x", "y"}})
    assert t["a"].tolist() == [1.5, -3.0]
    assert t["name"].tolist() == ["x", "y"]


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("a\n1\n", "missing column 'b'"),
        ("a,b\n1,2\n1,abc\n", "row 3, column 'b': 'abc' is not a finite number"),
        ("a,b\n1,nan\n", "row 2, column 'b'"),
        ("a,b\n1,\n", "row 2, column 'b'"),
        ("a,b\n", "0 data rows"),
        ("", "not a readable CSV"),
    ],
)
def test_malformed_files_name_row_and_column(tmp_path, text, needle):
    p = _write(tmp_path, text)
    with pytest.raises(InputError) as info:
        read_table(p, ["a", "b"])
    message = str(info.value)
    assert needle in message and str(p) in message and "\n" not in message


def test_choices_and_missing_file(tmp_path):
    p = _write(tmp_path, "set,a\nazimuth,1\nroll,2\n")
    with pytest.raises(InputError, match="row 3, column 'set': 'roll' is not one of"):
        read_table(p, ["a"], text=["set"], choices={"set": {"azimuth", "pitch"}})
    with pytest.raises(InputError, match="no such file"):
        read_table(tmp_path / "nope.csv", ["a"])


def _camera_640x480():
    from montecarlo.geometry.camera import Camera

    return Camera.from_degrees(40.0, 30.0, 640, 480)


GROUND_HEADER = "target,x_m,y_m,z_m,px,pz\n"
GROUND_ROWS = "".join(f"T{i},{i}.0,100.0,1.0,0.0,0.0\n" for i in range(1, 5))


@pytest.mark.parametrize(("px", "pz", "needle"), [
    (319.0, 0.0, None), (0.0, 239.0, None),
    (330.0, 0.0, "column 'px': 330.0 is outside the detector (|px| <= 320 px)"),
    (0.0, 250.0, "column 'pz': 250.0 is outside the detector (|pz| <= 240 px)"),
])
def test_detector_limits_on_a_non_square_camera(tmp_path, px, pz, needle):
    """640 x 480 px with 40 x 30 deg: |px| <= 320 and |pz| <= 240 (half the pixel counts).
    px = 319 is accepted and pz = 250 refused; with the limits swapped (240 for px, 320 for
    pz) the first would be refused and the second accepted, so a swap fails this test."""
    from montecarlo.io.ground_csv import read_ground_csv

    p = _write(tmp_path, GROUND_HEADER + GROUND_ROWS + f"T9,9.0,100.0,1.0,{px},{pz}\n")
    if needle is None:
        data = read_ground_csv(p, _camera_640x480())
        assert data.pixels[-1].tolist() == [px, pz]
    else:
        with pytest.raises(InputError) as info:
            read_ground_csv(p, _camera_640x480())
        assert f"row 6, {needle}" in str(info.value)


def test_repeated_rows_of_ground_and_collimation_files_are_refused(tmp_path):
    """A target repeated in one session at one time (or without times), and a mirror repeated
    in its set, were counted twice (14 mirrors reported as 15)."""
    from montecarlo.io.collimation_csv import read_mirror_csv
    from montecarlo.io.ground_csv import read_ground_csv

    camera = _camera_640x480()
    p = _write(tmp_path, GROUND_HEADER + GROUND_ROWS + "T2,2.0,100.0,1.0,0.0,0.0\n")
    with pytest.raises(InputError, match=r"row 6, column 'target': 'T2' repeats row 3"):
        read_ground_csv(p, camera)
    p = _write(tmp_path, "target,x_m,y_m,z_m,px,pz,t_s,session\n"
               "T1,1.0,100.0,1.0,0,0,0,S1\nT1,1.0,100.0,1.0,0,0,10,S1\n"
               "T1,1.0,100.0,1.0,0,0,0,S2\n")
    assert read_ground_csv(p, camera).n == 3  # other time, other session: a new observation
    p = _write(tmp_path, "target,x_m,y_m,z_m,px,pz,t_s,session\n"
               "T1,1.0,100.0,1.0,0,0,0,S1\nT1,1.0,100.0,1.0,0,0,0,S1\n")
    with pytest.raises(InputError, match=r"row 3.*'T1' in session 'S1' at t_s = 0 repeats row 2"):
        read_ground_csv(p, camera)
    head = "mirror,set,theodolite_az_deg,theodolite_el_deg,ins_az_deg,ins_el_deg\n"
    p = _write(tmp_path, head + "A1,azimuth,0,0,30,0\nA1,pitch,0,12,30,12\n")
    assert len(read_mirror_csv(p).mirror) == 2  # one name in two sets: two mirrors
    p = _write(tmp_path, head + "A1,azimuth,0,0,30,0\nA2,azimuth,20,0,50,0\n"
               "A1,azimuth,0,0,30,0\n")
    with pytest.raises(InputError, match=r"row 4, column 'mirror': 'A1' in set 'azimuth' "
                                         r"repeats row 2"):
        read_mirror_csv(p)
