"""Write docs/reference/cli.md from the command line's own parser (every command, its usage and
each argument's help): ``.venv/bin/python -m tests.cli_reference > docs/reference/cli.md``.
``tests/test_docs_figures.py`` fails when the page differs from what this prints."""

from __future__ import annotations

import argparse
import os
from collections.abc import Iterator

HEADER = """# Command line

Every command of `montecarlo`, its usage and the help of each argument, as the parser states
them (`montecarlo COMMAND --help` prints the same). The page is generated:
`.venv/bin/python -m tests.cli_reference > docs/reference/cli.md`.

Common to every command: `-q` hides progress bars, `-v` says more; a bad input (file, field,
value or flag) is one line naming it, with exit code 2, and nothing written; a command that
finds a regression or a failed check exits 1. A command that writes a directory writes it only if
it is absent, empty or an earlier result of the same command, and a file only if absent unless
`--force` (README, "Your files are safe").
"""


def _subparsers(parser: argparse.ArgumentParser
                ) -> Iterator[tuple[str, str, argparse.ArgumentParser]]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {c.dest: c.help or "" for c in action._choices_actions}
            for name, sub in action.choices.items():
                yield name, helps.get(name, ""), sub


def _section(full: str, help_: str, sub: argparse.ArgumentParser) -> list[str]:
    out = [f"## `{full}`\n", (help_[:1].upper() + help_[1:] + ".\n") if help_ else ""]
    nested = list(_subparsers(sub))
    if nested:
        out.append("Subcommands: " + ", ".join(f"`{n}`" for n, _, _ in nested) + ".\n")
        for name, h, s in nested:
            out += _section(f"{full} {name}", h, s)
        return out
    out.append("```\n" + sub.format_usage().replace("usage: ", "").strip() + "\n```\n")
    rows = []
    for a in sub._actions:
        if isinstance(a, argparse._HelpAction) or a.dest in ("quiet", "verbose"):
            continue
        flag = ", ".join(a.option_strings) if a.option_strings else a.dest
        text = (a.help or "").replace("|", "\\|").replace("\n", " ")
        rows.append(f"| `{flag}` | {text % {'default': a.default} if '%(' in text else text} |")
    if rows:
        out.append("| argument | meaning |\n|---|---|\n" + "\n".join(rows) + "\n")
    return out


def page() -> str:
    """The text of docs/reference/cli.md."""
    os.environ["COLUMNS"] = "100"
    from montecarlo.cli import build_parser

    out = [HEADER]
    for name, help_, sub in _subparsers(build_parser()):
        out += _section(f"montecarlo {name}", help_, sub)
    return "\n".join(s for s in out if s)


if __name__ == "__main__":
    print(page(), end="")
