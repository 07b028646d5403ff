"""PCI and MIB by Monte Carlo through the study runner (montecarlo/systems/identifiability.py).

The acceptance: the MIB searched on one set of seeds (common random numbers) is checked on
fresh seeds; the PCI there must be within 3 points of its target. With ``n`` fresh sets the
binomial standard deviation at 0.8 is sqrt(0.16 / n) (0.018 at n = 500), and the search on
``m`` sets adds about as much again (the crossing of a step function of ``m`` sets).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from montecarlo.systems import identifiability as idf

ROOT = Path(__file__).resolve().parents[1]

GROUND = ("discrepancy_ground", "radial_distortion")
COLLIMATION = ("discrepancy_collimation", "axis_misalignment")
LINEAR_CHECKED = ("focal_scale", "aspect_ratio", "drift", "lever_arm")
"""Ground candidates whose linear PCI is checked against the nonlinear Monte Carlo."""


def mib_check(system: str, effect: str, search_sets: int, check_sets: int,
              target: float = idf.PCI_TARGET, n_jobs: int | None = 2,
              tol: float = 0.03) -> dict[str, float]:
    """Search the MIB (seed 1) on the system's default design, then the PCI there on fresh
    seeds (seed 2)."""
    m, seen = idf.mib_multiple(system, {}, effect, target, search_sets, 1, n_jobs, tol)
    (check,) = idf.pci(system, {}, effect, [m], check_sets, 2, n_jobs)
    return {"mib_mdb": m, "pci_check": check, "evaluations": len(seen),
            "pci_search": {f"{k:.4f}": v for k, v in sorted(seen.items())}}


def test_pci_zero_then_growing():
    """Collimation axis_misalignment on 16 sets (the same noise at every size): at a stated
    size of zero it is named only as often as the global test falsely rejects (alpha 0.01:
    two or more of 16 has probability 0.011); the PCI cannot fall from 1 to 4 MDB (common
    random numbers); at 4 MDB (noncentrality 16 times the MDB's) it is named in most sets."""
    system, effect = COLLIMATION
    zero, one, four = idf.pci(system, {}, effect, [{"axis_az": 0.0, "axis_el": 0.0}, 1.0,
                                                   4.0], 16, 3)
    assert zero <= 1 / 16
    assert one <= four
    assert four >= 0.75


@pytest.mark.slow
@pytest.mark.parametrize("case", [GROUND, COLLIMATION], ids=["ground", "collimation"])
def test_pci_at_mib_within_3_points(case, figures, request):
    """Search on 500 sets, check on 500 fresh ones (docs/validation/discrepancy.md)."""
    out = mib_check(*case, search_sets=500, check_sets=500)
    name = request.node.callspec.id
    if "mib_mdb" in out:
        figures.record(f"{name}.mib_mdb", out["mib_mdb"])
    figures.record(f"{name}.pci_check", out["pci_check"], idf.PCI_TARGET - 0.03,
                   idf.PCI_TARGET + 0.03)
    assert abs(out["pci_check"] - idf.PCI_TARGET) <= 0.03, out


def run_cli(*args, timeout=600, fresh=False):
    """``python -m montecarlo diagnose ARGS`` in a bare environment: a fresh process if
    ``fresh``, else one forked from a process with the libraries imported
    (``tests/forked_cli.py``)."""
    import subprocess
    import sys

    from tests.forked_cli import montecarlo_cli

    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    if not fresh:
        return montecarlo_cli("diagnose", *args, timeout=timeout, env=env)
    return subprocess.run([sys.executable, "-m", "montecarlo", "diagnose", *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, env=env)


def collimation_args(tmp_path):
    data = ROOT / "tests" / "data" / "bad_inputs" / "csv" / "valid_collimation.csv"
    return ("collimation", data, "--angle-sigma-arcsec", "3", "--readings", "absolute",
            "--json", tmp_path / "d.json")


def test_cli_identifiability_linear_json(tmp_path):
    """``diagnose collimation --identifiability`` (linear, 1000 sets): pci, mib, mib_mdb and
    their mode beside every testable candidate's MDB in the JSON; ``--check-sets`` without
    ``--identifiability`` is refused with one line and exit code 2, nothing written."""
    out = run_cli(*collimation_args(tmp_path), "--check-sets", "5", fresh=True)
    assert "Traceback" not in out.stderr
    assert out.returncode == 2 and "--check-sets" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "d.json").exists()
    auto = [a if a != "3" else "auto" for a in collimation_args(tmp_path)]
    out = run_cli(*auto, "--identifiability", "--sets", "1000")
    assert out.returncode == 2 and "--angle-sigma-arcsec" in out.stderr and "auto" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "d.json").exists()
    out = run_cli(*collimation_args(tmp_path), "--identifiability", "--sets", "1000")
    assert out.returncode == 0, out.stderr[-2000:]
    report = json.loads((tmp_path / "d.json").read_text())
    info = report["identifiability"]
    assert (info["mode"], info["sets"], info["check"]) == ("linear", 1000, None)
    check_candidates(report)


