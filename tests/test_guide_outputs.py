"""Every output a guide page (``docs/guide/*.md``) shows is what the program prints.

How a page shows a command and its output (the convention this test reads):

- A *command* is a ``.venv/bin/montecarlo ...`` line of an indented code block or of a
  fenced ``sh`` block (continuation lines ``\\`` joined, a trailing ``  # comment`` dropped).
  The commands of one code block form a *group*; other lines (``make install``) are not run.
- A *shown output* is a fenced block with a bare fence (three backticks, no language). The
  shown outputs between a group and the next command are the outputs of the group's last
  commands, in order: one block after ``run``, ``run``, ``compare`` is ``compare``'s; two
  blocks after ``simulate`` and ``fit`` are one each.
- ``<!-- not checked: REASON -->`` on the line before a bare fence exempts that block (an
  output that depends on the machine's state or on a previous run, not on the command).
- ``<!-- file: PATH -->`` on the line before a fenced block (of any language) says the block
  is the file PATH as the group's commands write it; it is compared with that file after all
  of the group's commands have run.

A block's command runs after the earlier commands of its group (``simulate`` before ``fit``),
in a directory laid out like the repository (``studies`` and ``tests/data`` linked,
``results/examples`` copied: nothing in the repository is written), shell globs expanded.
Its standard output is compared line by line with the block: a line ``...`` (indented or
not) stands for any number of printed lines, trailing whitespace is ignored, and lines that
name a run's time (``slow step: ...``) are dropped from both; nothing else is skipped, every
number must be printed as shown. Progress bars go to standard error, which is not compared.

Commands that take more than a few seconds (:data:`SLOW`) are in the slow test.
"""

import glob
import re
import shlex
import shutil
from functools import cache
from pathlib import Path

import pytest

from tests.forked_cli import montecarlo_cli

ROOT = Path(__file__).parent.parent
GUIDE = ROOT / "docs" / "guide"
PREFIX = ".venv/bin/montecarlo "
# a block is slow when its command, or a command run before it in its group, contains one of
# these: Monte Carlo studies, searches, the report's Monte Carlo and OpenCV on photographs
SLOW = (" run ", " compare ", " size ", " budget ", " nightly ", " --report ", " camera detect ",
        " diagnose camera ", " stabilization estimate ")
TIME_LINE = re.compile(r"slow step: ")
FENCE = re.compile(r"^```(\w*)\s*$")


def _command(line: str) -> str:
    return " ".join(line.strip().split("  #")[0].split())


def shown_outputs(page: Path, groups: list | None = None
                  ) -> list[tuple[tuple[str, ...], int, str, int, str | None]]:
    """``(group, index of the command in the group, shown block, line of the block, file)``
    for every shown output of ``page`` not marked ``not checked``; ``file`` is the PATH of a
    ``<!-- file: PATH -->`` block (then the index is the group's last command), else None.
    Every group of commands of the page, shown output or not, is appended to ``groups``."""
    lines = page.read_text().splitlines()
    found: list[tuple[tuple[str, ...], int, str, int, str | None]] = []
    groups = [] if groups is None else groups
    group: list[str] = []
    pending: list[tuple[str, int]] = []  # shown blocks after the current group
    files: list[tuple[str, int, str]] = []  # shown files after the current group

    def close_group() -> None:
        assert len(pending) <= len(group), (
            f"{page.name}: {len(pending)} shown outputs after {len(group)} command(s) "
            f"{group}: which command prints which?")
        first = len(group) - len(pending)
        for k, (block, at) in enumerate(pending):
            found.append((tuple(group), first + k, block, at, None))
        for block, at, path in files:
            assert group, f"{page.name}:{at}: a file shown before any command"
            found.append((tuple(group), len(group) - 1, block, at, path))
        pending.clear()
        files.clear()
        if group:
            groups.append(tuple(group))

    i = 0
    while i < len(lines):
        fence = FENCE.match(lines[i])
        if fence:
            end = next(j for j in range(i + 1, len(lines)) if lines[j].startswith("```"))
            body = lines[i + 1:end]
            if fence.group(1) == "sh":
                commands = [_command(c) for c in re.sub(r"\\\n\s*", " ", "\n".join(body))
                            .splitlines() if c.startswith(PREFIX)]
                if commands:
                    close_group()
                    group = commands
            elif lines[i - 1].startswith("<!-- file: "):
                path = lines[i - 1].removeprefix("<!-- file: ").removesuffix("-->").strip()
                files.append(("\n".join(body), i + 1, path))
            elif fence.group(1) == "" and not lines[i - 1].startswith("<!-- not checked:"):
                pending.append(("\n".join(body), i + 1))
            i = end + 1
        elif lines[i].startswith("    ") and (i == 0 or not lines[i - 1].strip()):
            end = i
            while end < len(lines) and (lines[end].startswith("    ") or not lines[end].strip()):
                end += 1
            block = re.sub(r"\\\n\s*", " ", "\n".join(lines[i:end]))
            commands = [_command(c) for c in block.splitlines() if c.startswith("    " + PREFIX)]
            if commands:
                close_group()
                group = commands
            i = end
        else:
            i += 1
    close_group()
    return found


