"""Print the tables of docs/validation/acceptance.md's "Recorded runs" from results/acceptance/.

``.venv/bin/python -m tests.acceptance_tables`` prints the run table (one row per suite of the
Makefile's ``SUITES``, "not run" where no record exists) and one figure table per recorded suite,
each number linked to its record, in the form ``tests/test_docs_figures.py`` checks. A share
(a figure whose name says within, coverage, named, flagged, clean or misfit, or whose bounds lie
in [0, 1] as a share's do) is printed as a percentage.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RECORDS = ROOT / "results" / "acceptance"
LINK = "../../results/acceptance"
SHARE_WORDS = ("within", "coverage", "named", "flagged", "clean", "misfit", "wrongly", "clustered")


def suites() -> list[str]:
    """The suites of the Makefile's SUITES, in its order."""
    text = (ROOT / "Makefile").read_text(encoding="utf-8")
    block = re.search(r"^SUITES \?=((?:.*\\\n)*.*)$", text, re.M)
    assert block, "no SUITES in the Makefile"
    return block.group(1).replace("\\\n", " ").split()


def _is_share(name: str) -> bool:
    return any(w in name.rsplit(".", 1)[-1] for w in SHARE_WORDS)


def _number(value: float | None, share: bool) -> str:
    if value is None:
        return "–"
    return f"{100 * value:.1f} %" if share else f"{value:.3f}"


def tables() -> str:
    """The run table and the figure tables, as markdown."""
    rows = ["| suite | commit | date (UTC) | run time | tests | passed |",
            "|---|---|---|---|---|---|"]
    figures = []
    for suite in suites():
        path = RECORDS / f"{suite}.json"
        if not path.exists():
            rows.append(f"| `{suite}` | not run | | | | |")
            continue
        r = json.loads(path.read_text(encoding="utf-8"))
        tests = r.get("tests", {})
        done = sum(v == "passed" for v in tests.values())
        rows.append(
            f"| [`{suite}`]({LINK}/{suite}.json) | `{r['commit'][:10]}`"
            f"{' (tree modified)' if r.get('tree_modified') else ''} | "
            f"{r['date'][:16].replace('T', ' ')} | {r['run_time_s'] / 60:.1f} min | "
            f"{done}/{len(tests)} | {'yes' if r.get('passed') else 'no'} |")
        if not r.get("figures"):
            continue
        figures += ["", f"### `{suite}`", "", "| figure | value | low | high | holds |",
                    "|---|---|---|---|---|"]
        for name, f in r["figures"].items():
            share = _is_share(name)
            figures.append(
                f"| `{name}` | [{_number(f['value'], share)}]({LINK}/{suite}.json#{name}) | "
                f"{_number(f['low'], share)} | {_number(f['high'], share)} | "
                f"{'yes' if f['holds'] else 'no'} |")
    return "\n".join(rows + figures) + "\n"


if __name__ == "__main__":
    print(tables(), end="")
