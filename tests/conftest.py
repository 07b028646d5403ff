"""The ``figures`` fixture of the acceptance suites, and the file ``make acceptance`` writes.

With ``ACCEPTANCE_DIR`` set (``make acceptance`` sets it), the figures the tests of one test file
recorded, the tests' outcomes and the run's provenance go to ``$ACCEPTANCE_DIR/<suite>.json``,
``<suite>`` being the file's name without ``test_``. Without it nothing is written.
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import subprocess
import time
from pathlib import Path

import pytest

from tests.acceptance import Figures

ROOT = Path(__file__).parent.parent
_SUITES: dict[str, Figures] = {}
_OUTCOMES: dict[str, dict[str, str]] = {}
_STARTED = time.monotonic()


def suite_name(path: str | Path) -> str:
    """``tests/test_sizing.py`` -> ``sizing``."""
    return Path(path).stem.removeprefix("test_")


@pytest.fixture
def figures(request) -> Figures:
    """Where a test records its figures (``figures.record(name, value, low, high)``)."""
    suite = _SUITES.setdefault(suite_name(request.node.path), Figures())
    suite.test = request.node.nodeid
    return suite


def pytest_runtest_logreport(report):
    if report.when == "call" or report.outcome != "passed":
        outcomes = _OUTCOMES.setdefault(suite_name(report.fspath), {})
        if outcomes.get(report.nodeid) != "failed":
            # a strict xfail that failed as expected is a finding kept, not a skip
            xfailed = report.skipped and hasattr(report, "wasxfail")
            outcomes[report.nodeid] = "xfailed" if xfailed else report.outcome


def _git(*args: str) -> str:
    try:
        done = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True)
    except OSError:  # no git: the record says so by an empty commit
        return ""
    return done.stdout.strip()


_COMMIT = _git("rev-parse", "HEAD")  # the commit the suite started on
# tracked files that differ from the commit, the records of earlier suites left out
_MODIFIED = bool(_git("status", "--porcelain", "--untracked-files=no", "--", ".",
                      ":(exclude)results/acceptance"))


def pytest_sessionfinish(session, exitstatus):
    folder = os.environ.get("ACCEPTANCE_DIR")
    if not folder or not _OUTCOMES:
        return
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    took = time.monotonic() - _STARTED
    for suite, outcomes in _OUTCOMES.items():
        record = {
            "suite": suite,
            "command": os.environ.get("ACCEPTANCE_COMMAND", ""),
            "commit": _COMMIT,
            "tree_modified": _MODIFIED,
            "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
            "machine": {"host": platform.node(), "platform": platform.platform(),
                        "processor": platform.machine(), "cpus": os.cpu_count(),
                        "python": platform.python_version()},
            "run_time_s": round(took, 1),
            "interrupted": exitstatus == pytest.ExitCode.INTERRUPTED,
            "passed": (exitstatus != pytest.ExitCode.INTERRUPTED
                       and all(v in ("passed", "xfailed") for v in outcomes.values())),
            "tests": dict(sorted(outcomes.items())),
            "figures": dict(sorted(_SUITES.get(suite, Figures()).items.items())),
        }
        path = out / f"{suite}.json"
        path.write_text(json.dumps(record, indent=1, ensure_ascii=False) + "\n")
