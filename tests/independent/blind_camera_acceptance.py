"""Acceptance of ``diagnose camera`` on data of the blind second generator (camera_blind.py).

This harness is the package's own (not blind); the generator it drives was written by a second
author given only the CSV format and the published Zhang / Brown-Conrady models (its header).

Every data set goes through the CSV files, written by ``camera_blind.write`` and read back by
:func:`montecarlo.io.camera_csv.read_camera_csv`, so the reader's conventions meet the
generator's: target ids ``row * nx + col`` in millimetres (not centred), pixel centres at
integer coordinates from the top-left (the reader assumes no origin: the principal point is
fitted, so any fixed origin only moves ``c_x``, ``c_y``), OpenCV's Brown-Conrady form on
normalised coordinates (the same as the package's), random poses (5 to 8 views, tilts of
10-45 deg) and partial visibility. The generator's own camera: f = 600 px on 640 x 480,
principal point at the image centre (319.5, 239.5).

Scenarios, per data set ``seed`` (the generator's poses and view count depend on the seed, so
every set has its own design and its own minimal detectable biases, MDB):

* ``null``: the pinhole;
* ``radial``: ``k1`` at ``multiple`` times its MDB against the pinhole on that set's design;
* ``tangential``: ``p1 = p2`` at ``multiple`` times the MDB along (1, 1);
* ``bad_corner``: the generator's ``blunders=1``: one observation moved by ``blunder_px`` in a
  random direction; ``blunder_px`` is ``multiple`` times that corner's MDB along that
  direction (the corner and direction drawn by the generator with the set's seed).

MDBs are those of the engine on the noise-free pinhole views of the same seed (the hidden
distortion can hide a point at the image edge from the noisy set; the design is otherwise
the same). ``python -m tests.independent.blind_camera_acceptance --sets 200`` prints the table
(rows as :func:`montecarlo.tools.camera_acceptance.summarise`).
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from montecarlo.discrepancy import camera_effects as ce
from montecarlo.discrepancy.candidate_tests import ALPHA, analyse_candidates
from montecarlo.discrepancy.design import design_mdb
from montecarlo.discrepancy.engine import diagnose
from montecarlo.discrepancy.fit import fit_model
from montecarlo.discrepancy.problem import OUTLIER, with_outliers
from montecarlo.io.camera_csv import CameraData, read_camera_csv
from montecarlo.tools.camera_acceptance import SCENARIOS, format_table, summarise

from . import camera_blind as cb

GRID = 8
"""Target points per side (the generator's default 16 makes a diagnosis 10x slower)."""
PITCH_MM = 20.0
"""Target pitch [mm]: 8 points over 140 mm, as the package's own acceptance target."""


def blind_data(seed: int, noise_px: float, grid: int = GRID, **kwargs: Any
               ) -> tuple[CameraData, dict[str, Any]]:
    """One set of the blind generator, through its CSV files and the package's reader."""
    with tempfile.TemporaryDirectory() as tmp:
        pm, pv, pt = cb.write(tmp + "/", rng=seed, noise_px=noise_px, nx=grid, ny=grid,
                              pitch=PITCH_MM * 7 / (grid - 1), **kwargs)
        data = read_camera_csv(Path(pm), Path(pv))
        truth = json.loads(Path(pt).read_text())
    return data, truth


def injection(scenario: str, seed: int, sigma: float, multiple: float, grid: int = GRID
              ) -> dict[str, float]:
    """Generator keywords putting ``scenario`` at ``multiple`` MDB on set ``seed``'s design."""
    if scenario == "null":
        return {}
    if scenario in ("radial", "tangential"):
        exact = ce.camera_problem(blind_data(seed, 0.0, grid)[0], sigma)
        name = {"radial": "radial_k1", "tangential": "tangential"}[scenario]
        return {k: multiple * v for k, v in design_mdb(exact, exact.start, (), name).items()
                if k in ("k1", "p1", "p2")}
    # bad corner: learn which corner and which direction, then its MDB along that direction
    _, truth = blind_data(seed, 0.0, grid, blunders=1, blunder_px=1.0)
    b = truth["blunders"][0]
    exact = ce.camera_problem(blind_data(seed, 0.0, grid)[0], sigma)
    full = with_outliers(exact)
    fit = fit_model(full, (), exact.start)
    name = f"{OUTLIER}{b['view']}/{b['id']}"
    snoop = replace(full, candidates=tuple(c for c in full.candidates if c.name == name))
    (test,) = analyse_candidates(snoop, fit)
    v = test.projected @ np.array([b["du"], b["dv"]])  # unit direction (blunder_px = 1)
    return {"blunders": 1, "blunder_px": multiple * sigma * math.sqrt(test.lambda0
                                                                      / float(v @ v))}


def one_set(scenario: str, seed: int, sigma: float = 0.2, multiple: float = 3.0,
            grid: int = GRID, alpha: float = ALPHA) -> dict[str, Any]:
    """Diagnose one blind data set of ``scenario`` (row as camera_acceptance.one_set)."""
    kwargs = injection(scenario, seed, sigma, multiple, grid)
    data, truth = blind_data(seed, sigma, grid, **kwargs)
    d = diagnose(ce.camera_problem(data, sigma), alpha)
    flagged = [t.name[len(OUTLIER):] for t in d.outliers]
    right = None
    if truth["blunders"]:
        right = f"{truth['blunders'][0]['view']}/{truth['blunders'][0]['id']}"
    return {"scenario": scenario, "seed": seed, "named": list(d.named), "flagged": flagged,
            "right_corner": right, "injection": kwargs}


def run(sets: int, seed: int = 7000, sigma: float = 0.2, multiple: float = 3.0,
        grid: int = GRID, n_jobs: int = 1, scenarios: tuple[str, ...] = SCENARIOS
        ) -> dict[str, dict[str, float]]:
    """``sets`` data sets per scenario, seeds ``seed + k`` (the same design in each scenario)."""
    tasks = [(s, seed + k, sigma, multiple, grid) for s in scenarios for k in range(sets)]
    if n_jobs == 1:
        rows = [one_set(*task) for task in tasks]
    else:
        from joblib import Parallel, delayed

        rows = Parallel(n_jobs=n_jobs)(delayed(one_set)(*task) for task in tasks)
    return summarise(rows)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sets", type=int, default=200)
    p.add_argument("--seed", type=int, default=7000)
    p.add_argument("--sigma", type=float, default=0.2)
    p.add_argument("--grid", type=int, default=GRID)
    p.add_argument("--multiple", type=float, default=3.0)
    p.add_argument("--n-jobs", type=int, default=1)
    args = p.parse_args(argv)
    table = run(args.sets, args.seed, args.sigma, args.multiple, args.grid, args.n_jobs)
    print(format_table(table))


if __name__ == "__main__":
    main()
