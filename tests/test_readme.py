"""Every ``.venv/bin/montecarlo`` command printed in the README runs as printed (exit 0), in
the README's order, from a directory laid out like the repository."""

import json
import re
import shlex
import shutil
from pathlib import Path

import pytest

from tests.forked_cli import montecarlo_cli

ROOT = Path(__file__).parent.parent
PREFIX = ".venv/bin/montecarlo "


def readme_commands() -> list[str]:
    """The commands of the README's indented code blocks (continuation lines joined)."""
    text = re.sub(r"\\\n\s*", " ", (ROOT / "README.md").read_text())
    commands = []
    for line in text.splitlines():
        if line.startswith("    " + PREFIX):
            commands.append(line.strip().split("  #")[0].strip())
    return commands


def test_the_readme_shows_commands_of_every_kind():
    names = {shlex.split(c)[1] for c in readme_commands()}
    assert {"table1", "list", "validate", "run", "init", "schema", "plan", "compare", "report",
            "diagnose"} <= names


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    work = tmp_path_factory.mktemp("readme")
    (work / "studies").symlink_to(ROOT / "studies")
    shutil.copytree(ROOT / "results" / "examples", work / "results" / "examples")
    return work


@pytest.mark.parametrize("command", readme_commands())
def test_readme_command_runs_as_printed(workdir, command):
    args = shlex.split(command)[1:]
    done = montecarlo_cli(*args, cwd=workdir)
    assert done.returncode == 0, f"{command}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"


def test_the_python_examples_of_docs_api_run_and_print_what_they_show(workdir, monkeypatch,
                                                                        capsys):
    """The code blocks of docs/reference/python-api.md, run in order in one namespace; the printed
    table is the
    one the page shows."""
    text = (ROOT / "docs" / "reference" / "python-api.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    shown = re.search(r"prints .*?:\n\n```\n(.*?)```", text, re.S).group(1)
    monkeypatch.chdir(workdir)
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, "docs/reference/python-api.md", "exec"), namespace)
    out = capsys.readouterr().out
    assert shown.strip() in out
    assert "[1.14012739 1.31886844 1.51711446]" in out
    assert (workdir / "results" / "api-demo" / "report.md").exists()
    assert (workdir / "api_demo.png").exists()


def _printed(pattern: str, text: str) -> str:
    found = re.search(pattern, text, re.S)
    assert found, f"the README no longer prints {pattern!r}"
    return found.group(1)


def _same_at_printed_digits(printed: str, value: float) -> bool:
    """``value`` rounded to the significant digits of ``printed`` (e.g. "2e-152", "0.00788")."""
    printed = printed.replace("−", "-")
    mantissa = printed.lower().split("e")[0].lstrip("-").lstrip("0.")
    digits = max(len(mantissa.replace(".", "")), 1)
    return float(f"{value:.{digits - 1}e}") == float(printed)


def test_the_worked_example_numbers_are_what_diagnose_prints(workdir, capsys):
    """The README's worked example (a hidden radial distortion found, named and removed): every
    number it prints, read from the README, against the diagnosis of the shipped data set at
    the digits printed: the `diagnosis.json` its command wrote above (`--report out/`), or, if
    that test was not run, `diagnose ground --json` run here."""
    from montecarlo.cli import main
    readme = re.sub(r"\s+", " ", (ROOT / "README.md").read_text())
    example = readme[readme.index("### Worked example"):]
    example = example[:example.index("![residuals]")]
    written = workdir / "out" / "diagnosis.json"
    if written.exists():
        d = json.loads(written.read_text())
    else:
        code = main(["diagnose", "ground",
                     str(ROOT / "results/examples/discrepancy_ground/data.csv"), "--fov-deg", "90",
                     "90", "--pixels", "512", "512", "--pixel-sigma-px", "0.3",
                     "--survey-sigma-m", "0.01", "--json", "-q"])
        assert code == 0
        d = json.loads(capsys.readouterr().out)
    before, after = d["gap"]["before"], d["gap"]["after"]
    assert _same_at_printed_digits(_printed(r"χ²_red = ([\d.]+) on \d+ degrees", example),
                                   before["chi2_red"])
    assert int(_printed(r"χ²_red = [\d.]+ on (\d+) degrees", example)) == before["dof"]
    # the candidates that apply to one session (session_shift is listed as unavailable)
    applicable = [c for c in d["candidates"] if c["status"] != "unavailable"]
    assert int(_printed(r"Among (\d+) candidate effects", example)) == len(applicable)
    [named] = d["named_effects"]
    assert named["name"] == _printed(r"`(\w+)` is named", example)
    assert _same_at_printed_digits(_printed(r"Holm-corrected p = ([\de.-]+)\)", example),
                                   named["p_value"])
    assert _same_at_printed_digits(_printed(r"at k1 = (−?[\d.]+) ±", example),
                                   named["parameters"]["k1"])
    assert _same_at_printed_digits(_printed(r"at k1 = −?[\d.]+ ± (\d+(?:\.\d+)?)", example),
                                   named["stderr"]["k1"])
    status = {c["name"]: c for c in d["candidates"]}
    assert status["detector_rotation"]["status"] == "absorbed"
    assert status["detector_rotation"]["absorbed_by"] == {"rho": ["gamma"]}  # "by the roll"
    assert status["refraction"]["status"] == "undetectable"
    assert _same_at_printed_digits(_printed(r"fits at χ²_red = ([\d.]+)", example),
                                   after["chi2_red"])
    assert _same_at_printed_digits(_printed(r"fits at χ²_red = [\d.]+ \(p = ([\d.]+)\)", example),
                                   after["p_value"])
    lo, hi = d["chi2_red_band_99"]["after"]
    assert lo < after["chi2_red"] < hi  # "inside its 99 % band"
    truth = json.loads((ROOT / "results/examples/discrepancy_ground/truth.json").read_text())
    assert "-0.008" in json.dumps(truth) and "k1 = −0.008" in example
