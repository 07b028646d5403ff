"""``montecarlo collimation ...`` run as a subprocess, as users run it."""

import json
import math

import numpy as np
import pytest

from montecarlo.cli import main
from tests.forked_cli import montecarlo_cli

GOOD = """mirror,set,theodolite_az_deg,theodolite_el_deg,ins_az_deg,ins_el_deg
A1,azimuth,0.0,0.0,30.0,-0.05
A2,azimuth,45.0,0.0,75.0,-0.05
P1,pitch,0.0,30.0,29.99,29.95
P2,pitch,0.0,60.0,29.95,59.95
"""


def run_cli(*args):
    return montecarlo_cli("collimation", *args)


def test_simulate_then_fit_recovers_the_injected_offsets(tmp_path):
    data, out = tmp_path / "cal.csv", tmp_path / "fit.json"
    sim = run_cli("simulate", str(data), "--seed", "7", "--axis-az-arcsec", "300",
                  "--axis-el-arcsec", "-120", "--with-roll", "--mount-roll-sigma-deg", "0.5",
                  "--readings", "absolute")
    assert sim.returncode == 0, sim.stderr
    fit = run_cli("fit", str(data), "--json", str(out), "--angle-sigma-arcsec", "2.83",
                  "--readings", "absolute")
    assert fit.returncode == 0, fit.stderr
    assert "axis_az" in fit.stdout and "RMS of all residuals" in fit.stdout
    report = json.loads(out.read_text())
    assert report["roll"] == "reported" and report["n_mirrors"] == 10
    for name, truth in (("axis_az", 300.0), ("axis_el", -120.0)):
        # 4 sigma: this single seeded data set must not fail by chance (p < 1e-4)
        assert abs(report["parameters"][name] - truth) < 4 * report["stderr"][name]
    assert report["rms_arcsec"]["after"]["all"] < report["rms_arcsec"]["before"]["all"] / 10
    assert len(report["mirrors"]) == 10
    assert set(report["mirrors"][0]) >= {"residual_before_az_arcsec", "residual_after_el_arcsec",
                                         "corrected_ins_az_deg", "consistency_after_arcsec"}


def _bad(text_edit):
    lines = GOOD.splitlines()
    return "\n".join(text_edit(lines)) + "\n"


MALFORMED = {
    "missing column": (_bad(lambda ls: [",".join(x.split(",")[:-1]) for x in ls]),
                       "missing column 'ins_el_deg'"),
    "non-numeric": (_bad(lambda ls: [*ls[:2], ls[2].replace("45.0", "4x5"), *ls[3:]]),
                    "row 3, column 'theodolite_az_deg'"),
    "nan": (_bad(lambda ls: [*ls[:3], ls[3].replace("29.99", "nan"), *ls[4:]]),
            "row 4, column 'ins_az_deg'"),
    "empty": (_bad(lambda ls: [*ls[:4], ls[4].replace("59.95", ""), *ls[5:]]),
              "row 5, column 'ins_el_deg'"),
    "too few rows": (_bad(lambda ls: ls[:2]), "1 data rows, at least 2 needed"),
    "unknown set": (_bad(lambda ls: [*ls[:2], ls[2].replace("azimuth", "roll"), *ls[3:]]),
                    "row 3, column 'set': 'roll' is not one of azimuth, pitch"),
    "not separable": (_bad(lambda ls: ls[:3]), "not separable"),
}


@pytest.mark.parametrize("case", list(MALFORMED))
def test_malformed_data_exit_2_with_one_line(tmp_path, capsys, case):
    """In-process ``cli.main`` (the same code path; the subprocess case is below)."""
    text, needle = MALFORMED[case]
    data, out = tmp_path / "bad.csv", tmp_path / "fit.json"
    data.write_text(text)
    assert main(["collimation", "fit", str(data), "--json", str(out),
                 "--readings", "absolute"]) == 2
    captured = capsys.readouterr()
    assert captured.err.count("\n") == 1, captured.err
    assert needle in captured.err and str(data) in captured.err
    assert not out.exists() and captured.out == ""


