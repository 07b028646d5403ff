"""Result directories never take what is not theirs: the one rule every directory writer
follows (:class:`montecarlo.io.files.OutputDir`), checked through the command line.

A directory is replaced only if it is absent, empty or wholly an earlier result of the same
command (every entry listed, with its size, in its ``provenance.json``). The current directory
and its parents, the results root, a directory holding the study file and a symbolic link are
refused before any work, and a lock file beside the output directory keeps a second writer out.
Each refusal is one line, exit code 2, and leaves every file as it was. The refusals that
need a single command (a study named '.', `--out .`, `--out` a symbolic link, ...) are cases
of ``tests/test_bad_inputs.py``; the ones here need a result written first, or a lock held.
"""

import hashlib
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from montecarlo.errors import InputError
from montecarlo.io.files import PROVENANCE, OutputDir, OutputLock

ENV = {**os.environ, "MPLBACKEND": "Agg", "PYTHONDONTWRITEBYTECODE": "1",
       "PYTHONPATH": str(Path(__file__).resolve().parents[1])}

STUDY = """
[study]
name = "{name}"
system = "ground"
trials = 200
seed = 1

[sensor]
fov_deg = [90.0, 90.0]
pixels = [512, 512]

[mounting]
psi_deg = 30.0
theta_deg = 0.0
gamma_deg = 0.0

[geometry]
L_m = 100.0
H_m = 2.0

[errors]
pixel_px = {{ dist = "normal", sigma = 0.5 }}
pixel_relation = "common"
"""


def study_file(folder: Path, name: str = "small", file: str | None = None) -> Path:
    path = folder / (file or f"{name}.toml")
    path.write_text(textwrap.dedent(STUDY.format(name=name)))
    return path


def cli(*args, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "montecarlo", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=120, env=ENV,
                          stdin=subprocess.DEVNULL)


def refused(proc: subprocess.CompletedProcess, *words: str) -> None:
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr + proc.stdout
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    for word in words:
        assert word in lines[0], lines[0]


def tree(root: Path) -> dict[str, str]:
    """Every path under ``root`` (hidden ones too) with its content hash (or 'dir'/'link')."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            rel = p.relative_to(root).as_posix()
            out[rel] = ("link:" + os.readlink(p)) if p.is_symlink() else "dir" if p.is_dir() \
                else hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def test_the_directory_holding_the_study_file_is_refused(tmp_path):
    """An earlier result that holds the study file itself is not replaced (that would delete
    the study); nor is any directory holding an input."""
    out = tmp_path / "out"
    out.mkdir()
    study = study_file(out)
    (out / PROVENANCE).write_text(json.dumps({"kind": "run", "study": "small", "files": {}}))
    with pytest.raises(InputError, match="holds the input"):
        OutputDir(out, "run", {"study": "small"}, inputs=(study,)).check()
    with pytest.raises(InputError, match="holds the input"):
        OutputDir(tmp_path, "run", inputs=(study,)).check()


@pytest.mark.slow
def test_a_rerun_keeps_a_file_the_user_added_to_an_earlier_result(tmp_path):
    """A rerun into an earlier result replaced the whole directory, deleting a file the user
    had added; it is now refused while the file is there (`report` likewise for a file added
    to plots/), and a result file the user edited (its size changed) is the user's too. Once
    the user's files are moved out, the result is replaced again."""
    study = study_file(tmp_path)
    out = tmp_path / "out"
    assert cli("run", study, "--out", out, "--quiet", cwd=tmp_path).returncode == 0
    written = json.loads((out / PROVENANCE).read_text())["files"]
    assert {"summary.csv", "summary.parquet", "report.md", "plots"} <= set(written)
    assert written["summary.csv"] == (out / "summary.csv").stat().st_size

    (out / "my_notes.txt").write_text("analysis I wrote by hand\n")
    (out / "plots" / "my_sketch.png").write_bytes(b"not ours")
    before = tree(tmp_path)
    refused(cli("run", study, "--out", out, "--quiet", cwd=tmp_path), "2 file(s)",
            "my_notes.txt", "did not write")
    refused(cli("report", out, cwd=tmp_path), "plots/my_sketch.png")
    assert tree(tmp_path) == before

    match = {"study": "small"}
    (out / "my_notes.txt").unlink()
    (out / "plots" / "my_sketch.png").unlink()
    with (out / "report.md").open("a") as f:
        f.write("my conclusions\n")
    with pytest.raises(InputError, match=r"report\.md"):
        OutputDir(out, "run", match).check()
    (out / "report.md").unlink()  # a result file the user deleted is no one's loss
    with OutputDir(out, "run", match) as staging:
        (staging / PROVENANCE).write_text(json.dumps({"kind": "run", **match}))
    assert sorted(p.name for p in out.iterdir()) == [PROVENANCE]


def test_an_earlier_result_without_a_list_of_its_files_is_not_replaced(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / PROVENANCE).write_text(json.dumps({"kind": "run", "study": "small"}))
    (out / "summary.csv").write_text("x\n")
    with pytest.raises(InputError, match="without the list of its files"):
        OutputDir(out, "run", {"study": "small"}).check()


def test_schema_out_does_not_overwrite_a_users_file_without_force(tmp_path):
    mine = tmp_path / "schema.json"
    mine.write_text("my own schema\n")
    refused(cli("schema", "--out", mine, cwd=tmp_path), "schema.json", "--force")
    assert mine.read_text() == "my own schema\n"
    done = cli("schema", "--out", mine, "--force", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert json.loads(mine.read_text())["type"] == "object"


def test_a_second_writer_of_the_same_out_is_refused_while_the_first_holds_the_lock(tmp_path):
    """Two runs into one --out both said 'written' and the later silently replaced the other.
    While one writer holds .out.lock, another is refused in one line; after it, the lock file
    is gone and a run succeeds."""
    study = study_file(tmp_path)
    out = tmp_path / "out"
    with OutputLock(out):
        assert (tmp_path / ".out.lock").read_text().strip() == str(os.getpid())
        refused(cli("run", study, "--out", out, "--quiet", cwd=tmp_path), "another process",
                f"pid {os.getpid()}")
        assert not out.exists()
    assert not (tmp_path / ".out.lock").exists()
    with OutputDir(out, "run") as staging:
        assert (tmp_path / ".out.lock").exists()
        with pytest.raises(InputError, match="another process"), OutputDir(out, "run"):
            pass
        (staging / PROVENANCE).write_text(json.dumps({"kind": "run"}))
    assert not (tmp_path / ".out.lock").exists() and (out / PROVENANCE).exists()


def test_a_lock_left_by_a_killed_writer_is_taken_over(tmp_path):
    """flock is released by the kernel when its holder dies; the file it leaves is reused."""
    (tmp_path / ".out.lock").write_text("999999\n")
    with OutputDir(tmp_path / "out", "run") as staging:
        (staging / PROVENANCE).write_text(json.dumps({"kind": "run"}))
    assert not (tmp_path / ".out.lock").exists()
    assert json.loads((tmp_path / "out" / PROVENANCE).read_text())["files"] == {}