def _cases(slow: bool) -> list:
    cases = []
    for page in sorted(GUIDE.glob("*.md")):
        for group, index, block, at, path in shown_outputs(page):
            is_slow = any(s in c + " " for c in group[:index + 1] for s in SLOW)
            if is_slow == slow:
                words = [w for w in group[index].split()[1:] if not w.startswith("-")]
                name = path or " ".join(words[:1] + [w for w in words[1:2] if w.isalpha()])
                cases.append(pytest.param(group, index, block, path, id=f"{page.name}:{at}:{name}"))
    return cases


def _workdir(base: Path) -> None:
    base.mkdir()
    (base / "studies").symlink_to(ROOT / "studies")
    (base / "tests").mkdir()
    (base / "tests" / "data").symlink_to(ROOT / "tests" / "data")
    shutil.copytree(ROOT / "results" / "examples", base / "results" / "examples")


_RUNS: dict[tuple[str, ...], tuple[Path, list]] = {}  # each group's directory and results


def run_in_group(group: tuple[str, ...], index: int, tmp_root: Path):
    """The result of ``group[index]``, run after the group's earlier commands (each run once
    per group, in one directory)."""
    if group not in _RUNS:
        _RUNS[group] = (tmp_root / f"group-{len(_RUNS) + 1}", [])
        _workdir(_RUNS[group][0])
    key, runs = _RUNS[group]
    while len(runs) <= index:
        command = group[len(runs)]
        args = []
        for arg in shlex.split(command)[1:]:
            args += sorted(glob.glob(arg, root_dir=key)) if glob.has_magic(arg) else [arg]
        done = montecarlo_cli(*args, cwd=key)
        assert done.returncode == 0, f"{command}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
        runs.append(done)
    return runs[index], key


def _lines(text: str) -> list[str]:
    return [line.rstrip() for line in text.strip("\n").splitlines()
            if not TIME_LINE.match(line)]


def matches(shown: str, printed: str) -> bool:
    """Whether ``printed`` is ``shown``, a ``...`` line standing for any number of lines."""
    want, got = _lines(shown), _lines(printed)

    @cache
    def match(i: int, j: int) -> bool:
        if i == len(want):
            return j == len(got)
        if want[i].strip() == "...":
            return any(match(i + 1, k) for k in range(j, len(got) + 1))
        return j < len(got) and want[i] == got[j] and match(i + 1, j + 1)

    return match(0, 0)


def test_matching_reads_the_dots_and_nothing_else():
    printed = "a 1\nb 2\nslow step: loading took 3.1 s\nc 3\n"
    assert matches("a 1\n...\nc 3", printed) and matches("a 1\n  ...\nc 3", printed)
    assert matches("a 1\nb 2  \nc 3", printed)
    assert matches("...\nc 3", printed) and matches("a 1\n...", printed)
    assert not matches("a 1\nb 2", printed)  # a missing line
    assert not matches("a 1\nb 2.0\nc 3", printed)  # a number as printed, no tolerance
    assert not matches("a 1\n...\nd 4", printed)