def test_malformed_data_subprocess_exit_code(tmp_path):
    data, out = tmp_path / "bad.csv", tmp_path / "fit.json"
    data.write_text(MALFORMED["unknown set"][0])
    result = run_cli("fit", str(data), "--json", str(out))
    assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr
    assert "Traceback" not in result.stderr and not out.exists()


def test_bad_flag_exits_2(tmp_path, capsys):
    data = tmp_path / "cal.csv"
    data.write_text(GOOD)
    assert main(["collimation", "fit", str(data), "--angle-sigma-arcsec", "-1"]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_figures_command_writes_pngs_and_reports_the_disagreement(tmp_path, capsys):
    assert main(["collimation", "figures", str(tmp_path)]) == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == [*(f"fig{i}.png" for i in (3, 4, 5, 6)), "procedure.png", "provenance.json"]
    for name in names[:-1]:
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "at β = 60°, Δβ is almost equal to γ: Δβ(60°) / γ = 0.001512 -> DOES NOT HOLD" \
        in capsys.readouterr().out


@pytest.mark.parametrize(("options", "fit_options"), [
    ((), ()),
    (("--roll-mirror", "left", "--with-roll"), ("--roll-mirror", "left")),
    (("--no-reference-rows", "--with-roll"), ()),
    (("--no-reference-rows",), ("--free-roll",)),
])
def test_procedure_simulate_then_fit(tmp_path, capsys, options, fit_options):
    """The paper's procedure (default --readings reference) on the pitch-to-60° layout."""
    data, out = tmp_path / "cal.csv", tmp_path / "fit.json"
    assert main(["collimation", "simulate", str(data), "--seed", "5", "--axis-az-arcsec", "250",
                 "--axis-el-arcsec", "-150", "--mount-roll-sigma-deg", "1",
                 "--pitch-elevations-deg", "12,24,36,48,60", *options]) == 0
    has_rows = "--no-reference-rows" not in options
    assert ("reference_center" in data.read_text()) == has_rows
    assert main(["collimation", "fit", str(data), "--json", str(out),
                 "--angle-sigma-arcsec", "2.83", *fit_options]) == 0
    r = json.loads(out.read_text())
    for name, truth in (("axis_az", 250.0), ("axis_el", -150.0)):
        # 4 sigma: this single seeded data set must not fail by chance (p < 1e-4)
        assert abs(r["parameters"][name] - truth) < 4 * r["stderr"][name]
    assert r["readings"] == "reference" and len(r["mirrors"]) == 10
    assert ("reference_az" in r["parameters"]) != has_rows
    assert r["rms_arcsec"]["after"]["all"] < r["rms_arcsec"]["before"]["all"]
    assert set(r["mirrors"][0]) >= {"corrected_ins_az_deg", "corrected_ins_el_deg",
                                    "deviation_az_arcsec", "verdict"}
    corr = np.array(r["correlation"]["matrix"])
    np.testing.assert_allclose(np.diag(corr), 1.0, atol=1e-12)
    # the corrected readings agree with the theodolite's within the propagated noise
    dev = [max(abs(m["deviation_az_arcsec"]), abs(m["deviation_el_arcsec"])) for m in r["mirrors"]]
    assert max(dev) < 30.0 and r["claim_15_arcsec"]["max_deviation_arcsec"] == max(dev)


def test_procedure_report_flags_gamma_and_the_level_mount_floor(tmp_path, capsys):
    data = tmp_path / "cal.csv"
    assert main(["collimation", "simulate", str(data), "--seed", "2", "--axis-el-arcsec",
                 "400"]) == 0
    capsys.readouterr()
    assert main(["collimation", "fit", str(data), "--angle-sigma-arcsec", "2.83"]) == 0
    text = capsys.readouterr().out
    assert "NOT DETERMINED: axis_az" in text and "pitch mirrors must reach about" in text
    assert "INS roll not recorded: a level mount is assumed" in text
    assert "the paper's 15″ claim" in text


REFERENCE_ROWS = """C,reference_center,0.0,0.0,30.0,0.0
R,reference_roll,90.0,0.0,120.0,0.0
"""


@pytest.mark.parametrize(("text", "options", "needle"), [
    (GOOD + REFERENCE_ROWS + "C2,reference_center,0,0,30,0\n", (),
     "row 8, column 'set': a second 'reference_center' row (the first is row 6)"),
    (GOOD + REFERENCE_ROWS.splitlines()[0] + "\n", (),
     "a 'reference_center' row without a 'reference_roll' row"),
    (GOOD, ("--readings", "absolute", "--free-roll"), "--free-roll: only with --readings"),
    (GOOD, ("--fit-frame-tilt",), "--fit-frame-tilt: only with --readings absolute"),
    (GOOD, ("--roll-mirror", "up"), "invalid choice: 'up'"),
    (GOOD, ("--angle-sigma-arcsec", "2", "--ins-sigma-arcsec", "1"), "not both"),
])
def test_procedure_bad_input_exits_2_with_one_line(tmp_path, capsys, text, options, needle):
    data, out = tmp_path / "bad.csv", tmp_path / "fit.json"
    data.write_text(text)
    assert main(["collimation", "fit", str(data), "--json", str(out), *options]) == 2
    captured = capsys.readouterr()
    assert captured.err.count("\n") == 1 and needle in captured.err, captured.err
    assert not out.exists()


def test_absolute_data_read_as_reference_readings_is_flagged(tmp_path, capsys):
    """Absolute readings fitted as relative ones (the default) leave a misfit the report names."""
    data = tmp_path / "abs.csv"
    assert main(["collimation", "simulate", str(data), "--readings", "absolute", "--seed",
                 "3"]) == 0
    capsys.readouterr()
    assert main(["collimation", "fit", str(data), "--angle-sigma-arcsec", "2.83"]) == 0
    assert "MISFIT" in capsys.readouterr().out
    assert main(["collimation", "fit", str(data), "--angle-sigma-arcsec", "2.83",
                 "--readings", "absolute"]) == 0
    assert "MISFIT" not in capsys.readouterr().out


def _relative_file(tmp_path, name, seed, side="left", mount="1"):
    path = tmp_path / name
    assert main(["collimation", "simulate", str(path), "--seed", str(seed), "--roll-mirror",
                 side, "--no-reference-rows", "--axis-az-arcsec", "-36", "--axis-el-arcsec",
                 "-2520", "--mount-roll-sigma-deg", mount]) == 0
    return path


def test_auto_takes_the_side_the_data_support_and_warns_once(tmp_path, capsys):
    """Relative readings made with the roll mirror on the left: the default (auto) fits both
    sides, keeps left, reports both chi-squares and warns in one line on standard error that
    the stated (the text's) right is rejected. Stating right keeps right, with the warning."""
    data, out = _relative_file(tmp_path, "a.csv", 5), tmp_path / "fit.json"
    capsys.readouterr()
    assert main(["collimation", "fit", str(data), "--json", str(out)]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    r = json.loads(out.read_text())
    side = r["roll_mirror"]
    assert side["chosen"] == "left" and side["stated"] == "right" and side["decided"]
    assert side["chi2_right"] > 10 * side["chi2_left"]
    assert side["weights"] == "1 arcsec per reading"  # sigmas a posteriori here
    assert r["azimuth_sense"]["chosen"] == "same"
    assert r["claim_15_arcsec"]["in_sample"] is True
    assert len(err) == 1 and err[0].startswith("warning: the data reject the roll mirror on "
                                               "the right")
    assert abs(r["parameters"]["axis_el"] + 2520.0) < 4 * r["stderr"]["axis_el"] + 72.0
    assert main(["collimation", "fit", str(data), "--roll-mirror", "right", "--json",
                 str(tmp_path / "right.json")]) == 0
    assert json.loads((tmp_path / "right.json").read_text())["roll_mirror"]["chosen"] == "right"
    assert "kept as asked" in capsys.readouterr().err


def test_corrected_values_are_in_the_file_theodolite_frame(tmp_path):
    """Noise-free data whose theodolite azimuth zero is 5° off the central mirror, free rolls:
    the corrected reading of each mirror points along its normal, so its heading equals the
    file's theodolite azimuth (hand: the simulator wrote the true normal there), not the
    azimuth relative to the fitted central mirror."""
    from montecarlo.io.collimation_csv import MirrorData, write_mirror_csv
    from montecarlo.seed003 import procedure as pr
    from montecarlo.seed003.model import Noise

    az, el, sets = pr.procedure_layout()
    d = pr.simulate_procedure(math.radians(-0.01), math.radians(-0.7), az + math.radians(5),
                              el, Noise(0, 0, 0, 0, 0), 0, side=-1.0,
                              az_center=math.radians(5.0), reference_rows=False,
                              with_roll=False)
    names = tuple(f"M{i}" for i in range(az.size))
    path = tmp_path / "c.csv"
    write_mirror_csv(path, MirrorData(names, tuple(sets), d.theodolite_az, d.theodolite_el,
                                      d.ins_az, d.ins_el))
    out = tmp_path / "c.json"
    assert main(["collimation", "fit", str(path), "--free-roll", "--angle-sigma-arcsec", "2",
                 "--json", str(out)]) == 0
    r = json.loads(out.read_text())
    for m, a, e in zip(r["mirrors"], np.degrees(az) + 5.0, np.degrees(el), strict=True):
        assert (m["corrected_ins_az_deg"] - a) * 3600 == pytest.approx(0.0, abs=0.1)
        assert (m["theodolite_az_deg"] - a) * 3600 == pytest.approx(0.0, abs=1e-6)
        assert (m["corrected_ins_el_deg"] - e) * 3600 == pytest.approx(0.0, abs=0.1)


def test_verify_applies_a_saved_fit_out_of_sample(tmp_path, capsys):
    """The fit's offsets applied to its own data reproduce its deviations (level mount: only the
    reference azimuth is refitted, to the same value); applied to a second set of the same
    device they give out-of-sample deviations; leave-one-out adds them to the fit's JSON."""
    a = _relative_file(tmp_path, "a.csv", 7, mount="0")
    b = _relative_file(tmp_path, "b.csv", 8, mount="0")
    fit, same, other = tmp_path / "fit.json", tmp_path / "same.json", tmp_path / "other.json"
    assert main(["collimation", "fit", str(a), "--angle-sigma-arcsec", "2.83", "--verify",
                 "leave-one-out", "--json", str(fit)]) == 0
    r = json.loads(fit.read_text())
    assert r["verification"]["in_sample"] is False
    assert len(r["verification"]["mirrors"]) == 10
    assert main(["collimation", "verify", str(fit), str(a), "--json", str(same)]) == 0
    s = json.loads(same.read_text())
    for m, n in zip(r["mirrors"], s["mirrors"], strict=True):
        assert n["deviation_az_arcsec"] == pytest.approx(m["deviation_az_arcsec"], abs=1e-3)
        assert n["deviation_el_arcsec"] == pytest.approx(m["deviation_el_arcsec"], abs=1e-3)
    assert main(["collimation", "verify", str(fit), str(b), "--json", str(other)]) == 0
    o = json.loads(other.read_text())
    worst = max(max(abs(m["deviation_az_arcsec"]), abs(m["deviation_el_arcsec"]))
                for m in o["mirrors"])
    assert o["claim_15_arcsec"]["max_deviation_arcsec"] == pytest.approx(worst)
    assert o["in_sample"] is False and o["claim_15_arcsec"]["holds"] == (worst <= 15.0)
    bad = tmp_path / "bad.json"
    bad.write_text('{"readings": "reference"}')
    capsys.readouterr()
    assert main(["collimation", "verify", str(bad), str(b)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.json" in err[0]
