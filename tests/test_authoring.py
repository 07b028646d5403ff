"""Writing study files: ``validate``, ``schema``, ``init`` and ``list``, run as users run them."""

import json
import tomllib
from pathlib import Path

import jsonschema
import pytest

import montecarlo
from montecarlo.engine.runner import available_cores
from montecarlo.systems import REGISTRY
from tests.forked_cli import montecarlo_cli

ROOT = Path(__file__).parent.parent
STUDIES = sorted((ROOT / "studies").glob("*.toml"))


def cli(*args, cwd=None):
    return montecarlo_cli(*args, cwd=cwd)


def test_validate_states_grid_trials_time_and_spec():
    out = cli("validate", ROOT / "studies" / "table1.toml", "--n-jobs", "1")
    assert out.returncode == 0, out.stderr
    assert "valid ground study 'table1'" in out.stdout
    assert "grid points: 12" in out.stdout
    assert "64, 20,000 per point, 120,384 in all; 6 enumerate their worst-case corners" \
        in out.stdout
    assert "on 1 core" in out.stdout and "spec: max of table1_angle <= 3 mrad" in out.stdout


def test_validate_plans_the_cores_the_run_takes():
    """A small study stays in the calling process however many workers are asked for, as the
    run records; the layout study (about 36 s of single-core work) goes to the workers."""
    small = ROOT / "studies" / "range_sizing.toml"
    info = json.loads(cli("validate", small, "--trials", "50", "--n-jobs", "2",
                          "--json").stdout)
    ran = montecarlo.run(small, trials=50, n_jobs=2)
    assert info["cores"] == 1 and ran._result.workers == 0
    big = json.loads(cli("validate", ROOT / "studies" / "collimation_layout.toml", "--n-jobs",
                         "2", "--json").stdout)
    assert big["cores"] == min(2, available_cores())


def test_validate_json_agrees_with_the_loaded_study():
    out = cli("validate", ROOT / "studies" / "range_sizing.toml", "--trials", "1000", "--json")
    info = json.loads(out.stdout)
    study = montecarlo.load_study(ROOT / "studies" / "range_sizing.toml", trials=1000)
    assert info["grid_points"] == len(study.points) == 60
    assert info["total_trials"] == 60_000 and info["trials_per_point"] == [1000]
    assert info["spec"]["statistic"] == study.spec.statistic


def test_validate_refuses_a_bad_study_in_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text((ROOT / "studies" / "table1.toml").read_text().replace(
        "pixels = [512, 512]", "pixels = [0, 512]"))
    out = cli("validate", bad)
    assert out.returncode == 2 and out.stderr.count("\n") == 1
    assert "bad.toml" in out.stderr and "sensor.pixels" in out.stderr


@pytest.mark.parametrize("study", STUDIES, ids=lambda p: p.name)
def test_every_shipped_study_meets_its_systems_schema(study):
    raw = tomllib.loads(study.read_text())
    out = cli("schema", raw["study"]["system"])
    jsonschema.validate(raw, json.loads(out.stdout))


def test_the_schema_rejects_what_the_loader_rejects():
    schema = json.loads(cli("schema", "ground").stdout)
    raw = tomllib.loads((ROOT / "studies" / "table1.toml").read_text())
    raw["errors"]["dx_m"] = {"dist": "uniform", "sigma": 0.1}  # uniform has no sigma
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(raw, schema)
    common = json.loads(cli("schema").stdout)
    assert common["$defs"]["StudyHeader"]["properties"]["system"]["enum"] == list(REGISTRY)


@pytest.mark.parametrize("system", list(REGISTRY))
def test_init_writes_a_study_that_loads_and_runs(tmp_path, system):
    path = tmp_path / f"my {system}.toml"
    out = cli("init", system, path)
    assert out.returncode == 0, out.stderr
    text = path.read_text()
    assert text.startswith("# ") and f'system = "{system}"' in text
    study = montecarlo.load_study(path, trials=2)
    assert study.header.name == f"my_{system}"
    result = montecarlo.run(study, trials=2)
    assert (result.summary["trials"] >= 2).all()


def test_init_never_replaces_a_file_unless_forced(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text("my notes\n")
    out = cli("init", "ground", path)
    assert out.returncode == 2 and "exists" in out.stderr and "--force" in out.stderr
    assert path.read_text() == "my notes\n"
    assert cli("init", "ground", path, "--force").returncode == 0
    assert 'system = "ground"' in path.read_text()
    assert cli("init", "nosuch").returncode == 2


def test_list_names_every_system_shape_and_metric_with_units():
    data = json.loads(cli("list", "--json").stdout)
    assert [s["name"] for s in data["systems"]] == list(REGISTRY)
    shapes = {d["dist"] for d in data["distributions"]}
    assert shapes == {"fixed", "uniform", "normal", "corners", "triangular", "arcsine",
                      "truncnormal", "lognormal"}
    ground = data["systems"][0]
    assert {"name": "rotation_angle", "label": "true rotation angle φ of D", "unit": "mrad",
            "of": "value"} in ground["metrics"]
    assert all(m["unit"] for s in data["systems"] for m in s["metrics"])
    text = cli("list", "air").stdout
    assert text.startswith("air: ") and "params.gyro_drift_deg_per_h [deg/h]" in text
