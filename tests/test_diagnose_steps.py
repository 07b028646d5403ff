"""The slow-step notes of ``montecarlo diagnose``: named with their time and why, only when slow."""

from __future__ import annotations

import subprocess
import sys

from montecarlo.cli import steps as timing


def test_a_slow_step_is_named_with_why(monkeypatch):
    monkeypatch.setattr(timing, "SLOW_STEP", 0.0)
    steps = timing.Steps()
    with steps("the diagnosis", "nonlinear fits"):
        pass
    with steps("loading"):
        pass
    notes = steps.notes()
    assert len(notes) == 2
    assert notes[0].startswith("slow step: the diagnosis took ")
    assert notes[0].endswith(" s (nonlinear fits)")
    assert notes[1].endswith(" s")


def test_a_quick_step_is_not_named(monkeypatch):
    monkeypatch.setattr(timing, "SLOW_STEP", float("inf"))
    steps = timing.Steps()
    with steps("loading", "imports"):
        pass
    assert steps.notes() == []
    assert steps.spent[0][0] == "loading" and steps.spent[0][1] >= 0.0


def test_json_output_stays_parsable_with_notes(tmp_path):
    """With --json the notes go to stderr, so stdout is the JSON alone."""
    import json

    data = "results/examples/discrepancy_collimation/data.csv"
    code = ("import sys; from montecarlo.cli import steps; steps.SLOW_STEP = 0.0; "
            "from montecarlo.cli import main; sys.exit(main(sys.argv[1:]))")
    out = subprocess.run([sys.executable, "-c", code, "diagnose", "collimation", data,
                          "--readings", "absolute", "--angle-sigma-arcsec", "2.828", "--json"],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    json.loads(out.stdout)
    assert "slow step: the diagnosis took" in out.stderr


def test_loaded_libraries_frozen_during_the_command_only(capsys):
    """The loading step freezes what it loaded out of the garbage collector's full
    collections; ``main`` unfreezes when the command ends, so an in-process caller's later
    garbage is collected as usual."""
    import gc

    from montecarlo.cli import main

    frozen = []
    with timing.Steps().loading():
        pass
    frozen.append(gc.get_freeze_count())
    gc.unfreeze()
    assert main(["diagnose", "collimation", "results/examples/discrepancy_collimation/data.csv",
                 "--readings", "absolute", "--angle-sigma-arcsec", "2.828", "--json"]) == 0
    frozen.append(gc.get_freeze_count())
    assert frozen[0] > 0 and frozen[1] == 0
