"""Commands that help write study files: ``validate``, ``schema``, ``init``, ``list``."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path
from typing import Any

from montecarlo.cli.common import (
    add_json_option,
    add_max_points_option,
    add_n_jobs_option,
    check_json_option,
    emit_json,
    positive_int,
    write_text,
)
from montecarlo.errors import InputError


def _cmd_validate(args: argparse.Namespace) -> int:
    from montecarlo.engine.runner import (
        RunOptions,
        checked_options,
        estimated_seconds,
        plan_text,
        planned_workers,
        uses_reference,
    )
    from montecarlo.systems import load_study

    check_json_option(args)
    study = load_study(args.study, trials=args.trials, max_points=args.max_points)
    options = checked_options(study, RunOptions(n_jobs=args.n_jobs))
    reference = uses_reference(study, options)
    points = list(range(len(study.points)))
    seconds = estimated_seconds(study, points, reference)
    workers = planned_workers(study, points, options, reference)
    cores = max(workers or 1, 1)
    trials = [p.trials for p in study.points]
    h = study.header
    info: dict[str, Any] = {
        "study": h.name, "file": str(args.study), "system": h.system, "valid": True,
        "grid_points": len(study.points),
        "sweep": [{"mode": mode, "keys": list(keys)} for mode, keys in study.sweep_groups],
        "trials_per_point": sorted(set(trials)), "total_trials": sum(trials),
        "enumerated_points": sum(not p.sampled for p in study.points),
        "estimated_seconds": seconds / cores, "cores": cores,
        "kernel": "reference" if reference else "fast",
        "metrics": list(dict.fromkeys(m.name for _, m in study.metrics)),
        "spec": None if study.spec is None else study.spec.model_dump(),
    }
    if emit_json(args, info):
        return 0
    sweep = "; ".join(f"{mode}: {', '.join(keys)}" for mode, keys in study.sweep_groups)
    print(f"{args.study}: valid {h.system} study '{h.name}'")
    print(f"  grid points: {len(study.points)}" + (f" ({sweep})" if sweep else ""))
    each = ", ".join(f"{t:,}" for t in info["trials_per_point"])
    corners = f"; {info['enumerated_points']} enumerate their worst-case corners" \
        if info["enumerated_points"] else ""
    print(f"  trials: {each} per point, {sum(trials):,} in all{corners}")
    print(f"  run time: {plan_text(seconds, workers)} ({info['kernel']} path)")
    if study.spec is not None:
        s = study.spec
        print(f"  spec: {s.statistic} of {s.metric}{f' ({s.variant})' if s.variant else ''} "
              f"<= {s.limit:g} {study.metric(s.metric).unit}")
    return 0


def _cmd_schema(args: argparse.Namespace) -> int:
    from montecarlo.systems.catalog import study_schema

    text = json.dumps(study_schema(args.system), indent=2, default=str) + "\n"
    if args.out:
        out = Path(args.out)
        if (out.exists() or out.is_symlink()) and not args.force:
            raise InputError(f"{out}: exists; choose another name or add --force to replace it")
        write_text(out, text)
        print(f"wrote {args.out}")
    else:
        print(text, end="")
    return 0


def _cmd_init(args: argparse.Namespace) -> int:
    from montecarlo.systems.catalog import starter_study

    if args.out is None:
        print(starter_study(args.system, args.name), end="")
        return 0
    out = Path(args.out)
    if out.exists() and not args.force:
        raise InputError(f"{out}: exists; choose another name or add --force to replace it")
    name = args.name or re.sub(r"[^A-Za-z0-9_.-]", "_", out.stem)
    write_text(out, starter_study(args.system, name, str(out)))
    print(f"wrote {out}: a {args.system} study; check it with `montecarlo validate {out}`")
    return 0


def _cmd_list(args: argparse.Namespace) -> int:
    from montecarlo.systems.catalog import (
        DESCRIPTIONS,
        distributions,
        inputs_of,
        metrics_of,
        system_names,
    )

    check_json_option(args)
    systems = [args.system] if args.system else system_names()
    data = {"systems": [{"name": s, "description": DESCRIPTIONS[s], "inputs": inputs_of(s),
                         "metrics": metrics_of(s)} for s in systems],
            "distributions": distributions()}
    if emit_json(args, data):
        return 0
    for s in data["systems"]:
        print(f"{s['name']}: {s['description']}")
        print("  inputs:")
        for i in s["inputs"]:
            unit = f" [{i['unit']}]" if i["unit"] else ""
            extra = i.get("shape") or (f"one of {', '.join(i['choices'])}" if i["choices"] else
                                       f"default {i['default']}")
            print(f"    {i['key']}{unit}: {extra}")
        print("  metrics:")
        for m in s["metrics"]:
            print(f"    {m['name']} [{m['unit']}]: {m['label']}"
                  + (" (percentiles of the magnitude)" if m["of"] == "magnitude" else ""))
    print("error-source shapes (a 'source' above; a plain number is fixed):")
    for d in data["distributions"]:
        params = ", ".join(f"{k}" + ("" if v is None else f" = {v:g}")
                           for k, v in d["parameters"].items())
        print(f"  {{ dist = \"{d['dist']}\", {params} }}: {d['meaning']}")
    return 0


def _system_name(value: str) -> str:
    from montecarlo.systems import REGISTRY

    if value not in REGISTRY:
        raise argparse.ArgumentTypeError(f"unknown system (choose from {', '.join(REGISTRY)})")
    return value


def add_commands(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("validate", help="check a study file; say its grid, trials and run time")
    p.add_argument("study", help="study definition (TOML)")
    p.add_argument("--trials", type=positive_int, help="as `run --trials` would override")
    add_n_jobs_option(p)
    add_max_points_option(p)
    add_json_option(p, "the checked study")
    p.set_defaults(func=_cmd_validate)

    p = sub.add_parser("schema", help="JSON schema of a study file (for editors and checks)")
    p.add_argument("system", nargs="?", type=_system_name,
                   help="the system's full schema (default: the common sections)")
    p.add_argument("--out", help="write it to this file instead of printing it")
    p.add_argument("--force", action="store_true", help="replace OUT if it exists")
    p.set_defaults(func=_cmd_schema)

    p = sub.add_parser("init", help="write a commented starter study for a system")
    p.add_argument("system", type=_system_name, help="ground, air, collimation, ...")
    p.add_argument("out", nargs="?", help="file to write (default: print it)")
    p.add_argument("--name", help="study name (default: the file name)")
    p.add_argument("--force", action="store_true", help="replace OUT if it exists")
    p.set_defaults(func=_cmd_init)

    p = sub.add_parser("list", help="systems, their inputs and metrics with units, and the "
                       "error-source shapes")
    p.add_argument("system", nargs="?", type=_system_name, help="only this system")
    add_json_option(p, "the catalogue")
    p.set_defaults(func=_cmd_list)

