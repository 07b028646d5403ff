"""The diagnosis rows of ``montecarlo bench``: ``diagnose camera`` on Zhang's 1998 data set.

Zhang's five views of 256 corners (2,560 image coordinates, ``tests/data/camera``) at stated
pixel sigmas from 0.15 to 0.3 px and with ``auto``; the goal is every diagnosis within
:data:`GOAL_SECONDS`. Each is the whole command as a user runs it (``montecarlo diagnose
camera ... --json``, a fresh process: loading the libraries, reading, the diagnosis, the
report), once: its wall time and the CPU time of the process (user + system, every thread).
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

GOAL_SECONDS = 10.0
"""Every diagnosis of a real camera set within this (wall, quiet machine)."""

ZHANG = Path(__file__).resolve().parents[2] / "tests" / "data" / "camera"
QUICK_SIGMAS = ("0.25",)
FULL_SIGMAS = ("0.15", "0.2", "0.25", "0.3", "auto")


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def camera_diagnosis(sigma: str) -> dict[str, Any]:
    """One ``diagnose camera`` of Zhang's data at ``--pixel-sigma-px sigma``: wall and CPU
    seconds and the effects named."""
    command = [sys.executable, "-m", "montecarlo", "diagnose", "camera",
               str(ZHANG / "zhang_model.csv"), str(ZHANG / "zhang_views.csv"),
               "--pixel-sigma-px", sigma, "--json"]
    cpu, wall = _children_cpu(), time.perf_counter()
    out = subprocess.run(command, capture_output=True, text=True, check=True)
    wall, cpu = time.perf_counter() - wall, _children_cpu() - cpu
    named = [e["name"] for e in json.loads(out.stdout)["named_effects"]]
    return {"pixel_sigma_px": sigma, "wall_s": wall, "cpu_s": cpu, "named": named}


def camera_diagnoses(quick: bool) -> list[dict[str, Any]]:
    """The rows: at 0.25 px (``quick``), or at every sigma of :data:`FULL_SIGMAS`; none if the
    data set is not beside the package (an installed copy without the repository's tests)."""
    if not (ZHANG / "zhang_views.csv").is_file():
        return []
    return [camera_diagnosis(s) for s in (QUICK_SIGMAS if quick else FULL_SIGMAS)]


def format_diagnoses(rows: list[dict[str, Any]]) -> list[str]:
    if not rows:
        return ["diagnose camera on Zhang's data: not measured (tests/data/camera not found)"]
    lines = [f"diagnose camera on Zhang's 1998 data (2,560 coordinates), the whole command, "
             f"once each (goal: {GOAL_SECONDS:g} s):"]
    for r in rows:
        lines.append(f"  --pixel-sigma-px {r['pixel_sigma_px']:<5} {r['wall_s']:>7.1f} s wall "
                     f"{r['cpu_s']:>7.1f} s CPU   named: {', '.join(r['named']) or 'nothing'}")
    return lines
