"""SALib problem files for the error budget: export, import, round trip."""

from __future__ import annotations

import copy
import json
import subprocess
import sys

import numpy as np
import pytest
from SALib import ProblemSpec

from montecarlo.design import budget, problem_spec
from montecarlo.design.sizing_problem import DEFAULT_DESIGN, Requirement
from montecarlo.errors import InputError

REQ = Requirement(limit=3.0, metric="rotation_angle", statistic="p95", confidence=0.9,
                  variant="normalised")
SMALL = {"samples": 128, "trials": 400, "seed": 5, "resamples": 20, "n_jobs": 1}


def test_export_holds_the_study_factors_by_hand():
    """The default design: dx, dy, dh1 uniform ±0.1 m, dh ±0.001 m, pixel normal σ 0.3 px
    common to both targets -> SALib unif [-b, b] and norm [0, σ] on pixel_x, pixel_z."""
    r = budget.budget(DEFAULT_DESIGN, REQ, "common", **SMALL)
    spec = problem_spec.problem_spec(r.problem, REQ.metric)
    assert spec == {"num_vars": 6,
                    "names": ["dx_m", "dy_m", "dh1_m", "dh_m", "pixel_x", "pixel_z"],
                    "groups": ["dx_m", "dy_m", "dh1_m", "dh_m", "pixel_px", "pixel_px"],
                    "dists": ["unif"] * 4 + ["norm"] * 2,
                    "bounds": [[-0.1, 0.1]] * 3 + [[-0.001, 0.001]] + [[0.0, 0.3]] * 2,
                    "outputs": ["rotation_angle"]}
    assert ProblemSpec(json.loads(json.dumps(spec)))["num_vars"] == 6  # SALib takes it


@pytest.mark.parametrize("relation", ["common", "independent"])
def test_round_trip_gives_the_same_sobol_indices(relation):
    """Export the problem of the native budget, import it into a study whose error sources
    are all different, and budget again with the same seed: the same Sobol indices."""
    native = budget.budget(DEFAULT_DESIGN, REQ, relation, **SMALL)
    spec = json.loads(json.dumps(problem_spec.problem_spec(native.problem, REQ.metric)))
    other = copy.deepcopy(DEFAULT_DESIGN)
    other["errors"].update({"dx_m": 0.3, "dy_m": {"dist": "normal", "sigma": 1.0},
                            "dh1_m": 0.0, "pixel_px": {"dist": "uniform", "bound": 2.0}})
    base, rel = problem_spec.apply_problem_spec(other, spec)
    assert rel == relation
    again = budget.budget(base, REQ, rel, **SMALL)
    cols = ["S1", "S1_conf", "ST", "ST_conf"]
    np.testing.assert_array_equal(again.table[cols].to_numpy(), native.table[cols].to_numpy())
    assert list(again.table.index) == list(native.table.index)


def test_import_conversions_by_hand():
    spec = {"names": ["dx_m", "dy_m", "dh_m", "pixel_a_x", "pixel_a_z", "pixel_b_x",
                      "pixel_b_z"],
            "groups": ["dx_m", "dy_m", "dh_m", *["pixel_px"] * 4],
            "dists": ["unif", "triang", "truncnorm", *["norm"] * 4],
            "bounds": [[0.1, 0.3], [-0.2, 0.2, 0.5], [-0.002, 0.004, 0.001, 0.002],
                       *[[0.0, 0.4]] * 4]}
    errors, relation = problem_spec.errors_from_problem_spec(spec)
    assert relation == "independent"
    assert errors["dx_m"] == {"dist": "uniform", "bound": pytest.approx(0.1), "center": 0.2}
    assert errors["dy_m"] == {"dist": "triangular", "bound": 0.2, "center": 0.0}
    assert errors["dh_m"] == {"dist": "truncnormal", "sigma": 0.002, "bound": 0.003,
                              "mean": 0.001}
    assert errors["pixel_px"] == {"dist": "normal", "sigma": 0.4, "mean": 0.0}
    base, _ = problem_spec.apply_problem_spec(DEFAULT_DESIGN, spec)
    assert base["errors"]["dh1_m"] == 0.0  # not listed: fixed at its centre


@pytest.mark.parametrize(("change", "message"), [
    ({"names": ["dz_m"], "bounds": [[0, 1]]}, "'dz_m' is not a budget factor"),
    ({"names": ["dx_m"], "bounds": [[1, 0]]}, "need low < high"),
    ({"names": ["dx_m"], "bounds": [[0, 1]], "dists": ["lognorm"]}, "'lognorm' has no"),
    ({"names": ["pixel_x"], "bounds": [[0, 1]], "groups": ["pixel_px"]}, "pixel factors"),
    ({"names": ["dx_m"], "bounds": [[0, 1]], "groups": ["g"]}, "belongs to group 'dx_m'"),
])
def test_bad_problems_are_refused_in_one_line(change, message):
    with pytest.raises(InputError, match=message):
        problem_spec.errors_from_problem_spec(problem_spec.read_problem_spec_dict(change))


@pytest.mark.slow
def test_cli_round_trip(tmp_path):
    """budget --problem-spec, then budget --from-problem-spec: the same budget table."""
    run = [sys.executable, "-m", "montecarlo", "budget", "--limit", "3", "--samples", "128",
           "--trials", "400", "--resamples", "20", "--n-jobs", "1", "-q"]
    a = subprocess.run([*run, "--relations", "independent", "--out", str(tmp_path / "a"),
                        "--problem-spec", str(tmp_path / "p.json")], capture_output=True,
                       text=True, timeout=600)
    assert a.returncode == 0, a.stderr
    b = subprocess.run([*run, "--from-problem-spec", str(tmp_path / "p.json"),
                        "--out", str(tmp_path / "b")], capture_output=True, text=True,
                       timeout=600)
    assert b.returncode == 0, b.stderr
    assert (tmp_path / "a" / "budget-independent.csv").read_text() == \
        (tmp_path / "b" / "budget-independent.csv").read_text()
    (tmp_path / "bad.json").write_text('{"names": ["dz_m"], "bounds": [[0, 1]]}')
    c = subprocess.run([*run, "--from-problem-spec", str(tmp_path / "bad.json"),
                        "--out", str(tmp_path / "c")], capture_output=True, text=True,
                       timeout=600)
    assert c.returncode == 2 and "Traceback" not in c.stderr
    assert not (tmp_path / "c").exists()