def test_every_page_with_outputs_is_read():
    """The convention finds the blocks the pages show (a page rewritten in another layout
    would otherwise silently drop out of the check)."""
    counted = {page.name: len(shown_outputs(page)) for page in GUIDE.glob("*.md")}
    assert all(counted[name] >= 1 for name in (
        "air-calibration.md", "calibrate-an-autocollimator.md", "camera-images.md",
        "diagnose-your-data.md", "gimbal-installation-angles.md", "rerun-table1-nightly.md",
        "scale-out-on-dask.md", "size-a-range.md")), counted
    assert sum(counted.values()) >= 15, counted


def _check(group, index, block, path, tmp_path_factory):
    done, where = run_in_group(group, index, tmp_path_factory.getbasetemp())
    if path is None:
        assert matches(block, done.stdout), (
            f"{group[index]} no longer prints what the page shows; it prints:\n{done.stdout}")
    else:
        written = (where / path).read_text()
        assert matches(block, written), f"{path} is no longer what the page shows:\n{written}"


CASE = ("group", "index", "block", "path")


@pytest.mark.parametrize(CASE, _cases(slow=False))
def test_the_page_shows_what_the_command_prints(group, index, block, path, tmp_path_factory):
    _check(group, index, block, path, tmp_path_factory)


@pytest.mark.slow
@pytest.mark.parametrize(CASE, _cases(slow=True))
def test_the_page_shows_what_the_slow_command_prints(group, index, block, path,
                                                      tmp_path_factory):
    _check(group, index, block, path, tmp_path_factory)


# The committed results of the guide's worked examples: each is what its command on the page
# writes to results/NAME/ (a command does not replace results/examples/NAME/, which holds its
# input or which it did not write), and for a diagnosis what it prints, in diagnose.txt.
REPORT = ("report.md", "diagnosis.json", "residuals.png", "gap.png")
COMMITTED = {
    "discrepancy_ground": ("diagnose-your-data.md", REPORT),
    "discrepancy_collimation": ("diagnose-your-data.md", REPORT),
    "sizing": ("size-a-range.md", ("answers.csv", "confirmation-common.csv",
                                   "confirmation-independent.csv", "corners-common.csv",
                                   "corners-independent.csv", "grid-common.csv",
                                   "grid-independent.csv", "report.md", "frontier.png")),
    "budget": ("size-a-range.md", ("budget-common.csv", "budget-independent.csv", "report.md",
                                   "budget.png")),
}


def _writing_command(name: str) -> tuple[tuple[str, ...], int]:
    """The group of the command that writes results/NAME/ and its index in the group."""
    groups: list[tuple[str, ...]] = []
    shown_outputs(GUIDE / COMMITTED[name][0], groups)
    [found] = [(group, k) for group in groups for k, command in enumerate(group)
               if re.search(rf" --(report|out) results/{name}( |$)", command)]
    return found


@pytest.mark.parametrize("name", ["discrepancy_ground", "discrepancy_collimation"])
def test_the_committed_diagnose_text_is_what_the_diagnosis_prints(name, tmp_path_factory):
    """``diagnose.txt`` against the same diagnosis without ``--report`` (the same text but its
    last line, which names the report)."""
    group, k = _writing_command(name)
    args = shlex.split(group[k])
    for option in ("--report", "--n-jobs"):  # each with its value
        at = args.index(option)
        del args[at:at + 2]
    done, _ = run_in_group((" ".join(args),), 0, tmp_path_factory.getbasetemp())
    committed = (ROOT / "results" / "examples" / name / "diagnose.txt").read_text()
    *text, last = _lines(committed)
    assert last.startswith(f"report written to results/{name}/")
    assert _lines(done.stdout) == text


@pytest.mark.slow
@pytest.mark.parametrize("name", COMMITTED)
def test_the_committed_result_is_what_its_command_writes(name, tmp_path_factory):
    group, k = _writing_command(name)
    done, where = run_in_group(group, k, tmp_path_factory.getbasetemp())
    committed = ROOT / "results" / "examples" / name
    if (committed / "diagnose.txt").exists():
        assert _lines(done.stdout) == _lines((committed / "diagnose.txt").read_text())
    for file in COMMITTED[name][1]:
        assert (where / "results" / name / file).read_bytes() == (committed / file).read_bytes(), (
            f"results/examples/{name}/{file} is not what `{group[k]}` writes now")
