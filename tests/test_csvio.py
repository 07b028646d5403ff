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