def check_candidates(report, check_sets=None):
    testable = [c for c in report["candidates"] if c["status"] == "testable"]
    assert testable
    for c in testable:
        assert c["pci_size"] == ("fitted" if c["name"] in
                                 [e["name"] for e in report["named_effects"]] else "1 MDB")
        if c["pci"] is None:
            assert c["identifiability_reason"]
            continue
        assert c["mode"] == "linear"
        assert 0.0 <= c["pci"] <= 1.0
        if c["mib_mdb"] is not None:
            after = {a["name"]: a for a in report["candidates_after"]}
            mdb = (c["mdb"] if c["mib_of"] == "base model MDB" else after[c["name"]]["mdb"])
            assert c["mib"] == pytest.approx({k: c["mib_mdb"] * v for k, v in mdb.items()})
        if check_sets is None:
            assert "check" not in c
        else:
            assert c["check"]["mode"] == "nonlinear" and c["check"]["sets"] == check_sets
            assert 0.0 <= c["check"]["pci"] <= 1.0


@pytest.mark.slow
def test_cli_identifiability_check_json(tmp_path):
    """``--check-sets 8`` adds the nonlinear check beside the linear figures (the interface,
    not the figures)."""
    out = run_cli(*collimation_args(tmp_path), "--identifiability", "--sets", "1000",
                  "--check-sets", "8", "--n-jobs", "1", timeout=1200)
    assert out.returncode == 0, out.stderr[-2000:]
    report = json.loads((tmp_path / "d.json").read_text())
    assert report["identifiability"]["check"]["mode"] == "nonlinear"
    check_candidates(report, check_sets=8)


def ground_example_design():
    """The shipped ground example's diagnosis design (as ``diagnose ground`` builds it)."""
    from montecarlo.discrepancy import ground_effects as ge
    from montecarlo.discrepancy.engine import diagnose
    from montecarlo.geometry.camera import Camera
    from montecarlo.io.ground_csv import read_ground_csv

    camera = Camera.from_degrees(90, 90, 512, 512)
    data = read_ground_csv(ROOT / "results" / "examples" / "discrepancy_ground" / "data.csv",
                           camera, ge.min_targets(), "")
    d = diagnose(ge.ground_problem(data, camera, 0.3, 0.01, ge.STANDARD_REFRACTION))
    view = ge.report_view(data, camera, 0.3, 0.01, ge.STANDARD_REFRACTION)
    return d, {**view.study_params(d.after), "alpha": d.alpha}


@pytest.mark.slow
@pytest.mark.parametrize("effect", LINEAR_CHECKED)
def test_linear_pci_within_3_points_of_nonlinear(effect, figures):
    """On the shipped ground example, at 1 MDB: the linear PCI (10,000 sets) and the
    nonlinear one (the whole diagnosis of 200 simulated data sets) within 3 points. The
    binomial standard deviation of the nonlinear figure at a PCI of 0.75 on 200 sets is 3.1
    points (the linear one's, 0.4): the bound is the goal's, about one standard deviation."""
    d, design = ground_example_design()
    params = d.problem.effect(effect).parameters
    (linear,) = idf.linear_pci(GROUND[0], design, effect, [1.0], 10_000, 0, parameters=params)
    (nonlinear,) = idf.pci(GROUND[0], design, effect, [1.0], 200, 0, 2, params)
    figures.record(f"{effect}.linear", linear)
    figures.record(f"{effect}.nonlinear", nonlinear, linear - 0.03, linear + 0.03)
    assert abs(linear - nonlinear) <= 0.03, (linear, nonlinear)


def test_the_table_keeps_its_columns_whatever_the_length_of_an_entry():
    """A three-parameter MDB is longer than a one-parameter one: every row's MIB and PCI still
    start where the header's do, and a candidate without a PCI gives its reason there."""
    def candidate(name, mdb, mib, pci):
        return {"name": name, "mdb": mdb, "units": dict.fromkeys(mdb, "m"), "pci": pci,
                "pci_size": "1 MDB", "mib": mib, "mib_mdb": 1.5, "mib_of": "final model MDB",
                "identifiability_reason": "absorbed by gamma"}

    three = {"l_x": 0.0924, "l_y": 0.0676, "l_z": 0.1}
    report = {"identifiability": {"sets": 100, "pci_target": 0.8, "check": None},
              "candidates": [candidate("lever_arm", three, {k: 2 * v for k, v in three.items()},
                                       0.333),
                             candidate("b", {"b_y": 0.06}, {"b_y": 0.12}, 0.79),
                             candidate("rotation", {"r": 1.0}, None, None)]}
    header, *rows = idf.format_table(report).splitlines()[1:]
    mib, pci = header.index("MIB (linear)"), header.index("PCI (linear)")
    assert [r[mib:].split(" (")[0] for r in rows] == [
        "l_x 0.185 m, l_y 0.135 m, l_z 0.2 m", "b_y 0.12 m", "absorbed by gamma"]
    assert [r[pci:] for r in rows[:2]] == ["0.333 at 1 MDB", "0.790 at 1 MDB"]
    assert rows[0][pci - 1] == rows[1][pci - 1] == " "
