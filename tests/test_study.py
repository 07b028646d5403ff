"""Study files: shipped studies load, sweeps expand, and every mistake is one line, exit 2."""

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from montecarlo.cli import main
from montecarlo.errors import InputError
from montecarlo.systems import load_study

STUDIES = sorted(Path(__file__).parent.parent.glob("studies/*.toml"))

BASE = """
[study]
name = "t"
system = "ground"
trials = 100
seed = 1

[sensor]
fov_deg = [90.0, 90.0]
pixels = [512, 512]

[geometry]
L_m = 50.0
H_m = 1.0

[errors]
pixel_px = { dist = "normal", sigma = 0.5 }
pixel_relation = "common"
"""


def write(tmp_path, text, name="study.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


@pytest.mark.parametrize("path", STUDIES, ids=[p.name for p in STUDIES])
def test_shipped_studies_validate(path):
    study = load_study(path)
    assert study.points and study.metrics


def test_table1_study_has_the_papers_six_rows_twice():
    study = load_study(Path(__file__).parent.parent / "studies/table1.toml")
    assert len(study.points) == 12
    assert [p.trials for p in study.points[::2]] == [64] * 6  # the 2^6 corners


def test_zip_and_product_expand(tmp_path):
    p = write(tmp_path, BASE + """
    [[sweep]]
    mode = "zip"
    "geometry.L_m" = [50.0, 100.0, 200.0]
    "geometry.H_m" = [1.0, 2.0, 3.0]

    [[sweep]]
    "errors.pixel_relation" = ["common", "independent"]
    "errors.pixel_px.sigma" = [0.1, 0.2]
    """)
    study = load_study(p)
    assert len(study.points) == 3 * 2 * 2
    assert study.points[-1].overrides == {"geometry.L_m": 200.0, "geometry.H_m": 3.0,
                                          "errors.pixel_relation": "independent",
                                          "errors.pixel_px.sigma": 0.2}
    assert study.hash() == load_study(p).hash()
    assert study.hash() != load_study(p, seed=2).hash()


def test_one_at_a_time_varies_each_key_around_the_base(tmp_path):
    p = write(tmp_path, BASE + """
    [[sweep]]
    mode = "one_at_a_time"
    "geometry.L_m" = [25.0, 100.0]
    "errors.pixel_px.sigma" = [0.1]

    [[sweep]]
    "errors.pixel_relation" = ["common", "independent"]
    """)
    study = load_study(p)
    assert len(study.points) == (1 + 2 + 1) * 2
    values = [(q.values["geometry.L_m"], q.values["errors.pixel_px.sigma"])
              for q in study.points[::2]]
    assert values == [(50.0, 0.5), (25.0, 0.5), (100.0, 0.5), (50.0, 0.1)]


MISTAKES = [
    ("unknown key", BASE.replace("L_m = 50.0", "L_mm = 50.0"), ["geometry.L_mm", "unknown key"]),
    ("wrong type", BASE.replace("L_m = 50.0", 'L_m = "fifty"'), ["geometry.L_m", "'fifty'"]),
    ("out of range", BASE.replace("L_m = 50.0", "L_m = -5.0"), ["geometry.L_m", "-5.0"]),
    ("zero height", BASE.replace("H_m = 1.0", "H_m = 0.0"), ["geometry.H_m", "0.0"]),
    ("empty sweep", BASE + '[[sweep]]\n"geometry.L_m" = []\n', ["geometry.L_m", "empty list"]),
    ("zip lengths", BASE + '[[sweep]]\nmode = "zip"\n"geometry.L_m" = [1.0, 2.0]\n'
     '"geometry.H_m" = [1.0]\n', ["zipped lists differ", "geometry.H_m: 1"]),
    ("unknown system", BASE.replace('system = "ground"', 'system = "orbital"'),
     ["study.system", "'orbital'"]),
    ("TOML syntax", BASE.replace("trials = 100", "trials = = 100"), ["not valid TOML", "line"]),
    ("unknown dist", BASE.replace('dist = "normal"', 'dist = "gaussian"'),
     ["errors.pixel_px", "gaussian"]),
    ("missing section", BASE.replace("[geometry]\nL_m = 50.0\nH_m = 1.0\n", ""),
     ["geometry", "required key is missing"]),
    ("missing relation", BASE.replace('pixel_relation = "common"\n', ""),
     ["errors.pixel_relation", "required"]),
    ("correlation range", BASE.replace('pixel_relation = "common"', "pixel_relation = 1.5"),
     ["errors.pixel_relation", "1.5"]),
    ("normal worst case", BASE.replace("[errors]", '[errors]\nevaluation = "worst_case"'),
     ["errors", "pixel_px", "no worst case"]),
    ("field of view", BASE.replace("fov_deg = [90.0, 90.0]", "fov_deg = [190.0, 90.0]"),
     ["sensor.fov_deg", "190.0"]),
    ("bad sweep value", BASE + '[[sweep]]\n"geometry.H_m" = [1.0, 0.0]\n',
     ["geometry.H_m", "sweep point 1", "0.0"]),
    ("sweep into a number", BASE + '[[sweep]]\n"geometry.L_m.x" = [1.0]\n',
     ["geometry.L_m.x", "not a table"]),
    ("unknown spec metric", BASE + '[spec]\nmetric = "nope"\nlimit = 3.0\n',
     ["spec.metric", "nope"]),
    ("negative trials", BASE.replace("trials = 100", "trials = -3"), ["study.trials", "-3"]),
    ("one_at_a_time without base", BASE + '[[sweep]]\nmode = "one_at_a_time"\n'
     '"errors.dx_m.bound" = [0.1]\n', ["errors.dx_m.bound", "base value"]),
    ("unknown sweep mode", BASE + '[[sweep]]\nmode = "random"\n"geometry.L_m" = [1.0]\n',
     ["sweep[0].mode", "'random'"]),
]


@pytest.mark.parametrize(("kind", "text", "needles"), MISTAKES, ids=[m[0] for m in MISTAKES])
def test_mistakes_give_one_line_and_exit_2(tmp_path, capsys, kind, text, needles):
    p = write(tmp_path, text)
    code = main(["run", str(p), "--quiet", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert str(p) in err, err
    for needle in needles:
        assert needle in err, (needle, err)
    assert not (tmp_path / "out").exists()


def test_missing_file_and_bad_flags(tmp_path, capsys):
    assert main(["run", str(tmp_path / "nope.toml")]) == 2
    assert "no such study file" in capsys.readouterr().err
    p = write(tmp_path, BASE)
    for flags in (["--n-jobs", "0"], ["--trials", "ten"], ["--backend", "mpi"],
                  ["--scheduler", "tcp://x:1"]):
        assert main(["run", str(p), "--quiet", *flags]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1, err


def test_real_process_exit_code(tmp_path):
    p = write(tmp_path, BASE.replace("L_m = 50.0", "L_m = -5.0"))
    out = subprocess.run([sys.executable, "-m", "montecarlo", "run", str(p)],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert out.stderr.strip().count("\n") == 0 and "geometry.L_m" in out.stderr


def test_grid_size_is_counted_before_expanding_and_limited_by_max_points(tmp_path, capsys):
    """product 3 x 2 = 6, times zip 4, times one_at_a_time 1 + 2 + 1 = 4: 96 points (by hand),
    counted from the lists alone; --max-points 95 refuses the study in one line naming the
    count and a memory estimate, 96 admits it, and the default limit refuses a million points
    within a second (validate was still expanding after 120 s at 4.7 GB)."""
    import time

    from montecarlo.engine.study import BYTES_PER_POINT, MAX_POINTS, _expand, grid_size

    groups = [("product", {"a": [1, 2, 3], "b": [1, 2]}), ("zip", {"c": [1, 2, 3, 4],
                                                               "d": [5, 6, 7, 8]}),
              ("one_at_a_time", {"e": [1, 2], "f": [3]})]
    assert grid_size(groups) == 96 == len(_expand(groups))
    sweep = """
    [[sweep]]
    "geometry.L_m" = [40.0, 50.0, 60.0]
    "geometry.H_m" = [1.0, 2.0]
    [[sweep]]
    mode = "zip"
    "errors.pixel_px.sigma" = [0.1, 0.2, 0.3, 0.4]
    "sensor.pixels" = [[512, 512], [640, 480], [1024, 768], [2048, 2048]]
    [[sweep]]
    mode = "one_at_a_time"
    "mounting.psi_deg" = [10.0, 20.0]
    "mounting.theta_deg" = [5.0]
    """
    p = write(tmp_path, BASE + "[mounting]\npsi_deg = 30.0\ntheta_deg = 0.0\ngamma_deg = 0.0\n"
              + sweep)
    assert main(["validate", str(p), "--max-points", "95"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "96 grid points" in err and "--max-points" in err
    assert f"{96 * BYTES_PER_POINT / 1e6:.3g} MB" in err
    assert main(["validate", str(p), "--max-points", "96"]) == 0
    ranges = ", ".join(f"{v:.1f}" for v in range(10, 1010))
    sigmas = ", ".join(f"{v / 1000:.3f}" for v in range(1, 1001))
    huge = write(tmp_path, BASE + f'[[sweep]]\n"geometry.L_m" = [{ranges}]\n'
                 f'"errors.pixel_px.sigma" = [{sigmas}]\n', "huge.toml")
    start = time.monotonic()
    assert main(["validate", str(huge)]) == 2
    assert time.monotonic() - start < 5.0
    assert f"1,000,000 grid points (about 150 GB of memory) exceed the limit of {MAX_POINTS:,}" \
        in capsys.readouterr().err


def test_an_errors_file_updates_the_study_errors_key_by_key(tmp_path):
    """``--errors FILE``: the file's [errors] keys replace the study's, the others stay."""
    from montecarlo.engine.study import merge_errors_file

    raw = {"study": {"name": "s"}, "errors": {"pixel_px": 0.3, "dx_m": 0.1}}
    path = tmp_path / "e.toml"
    path.write_text('[errors]\npixel_px = { dist = "normal", sigma = 0.8 }\n')
    merged = merge_errors_file(raw, path)
    assert merged["errors"] == {"pixel_px": {"dist": "normal", "sigma": 0.8}, "dx_m": 0.1}
    assert raw["errors"]["pixel_px"] == 0.3  # the study given is not changed
    path.write_text('[errors]\npixel_px = 0.5\n[geometry]\nL_m = 1.0\n')
    with pytest.raises(InputError, match=r"e.toml: .*nothing else \(got: geometry\)"):
        merge_errors_file(raw, path)
