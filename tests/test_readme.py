"""Every ``.venv/bin/montecarlo`` command printed in the README runs as printed (exit 0), in
the README's order, from a directory laid out like the repository."""

import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

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
    done = subprocess.run([sys.executable, "-m", "montecarlo", *args], cwd=workdir,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"{command}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"


def test_the_python_examples_of_docs_api_run_and_print_what_they_show(workdir, monkeypatch,
                                                                        capsys):
    """The code blocks of docs/api.md, run in order in one namespace; the printed table is the
    one the page shows."""
    text = (ROOT / "docs" / "api.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    shown = re.search(r"prints .*?:\n\n```\n(.*?)```", text, re.S).group(1)
    monkeypatch.chdir(workdir)
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, "docs/api.md", "exec"), namespace)
    out = capsys.readouterr().out
    assert shown.strip() in out
    assert "[1.14012739 1.31886844 1.51711446]" in out
    assert (workdir / "results" / "api-demo" / "report.md").exists()
    assert (workdir / "api_demo.png").exists()
