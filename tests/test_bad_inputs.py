"""Acceptance test: bad inputs are refused in one line, with exit code 2, writing nothing.

Every case below is a study file, a CSV file or a flag combination that the command line must
refuse. Each runs ``python -m montecarlo ...`` in a process of its own, in a fresh temporary
directory into which the case's input files (from ``tests/data/bad_inputs/``) are copied, and must:

* exit with code 2;
* print exactly one line on stderr, starting with ``error: ``, that contains the case's
  ``expect`` strings (the file, the field/key/column/flag and the value, where there is one);
* print no Python traceback;
* write nothing: the temporary directory is byte-for-byte what it was before the run (no
  output directory, no output file, no parent directory made for them, no hidden
  ``.NAME.tmp-*`` directory), the case's ``absent`` paths do not exist, and the user's files
  made by ``setup`` (``unchanged``) keep their content, size, mode and modification time.

The cases selected for a session run a few at a time (:func:`outcomes`, one worker per core,
at least two). Each case is one short process, most of which, started afresh, would be spent
importing the libraries: so each worker is a server (``tests/forked_cli.py``) that imports them
once and runs every case as ``python -m montecarlo`` does, in a child forked for it.

The manifest is :data:`CASES`. ``argv`` and ``expect`` may use ``{tmp}``, the temporary
directory. ``files`` are paths under ``tests/data/bad_inputs/``, copied into the temporary
directory under their base name. ``setup`` maps a path in the temporary directory to a file's
text, or to ``None`` for an (empty) directory: things the user already has there (``links``:
their symbolic links). A case with
``defect`` set shows a real defect of the package; it is kept and marked ``xfail(strict=True)``
with the observed behaviour as the reason, so that fixing the defect makes the suite say so.

``tests/data/bad_inputs/README.md`` says how the input files were made.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import stat
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from tests.forked_cli import ForkedCli

DATA = Path(__file__).parent / "data" / "bad_inputs"
TIMEOUT = 60


@dataclass(frozen=True)
class Case:
    """One bad input: the command line and what its refusal must look like."""

    id: str
    argv: tuple[str, ...]
    """Arguments after ``python -m montecarlo``, run in the temporary directory."""
    files: tuple[str, ...] = ()
    """Input files under tests/data/bad_inputs/, copied in under their base names."""
    expect: tuple[str, ...] = ()
    """Strings the one error line must contain: file, field/key/column/flag, value."""
    absent: tuple[str, ...] = ()
    """Paths that must not exist afterwards (outputs, and their parents when new)."""
    setup: dict[str, str | None] = field(default_factory=dict)
    """The user's own files (path -> text) and folders (path -> None) made before the run."""
    unchanged: tuple[str, ...] = ()
    """Files made by ``setup`` that must be left exactly as they were."""
    links: dict[str, str] = field(default_factory=dict)
    """Symbolic links (path -> target) the user has, made after ``setup``."""
    defect: str | None = None
    """Observed defect of the package (the case is then an xfail with this reason)."""


# Things users already have in their working directory (see `setup`).
USER_FILE = {"userfile.txt": "my own notes, not results\n"}
USER_DIR = {"userdir/notes.txt": "my own notes, not results\n"}
EMPTY_DIR = {"existingdir": None}
OTHER_RESULTS = {"results/other_study/summary.csv": "another study's results\n",
                 "results/notes.txt": "my own notes\n"}
EARLIER_RESULT = '{"kind": "run", "study": "bad_input_base", "files": {}}\n'
"""provenance.json of an earlier result of valid_ground.toml that wrote nothing else."""



def study(id, file, *expect, defect=None):
    """`montecarlo run STUDY` of a bad study file (default output directory results/<name>)."""
    return Case(id, ("run", file, "--quiet"), files=(f"studies/{file}",), expect=(file, *expect),
                absent=("results",))


def csv_case(id, command, file, *expect, options=(), defect=None):
    """A command reading a bad CSV file (file name first, then the command's other flags)."""
    return Case(id, (*command, file, *options), files=(f"csv/{file}",), expect=(file, *expect))


FIT = ("collimation", "fit")
DIAG_COL = ("diagnose", "collimation")
DIAG_COL_OPTS = ("--angle-sigma-arcsec", "2.8")
DIAG_GROUND = ("diagnose", "ground")
DIAG_GROUND_OPTS = ("--fov-deg", "90", "90", "--pixels", "512", "512", "--pixel-sigma-px", "0.3",
                    "--survey-sigma-m", "0.01")
ESTIMATE = ("stabilization", "estimate")
BUDGET_CHEAP = ("--limit", "3", "--samples", "64", "--trials", "1000", "--resamples", "10")

VALID_STUDY = "studies/valid_ground.toml"
VALID_COL = "csv/valid_collimation.csv"
VALID_GROUND = "csv/valid_ground.csv"
VALID_STAB = "csv/valid_stabilization.csv"
CAM_MODEL, CAM_VIEWS = "valid_camera_model.csv", "valid_camera_views.csv"

CASES: list[Case] = [
    # ------------------------------------------------------------------ study files (run)
    study("study-unknown-key-typo-H_mm", "unknown_key_typo.toml", "geometry.H_mm", "unknown key",
          "did you mean 'H_m'", "2.0"),
    study("study-unknown-key-typo-trails", "unknown_key_study_trails.toml", "study.trails",
          "unknown key", "1000"),
    study("study-unknown-key-mounting-phi", "unknown_key_mounting_phi.toml", "mounting.phi_deg",
          "unknown key", "30.0"),
    study("study-unknown-table-solvr", "unknown_table.toml", "solvr", "unknown key"),
    study("study-wrong-type-string-number", "wrong_type_string_number.toml", "geometry.L_m",
          "'100'"),
    study("study-wrong-type-float-pixels", "wrong_type_float_pixels.toml", "sensor.pixels",
          "512.5"),
    study("study-wrong-type-bool-seed", "wrong_type_bool_seed.toml", "study.seed", "True"),
    study("study-wrong-type-fov-scalar", "wrong_type_fov_scalar.toml", "sensor.fov_deg", "90.0"),
    study("study-fov-three-values", "wrong_length_fov.toml", "sensor.fov_deg",
          "[90.0, 90.0, 90.0]"),
    study("study-missing-required-H_m", "missing_required_H_m.toml", "geometry.H_m", "missing"),
    study("study-missing-pixel-relation", "missing_pixel_relation.toml", "errors.pixel_relation",
          "missing"),
    study("study-missing-sensor-table", "missing_sensor_table.toml", "sensor", "missing"),
    study("study-missing-system", "missing_study_system.toml", "study.system", "missing"),
    study("study-missing-study-table", "missing_study_table.toml", "[study]", "missing"),
    study("study-toml-syntax-bad-number", "syntax_bad_number.toml", "not valid TOML", "line 18"),
    study("study-toml-syntax-unclosed-table", "syntax_unclosed_table.toml", "not valid TOML",
          "line 17"),
    study("study-toml-duplicate-key", "syntax_duplicate_key.toml", "not valid TOML", "line 20"),
    study("study-unknown-system", "unknown_system.toml", "study.system", "'grund'"),
    study("study-unknown-dist", "unknown_dist.toml", "errors.pixel_px", "gaussian"),
    study("study-negative-bound", "negative_bound.toml", "errors.dx_m", "bound", "-0.1"),
    study("study-negative-sigma", "negative_sigma.toml", "errors.pixel_px", "sigma", "-0.3"),
    study("study-nan-value", "nan_value.toml", "geometry.L_m", "nan"),
    study("study-inf-value", "inf_value.toml", "geometry.H_m", "inf"),
    study("study-negative-inf-sigma", "neg_inf_sigma.toml", "errors.pixel_px.sigma", "-inf"),
    study("study-nan-base-replaced-by-sweep", "nan_base_replaced_by_sweep.toml", "geometry.L_m",
          "nan"),
    study("study-nan-in-sweep-list", "nan_in_sweep_list.toml", "geometry.H_m", "nan"),
    study("study-L-1e300", "huge_L.toml", "geometry.L_m", "1e+300"),
    study("study-H-zero", "zero_H.toml", "geometry.H_m", "0.0"),
    study("study-fov-180", "fov_180.toml", "sensor.fov_deg", "180.0"),
    study("study-fov-0", "fov_0.toml", "sensor.fov_deg", "0.0"),
    study("study-pixels-0", "pixels_0.toml", "sensor.pixels", "[0, 512]"),
    study("study-trials-0", "trials_0.toml", "study.trials", "got 0"),
    study("study-trials-1e15-float", "trials_1e15_float.toml", "study.trials",
          "1000000000000000.0"),
    study("study-trials-10**15-int", "trials_10_pow_15_int.toml", "study.trials",
          "1000000000000000"),
    study("study-negative-seed", "negative_seed.toml", "study.seed", "-1"),
    study("study-name-with-path", "study_name_path.toml", "study.name", "'../escape'"),
    study("study-block-size-0", "block_size_0.toml", "study.block_size", "got 0"),
    study("study-confidence-1.5", "confidence_1_5.toml", "study.confidence", "1.5"),
    study("study-sweep-empty-list", "empty_sweep_list.toml", "geometry.L_m", "empty list"),
    study("study-sweep-not-a-list", "sweep_not_a_list.toml", "geometry.L_m", "must be a list",
          "50.0"),
    study("study-sweep-group-without-keys", "sweep_group_without_keys.toml", "sweep[0]",
          "no keys"),
    study("study-sweep-zip-lengths-differ", "zip_lengths_differ.toml", "zip",
          "geometry.L_m: 3", "geometry.H_m: 2"),
    study("study-sweep-same-key-two-groups", "same_key_two_groups.toml", "sweep", "geometry.L_m"),
    study("study-sweep-repeated-values", "repeated_sweep_values.toml", "geometry.L_m = 50.0",
          "points 0 and 2"),
    study("study-sweep-repeated-int-float", "repeated_sweep_int_float.toml",
          "geometry.L_m = 50", "points 0 and 1"),
    study("study-sweep-unknown-mode", "unknown_sweep_mode.toml", "sweep[0].mode", "'grid'"),
    study("study-sweep-key-into-non-table", "sweep_into_non_table.toml", "geometry.L_m.bound",
          "not a table"),
    study("study-sweep-key-unknown-section", "sweep_unknown_section.toml", "geomtry",
          "unknown key"),
    study("study-sweep-invalid-value", "sweep_invalid_value.toml", "geometry.H_m",
          "geometry.H_m = 0.0"),
    study("study-spec-unknown-metric", "spec_unknown_metric.toml", "spec.metric",
          "'rotation_angel'"),
    study("study-spec-unknown-variant", "spec_unknown_variant.toml", "spec.variant",
          "'normalized'"),
    study("study-spec-unknown-statistic", "spec_unknown_statistic.toml", "spec.statistic",
          "'p97'"),
    study("study-spec-limit-zero", "spec_limit_zero.toml", "spec.limit", "0.0"),
    study("study-spec-limit-negative", "spec_limit_negative.toml", "spec.limit", "-3.0"),
    study("study-pixel-relation-correlation-2", "pixel_relation_corr_2.toml",
          "errors.pixel_relation", "2.0"),
    study("study-pixel-relation-unknown-word", "pixel_relation_unknown_word.toml",
          "errors.pixel_relation", "'indep'"),
    study("study-worst-case-with-normal-source", "worst_case_normal_source.toml", "pixel_px",
          "normal"),
    study("study-evaluation-unknown", "evaluation_unknown.toml", "errors.evaluation",
          "'worstcase'"),
    study("study-solver-unknown-variant", "solver_unknown_variant.toml", "solver.variants",
          "'normalized'"),
    study("study-solver-no-variants", "solver_no_variants.toml", "solver.variants", "[]"),
    study("study-empty-file", "empty.toml", "[study]", "missing"),
    study("study-binary-file", "binary.toml", "not valid TOML"),
    study("study-air-unknown-param", "air_unknown_param.toml", "params.gyro_drift_deg_per_hr",
          "unknown key"),
    study("study-air-unknown-ta-source", "air_unknown_ta_source.toml", "params.ta_source",
          "'kalmann'"),
    study("study-collimation-negative-mirrors", "collimation_negative_mirrors.toml",
          "params.n_azimuth", "-3"),
    study("study-collimation-negative-sigma", "collimation_negative_sigma.toml",
          "params.theodolite_sigma_arcsec", "-2.0"),
    study("study-stabilization-negative-duration", "stabilization_negative_duration.toml",
          "params.duration_s", "-5.0"),
    study("study-stabilization-wrong-type", "stabilization_wrong_type.toml", "params.duration_s",
          "'long'"),
    Case("study-path-is-directory", ("run", "studydir", "--quiet"), setup={"studydir": None},
         expect=("studydir", "directory"), absent=("results",)),
    Case("study-path-missing", ("run", "nosuch.toml", "--quiet"),
         expect=("nosuch.toml", "no such"), absent=("results",)),
    Case("study-trials-override-too-large",
         ("run", "valid_ground.toml", "--trials", "100000000000000", "--quiet"),
         files=(VALID_STUDY,), expect=("valid_ground.toml", "study.trials", "100000000000000"),
         absent=("results",)),

    # ------------------------------------------------------------------ run flags and outputs
    Case("run-n-jobs-0", ("run", "valid_ground.toml", "--n-jobs", "0"), files=(VALID_STUDY,),
         expect=("--n-jobs", "'0'"), absent=("results",)),
    Case("run-trials-ten", ("run", "valid_ground.toml", "--trials", "ten"), files=(VALID_STUDY,),
         expect=("--trials", "'ten'"), absent=("results",)),
    Case("run-trials-negative", ("run", "valid_ground.toml", "--trials", "-1"),
         files=(VALID_STUDY,), expect=("--trials", "'-1'"), absent=("results",)),
    Case("run-seed-negative", ("run", "valid_ground.toml", "--seed", "-1"), files=(VALID_STUDY,),
         expect=("--seed", "'-1'"), absent=("results",)),
    Case("run-backend-mpi", ("run", "valid_ground.toml", "--backend", "mpi"),
         files=(VALID_STUDY,), expect=("--backend", "'mpi'"), absent=("results",)),
    Case("run-scheduler-with-loky",
         ("run", "valid_ground.toml", "--scheduler", "tcp://127.0.0.1:8786", "--quiet"),
         files=(VALID_STUDY,), expect=("--scheduler", "dask"), absent=("results",)),
    Case("run-scheduler-notanaddress",
         ("run", "valid_ground.toml", "--backend", "dask", "--scheduler", "notanaddress",
          "--quiet"),
         files=(VALID_STUDY,), expect=("--scheduler", "'notanaddress'"), absent=("results",)),
    Case("run-scheduler-http-url",
         ("run", "valid_ground.toml", "--backend", "dask", "--scheduler", "http://localhost:1",
          "--quiet"),
         files=(VALID_STUDY,), expect=("--scheduler", "'http://localhost:1'"),
         absent=("results",)),
    Case("run-chunk-size-not-block-multiple",
         ("run", "valid_ground.toml", "--chunk-size", "1000", "--quiet"), files=(VALID_STUDY,),
         expect=("--chunk-size", "1000", "65536"), absent=("results",)),
    Case("run-chunk-size-not-block-multiple-out-here",
         ("run", "valid_ground.toml", "--chunk-size", "1000", "--out", "out", "--quiet"),
         files=(VALID_STUDY,), expect=("--chunk-size", "1000", "65536"),
         absent=("out", ".checkpoints")),
    Case("run-out-is-existing-file",
         ("run", "valid_ground.toml", "--out", "userfile.txt", "--quiet"), files=(VALID_STUDY,),
         setup=USER_FILE, unchanged=("userfile.txt",), expect=("userfile.txt", "not a directory"),
         absent=(".checkpoints",)),
    Case("run-out-is-user-directory",
         ("run", "valid_ground.toml", "--out", "userdir", "--quiet"), files=(VALID_STUDY,),
         setup=USER_DIR, unchanged=("userdir/notes.txt",),
         expect=("userdir", "not an earlier result"), absent=(".checkpoints",)),
    Case("run-default-out-is-user-directory", ("run", "valid_ground.toml", "--quiet"),
         files=(VALID_STUDY,), setup={"results/bad_input_base/notes.txt": "mine\n"},
         unchanged=("results/bad_input_base/notes.txt",),
         expect=("results/bad_input_base", "not an earlier result"),
         absent=("results/.checkpoints",)),
    Case("run-out-absolute-user-directory",
         ("run", "valid_ground.toml", "--out", "{tmp}/userdir", "--quiet"), files=(VALID_STUDY,),
         setup=USER_DIR, unchanged=("userdir/notes.txt",),
         expect=("{tmp}/userdir", "not an earlier result"), absent=(".checkpoints",)),
    Case("run-missing-study-argument", ("run", "--quiet"), expect=("study", "required"),
         absent=("results",)),
    Case("run-unknown-flag-trails", ("run", "valid_ground.toml", "--trails", "10"),
         files=(VALID_STUDY,), expect=("--trails", "10"), absent=("results",)),

    # ------------------------------------------------------------------ where results go
    Case("run-study-named-dot", ("run", "name_dot.toml", "--quiet"),
         files=("studies/name_dot.toml",), setup=OTHER_RESULTS,
         unchanged=tuple(OTHER_RESULTS), expect=("name_dot.toml", "study.name", "'.'")),
    Case("run-study-named-dot-dot", ("run", "name_dotdot.toml", "--quiet"),
         files=("studies/name_dotdot.toml",), setup=OTHER_RESULTS,
         unchanged=tuple(OTHER_RESULTS), expect=("name_dotdot.toml", "study.name", "'..'")),
    Case("run-out-dot", ("run", "valid_ground.toml", "--out", ".", "--quiet"),
         files=(VALID_STUDY,), expect=(".:", "current directory"),
         absent=(".checkpoints", "results")),
    Case("run-out-dot-dot", ("run", "valid_ground.toml", "--out", "..", "--quiet"),
         files=(VALID_STUDY,), expect=("..:", "current directory"),
         absent=(".checkpoints", "results")),
    Case("run-out-through-a-subdirectory-to-here",
         ("run", "valid_ground.toml", "--out", "existingdir/..", "--quiet"),
         files=(VALID_STUDY,), setup=EMPTY_DIR, expect=("existingdir/..", "current directory"),
         absent=(".checkpoints", "results")),
    Case("run-out-results-root", ("run", "valid_ground.toml", "--out", "results", "--quiet"),
         files=(VALID_STUDY,), setup=OTHER_RESULTS, unchanged=tuple(OTHER_RESULTS),
         expect=("results", "results root")),
    Case("run-out-earlier-result-holding-a-users-file",
         ("run", "valid_ground.toml", "--out", "out", "--quiet"), files=(VALID_STUDY,),
         setup={"out/provenance.json": EARLIER_RESULT, "out/notes.txt": "mine\n"},
         unchanged=("out/provenance.json", "out/notes.txt"),
         expect=("out", "'notes.txt'", "did not write"), absent=(".checkpoints",)),
    Case("run-out-earlier-result-with-an-edited-file",
         ("run", "valid_ground.toml", "--out", "out", "--quiet"), files=(VALID_STUDY,),
         setup={"out/provenance.json": EARLIER_RESULT, "out/report.md": "my edits\n"},
         unchanged=("out/provenance.json", "out/report.md"),
         expect=("out", "'report.md'", "did not write"), absent=(".checkpoints",)),
    Case("run-out-symlink-to-users-directory",
         ("run", "valid_ground.toml", "--out", "link", "--quiet"), files=(VALID_STUDY,),
         setup=USER_DIR, links={"link": "userdir"}, unchanged=("userdir/notes.txt",),
         expect=("link", "symbolic link"), absent=(".checkpoints",)),
    Case("run-out-broken-symlink", ("run", "valid_ground.toml", "--out", "link", "--quiet"),
         files=(VALID_STUDY,), links={"link": "nowhere"}, expect=("link", "symbolic link"),
         absent=(".checkpoints", "nowhere")),
    Case("run-out-directory-holding-the-study",
         ("run", "studydir/valid_ground.toml", "--out", "studydir", "--quiet"),
         setup={"studydir/valid_ground.toml": (DATA / VALID_STUDY).read_text(),
                "studydir/provenance.json": EARLIER_RESULT},
         unchanged=("studydir/valid_ground.toml",), expect=("studydir", "holds the input")),
    Case("diagnose-report-directory-holding-the-data",
         (*DIAG_COL, "data/valid_collimation.csv", *DIAG_COL_OPTS, "--report", "data"),
         setup={"data/valid_collimation.csv": (DATA / VALID_COL).read_text()},
         unchanged=("data/valid_collimation.csv",), expect=("data", "holds the input")),
    Case("schema-out-existing-user-file", ("schema", "--out", "userfile.txt"), setup=USER_FILE,
         unchanged=("userfile.txt",), expect=("userfile.txt", "exists", "--force")),

    # ------------------------------------------------------------------ bounded work up front
    Case("run-sweep-of-a-million-points", ("run", "huge_sweep.toml", "--quiet"),
         files=("studies/huge_sweep.toml",),
         expect=("huge_sweep.toml", "1,000,000 grid points", "GB", "--max-points"),
         absent=("results",)),
    Case("validate-sweep-of-a-million-points", ("validate", "huge_sweep.toml"),
         files=("studies/huge_sweep.toml",),
         expect=("huge_sweep.toml", "1,000,000 grid points", "--max-points")),
    Case("validate-max-points-0", ("validate", "valid_ground.toml", "--max-points", "0"),
         files=(VALID_STUDY,), expect=("--max-points", "'0'")),
    Case("run-max-trials-below-the-studys-trials",
         ("run", "valid_ground.toml", "--until-decided", "--max-trials", "500", "--quiet"),
         files=(VALID_STUDY,), expect=("--max-trials", "500", "1,000"), absent=("results",)),
    Case("run-max-trials-without-until-decided",
         ("run", "valid_ground.toml", "--max-trials", "5000", "--quiet"),
         files=(VALID_STUDY,), expect=("--max-trials", "--until-decided"), absent=("results",)),
    Case("plan-pilot-too-small-for-p99", ("plan", "plan_p99.toml", "--trials", "100", "--quiet"),
         files=("studies/plan_p99.toml",), expect=("pilot of 100", "p99", "--trials 368"),
         absent=("results",)),

    # ------------------------------------------------------------------ study files, continued
    study("study-negative-base-replaced-by-sweep", "negative_base_replaced_by_sweep.toml",
          "geometry.L_m", "-100.0", "base value"),
    study("study-byte-order-mark", "bom.toml", "byte-order mark", "without BOM"),

    # ------------------------------------------------------------------ other commands' flags
    Case("cli-unknown-command", ("frobnicate",), expect=("'frobnicate'",)),
    Case("cli-unknown-subcommand", ("collimation", "frobnicate"), expect=("'frobnicate'",)),
    Case("cli-no-command", (), expect=("command", "required")),
    Case("air-seed-negative", ("air", "--seed", "-1"), expect=("--seed", "'-1'")),
    Case("air-trials-0", ("air", "--trials", "0"), expect=("--trials", "'0'")),
    Case("transfer-alignment-seed-negative", ("transfer-alignment", "--seed", "-1"),
         expect=("--seed", "'-1'")),
    Case("transfer-alignment-unknown-manoeuvre", ("transfer-alignment", "--manoeuvre", "loop"),
         expect=("manoeuvre", "'loop'")),
    Case("collimation-simulate-seed-negative", ("collimation", "simulate", "out.csv", "--seed",
                                                "-1"),
         expect=("--seed", "'-1'"), absent=("out.csv",)),
    Case("collimation-simulate-n-azimuth-negative",
         ("collimation", "simulate", "out.csv", "--n-azimuth", "-3"),
         expect=("--n-azimuth", "'-3'"), absent=("out.csv",)),
    Case("collimation-simulate-no-mirrors",
         ("collimation", "simulate", "out.csv", "--n-azimuth", "0", "--n-pitch", "0"),
         expect=("--n-azimuth", "--n-pitch", "0"), absent=("out.csv",)),
    Case("collimation-simulate-negative-sigma",
         ("collimation", "simulate", "out.csv", "--theodolite-sigma-arcsec", "-1"),
         expect=("--theodolite-sigma-arcsec", "'-1'"), absent=("out.csv",)),
    Case("collimation-simulate-into-missing-directory",
         ("collimation", "simulate", "nodir/out.csv"), expect=("nodir/out.csv", "nodir"),
         absent=("nodir",)),
    Case("collimation-simulate-out-is-directory", ("collimation", "simulate", "existingdir"),
         setup=EMPTY_DIR, expect=("existingdir", "directory")),
    Case("stabilization-simulate-seed-negative",
         ("stabilization", "simulate", "out.csv", "--seed", "-1"), expect=("--seed", "'-1'"),
         absent=("out.csv",)),
    Case("stabilization-simulate-fov-180",
         ("stabilization", "simulate", "out.csv", "--fov-deg", "180"),
         expect=("--fov-deg", "180"), absent=("out.csv",)),
    Case("stabilization-simulate-duration-0",
         ("stabilization", "simulate", "out.csv", "--duration-s", "0"),
         expect=("--duration-s", "'0'"), absent=("out.csv",)),
    Case("stabilization-simulate-rate-nan",
         ("stabilization", "simulate", "out.csv", "--rate-hz", "nan"),
         expect=("--rate-hz", "'nan'"),
         absent=("out.csv",)),
    Case("stabilization-simulate-into-missing-directory",
         ("stabilization", "simulate", "nodir/out.csv", "--duration-s", "1"),
         expect=("nodir/out.csv",), absent=("nodir",)),
    Case("stabilization-simulate-out-is-directory",
         ("stabilization", "simulate", "existingdir", "--duration-s", "1"), setup=EMPTY_DIR,
         expect=("existingdir", "directory")),
    Case("stabilization-estimate-forgetting-1.5",
         ("stabilization", "estimate", "valid_stabilization.csv", "--forgetting", "1.5"),
         files=(VALID_STAB,), expect=("--forgetting", "1.5")),
    Case("stabilization-estimate-image-noise-negative",
         ("stabilization", "estimate", "valid_stabilization.csv", "--image-noise-px", "-0.25"),
         files=(VALID_STAB,), expect=("--image-noise-px", "-0.25")),
    Case("stabilization-estimate-pixels-0",
         ("stabilization", "estimate", "valid_stabilization.csv", "--pixels", "0"),
         files=(VALID_STAB,), expect=("--pixels", "'0'")),
    Case("stabilization-observability-fov-0", ("stabilization", "observability", "--fov-deg",
                                               "0"),
         expect=("--fov-deg", "'0'")),
    Case("diagnose-ground-pixel-sigma-0",
         ("diagnose", "ground", "valid_ground.csv", "--fov-deg", "90", "90", "--pixels", "512",
          "512", "--pixel-sigma-px", "0"),
         files=(VALID_GROUND,), expect=("--pixel-sigma-px", "'0'")),
    Case("diagnose-ground-fov-nan",
         ("diagnose", "ground", "valid_ground.csv", "--fov-deg", "nan", "90", "--pixels", "512",
          "512", "--pixel-sigma-px", "0.3"),
         files=(VALID_GROUND,), expect=("--fov-deg", "'nan'")),
    Case("diagnose-ground-fov-180",
         ("diagnose", "ground", "valid_ground.csv", "--fov-deg", "180", "90", "--pixels", "512",
          "512", "--pixel-sigma-px", "0.3"),
         files=(VALID_GROUND,), expect=("--fov-deg", "180")),
    Case("diagnose-ground-alpha-1.5", (*DIAG_GROUND, "valid_ground.csv", *DIAG_GROUND_OPTS,
                                       "--alpha", "1.5"),
         files=(VALID_GROUND,), expect=("--alpha", "'1.5'")),
    Case("diagnose-ground-missing-pixel-sigma",
         ("diagnose", "ground", "valid_ground.csv", "--fov-deg", "90", "90", "--pixels", "512",
          "512"),
         files=(VALID_GROUND,), expect=("--pixel-sigma-px", "required")),
    Case("diagnose-ground-json-into-missing-directory",
         (*DIAG_GROUND, "valid_ground.csv", *DIAG_GROUND_OPTS, "--json", "nodir/out.json"),
         files=(VALID_GROUND,), expect=("nodir/out.json", "nodir"), absent=("nodir",)),
    Case("diagnose-ground-json-is-directory",
         (*DIAG_GROUND, "valid_ground.csv", *DIAG_GROUND_OPTS, "--json", "existingdir"),
         files=(VALID_GROUND,), setup=EMPTY_DIR, expect=("existingdir", "directory")),
    Case("diagnose-ground-report-user-directory",
         (*DIAG_GROUND, "valid_ground.csv", *DIAG_GROUND_OPTS, "--report", "userdir",
          "--trials", "0"),
         files=(VALID_GROUND,), setup=USER_DIR, unchanged=("userdir/notes.txt",),
         expect=("userdir", "not an earlier result")),
    Case("diagnose-ground-report-is-file",
         (*DIAG_GROUND, "valid_ground.csv", *DIAG_GROUND_OPTS, "--report", "userfile.txt",
          "--trials", "0"),
         files=(VALID_GROUND,), setup=USER_FILE, unchanged=("userfile.txt",),
         expect=("userfile.txt", "not a directory")),
    Case("diagnose-collimation-alpha-1.5",
         (*DIAG_COL, "valid_collimation.csv", *DIAG_COL_OPTS, "--alpha", "1.5"),
         files=(VALID_COL,), expect=("--alpha", "'1.5'")),
    Case("diagnose-collimation-missing-sigma", (*DIAG_COL, "valid_collimation.csv"),
         files=(VALID_COL,), expect=("--angle-sigma-arcsec", "required")),
    Case("diagnose-collimation-json-into-missing-directory",
         (*DIAG_COL, "valid_collimation.csv", *DIAG_COL_OPTS, "--json", "{tmp}/nodir/out.json"),
         files=(VALID_COL,), expect=("{tmp}/nodir/out.json",), absent=("nodir",)),
    Case("diagnose-collimation-report-user-directory",
         (*DIAG_COL, "valid_collimation.csv", *DIAG_COL_OPTS, "--report", "userdir", "--trials",
          "0"),
         files=(VALID_COL,), setup=USER_DIR, unchanged=("userdir/notes.txt",),
         expect=("userdir", "not an earlier result")),
    Case("collimation-fit-json-into-missing-directory",
         ("collimation", "fit", "valid_collimation.csv", "--json", "nodir/out.json"),
         files=(VALID_COL,), expect=("nodir/out.json", "nodir"), absent=("nodir",)),
    Case("collimation-fit-json-is-directory",
         ("collimation", "fit", "valid_collimation.csv", "--json", "existingdir"),
         files=(VALID_COL,), setup=EMPTY_DIR, expect=("existingdir", "directory")),
    Case("collimation-fit-sigma-0",
         ("collimation", "fit", "valid_collimation.csv", "--angle-sigma-arcsec", "0"),
         files=(VALID_COL,), expect=("--angle-sigma-arcsec", "'0'")),
    Case("collimation-figures-user-directory", ("collimation", "figures", "userdir"),
         setup=USER_DIR, unchanged=("userdir/notes.txt",),
         expect=("userdir", "not an earlier result")),
    Case("collimation-figures-is-file", ("collimation", "figures", "userfile.txt"),
         setup=USER_FILE, unchanged=("userfile.txt",), expect=("userfile.txt", "not a directory")),
    Case("synth-ground-unknown-effect", ("synth", "ground", "out.csv", "--effect", "bogus=1"),
         expect=("--effect", "bogus"), absent=("out.csv",)),
    Case("synth-ground-truth-into-missing-directory",
         ("synth", "ground", "out.csv", "--truth", "nodir/truth.json"),
         expect=("nodir/truth.json",), absent=("out.csv", "nodir")),
    Case("synth-ground-out-is-directory", ("synth", "ground", "existingdir"), setup=EMPTY_DIR,
         expect=("existingdir", "directory")),
    Case("synth-collimation-into-missing-directory", ("synth", "collimation", "nodir/out.csv"),
         expect=("nodir/out.csv",), absent=("nodir",)),
    Case("synth-collimation-n-azimuth-0",
         ("synth", "collimation", "out.csv", "--n-azimuth", "0"),
         expect=("--n-azimuth", "'0'"), absent=("out.csv",)),
    Case("size-limit-0", ("size", "--limit", "0"), expect=("--limit", "'0'"),
         absent=("results",)),
    Case("size-vary-not-a-number", ("size", "--limit", "3", "--vary", "L_m=abc:10"),
         expect=("--vary", "L_m", "'abc'"), absent=("results",)),
    Case("size-vary-unknown-knob", ("size", "--limit", "3", "--vary", "bogus=1:2", "--trials",
                                    "1000"),
         expect=("bogus",), absent=("results",)),
    Case("size-vary-bounds-reversed",
         ("size", "--limit", "3", "--vary", "L_m=400:25", "--trials", "1000"),
         expect=("L_m", "400", "25"), absent=("results",)),
    Case("size-weight-not-varied",
         ("size", "--limit", "3", "--vary", "L_m=25:400", "--weight", "H_m=2"),
         expect=("--weight", "H_m"), absent=("results",)),
    Case("size-order-unknown-knob", ("size", "--limit", "3", "--order", "L_m,bogus", "--trials",
                                     "1000"),
         expect=("order", "bogus"), absent=("results",)),
    Case("size-out-user-directory",
         ("size", "--limit", "3", "--out", "userdir", "--trials", "1000", "--levels", "2",
          "--no-confirm"),
         setup=USER_DIR, unchanged=("userdir/notes.txt",),
         expect=("userdir", "not an earlier result"), absent=("results",)),
    Case("size-study-unknown-key", ("size", "--study", "unknown_key_typo.toml", "--trials",
                                    "1000", "--levels", "2", "--no-confirm"),
         files=("studies/unknown_key_typo.toml",),
         expect=("unknown_key_typo.toml", "geometry.H_mm"), absent=("results",)),
    Case("size-study-missing", ("size", "--study", "nosuch.toml"),
         expect=("nosuch.toml", "no such"), absent=("results",)),
    Case("budget-out-user-directory", ("budget", *BUDGET_CHEAP, "--out", "userdir"),
         setup=USER_DIR, unchanged=("userdir/notes.txt",),
         expect=("userdir", "not an earlier result"), absent=("results",)),
    Case("budget-study-unknown-key", ("budget", *BUDGET_CHEAP, "--study",
                                      "unknown_key_typo.toml"),
         files=("studies/unknown_key_typo.toml",),
         expect=("unknown_key_typo.toml", "geometry.H_mm"), absent=("results",)),
    Case("budget-point-nan", ("budget", *BUDGET_CHEAP, "--point", "L_m=nan"),
         expect=("--point", "L_m", "'nan'"), absent=("results",)),
    Case("budget-point-unknown-knob", ("budget", *BUDGET_CHEAP, "--point", "range=50"),
         expect=("--point", "range"), absent=("results",)),
    Case("budget-samples-not-power-of-2", ("budget", "--limit", "3", "--samples", "100",
                                           "--trials", "1000"),
         expect=("samples", "100"), absent=("results",)),
    Case("budget-from-sizing-and-point",
         ("budget", *BUDGET_CHEAP, "--from-sizing", "valid_answers.csv", "--point", "L_m=50"),
         files=("csv/valid_answers.csv",), expect=("--from-sizing", "--point"),
         absent=("results",)),
    Case("budget-from-sizing-missing-file",
         ("budget", *BUDGET_CHEAP, "--from-sizing", "nosuch.csv"),
         expect=("nosuch.csv", "no such"), absent=("results",)),
    Case("nightly-out-user-directory", ("nightly", "--out", "userdir", "--quiet"),
         setup=USER_DIR, unchanged=("userdir/notes.txt",),
         expect=("userdir", "not an earlier result"), absent=("results",)),
    Case("nightly-studies-missing", ("nightly", "--studies", "nodir", "--quiet"),
         expect=("nodir/table1.toml", "no such"), absent=("results",)),

    # ------------------------------------------------------------------ CSV: collimation fit
    csv_case("fit-csv-missing-column", FIT, "col_missing_column.csv", "'ins_el_deg'"),
    csv_case("fit-csv-repeated-header", FIT, "col_repeated_header.csv", "'ins_az_deg'",
             "2 times"),
    csv_case("fit-csv-non-numeric", FIT, "col_non_numeric.csv", "row 4", "'ins_az_deg'",
             "'north'"),
    csv_case("fit-csv-empty-value", FIT, "col_empty_value.csv", "row 5", "'theodolite_el_deg'",
             "''"),
    csv_case("fit-csv-empty-mirror-name", FIT, "col_empty_mirror_name.csv", "row 3", "'mirror'",
             "empty"),
    csv_case("fit-csv-nan", FIT, "col_nan_value.csv", "row 6", "'ins_el_deg'", "'nan'"),
    csv_case("fit-csv-inf", FIT, "col_inf_value.csv", "row 7", "'theodolite_az_deg'", "'inf'"),
    csv_case("fit-csv-elevation-beyond-90", FIT, "col_elevation_beyond_90.csv", "row 8",
             "'theodolite_el_deg'", "95.0"),
    csv_case("fit-csv-azimuth-beyond-360", FIT, "col_azimuth_beyond_360.csv", "row 3",
             "'ins_az_deg'", "400.0"),
    csv_case("fit-csv-roll-beyond-180", FIT, "col_roll_beyond_180.csv", "row 5",
             "'ins_roll_deg'", "200.0"),
    csv_case("fit-csv-unknown-set", FIT, "col_unknown_set.csv", "row 4", "'set'", "'roll'"),
    csv_case("fit-csv-duplicate-mirror", FIT, "col_duplicate_mirror.csv", "row 5", "'mirror'",
             "'A3'", "repeats row 4"),
    csv_case("fit-csv-too-few-rows", FIT, "col_too_few_rows.csv", "1 data rows"),
    csv_case("fit-csv-header-only", FIT, "col_header_only.csv", "0 data rows"),
    csv_case("fit-csv-ragged-row", FIT, "col_ragged_row.csv", "line 5"),
    csv_case("fit-csv-empty-file", FIT, "empty.csv", "not a readable CSV"),
    csv_case("fit-csv-binary-file", FIT, "binary.csv", "not a readable CSV"),
    Case("fit-csv-is-directory", ("collimation", "fit", "csvdir"), setup={"csvdir": None},
         expect=("csvdir", "directory")),
    Case("fit-csv-missing-file", ("collimation", "fit", "nosuch.csv"),
         expect=("nosuch.csv", "no such")),
    Case("fit-csv-bad-with-json", ("collimation", "fit", "col_unknown_set.csv", "--json",
                                   "fit.json"),
         files=("csv/col_unknown_set.csv",), expect=("col_unknown_set.csv", "'set'", "'roll'"),
         absent=("fit.json",)),

    # ------------------------------------------------------------------ CSV: diagnose collimation
    csv_case("diagnose-collimation-csv-elevation-beyond-90", DIAG_COL,
             "col_elevation_beyond_90.csv", "row 8", "'theodolite_el_deg'", "95.0",
             options=DIAG_COL_OPTS),
    csv_case("diagnose-collimation-csv-unknown-set", DIAG_COL, "col_unknown_set.csv", "row 4",
             "'set'", "'roll'", options=DIAG_COL_OPTS),
    csv_case("diagnose-collimation-csv-duplicate-mirror", DIAG_COL, "col_duplicate_mirror.csv",
             "row 5", "'mirror'", "'A3'", options=DIAG_COL_OPTS),
    csv_case("diagnose-collimation-absolute-two-azimuth-mirrors", DIAG_COL,
             "col_two_azimuth_mirrors.csv", "not separable",
             options=(*DIAG_COL_OPTS, "--readings", "absolute")),
    csv_case("diagnose-collimation-csv-too-few-rows", DIAG_COL, "col_too_few_rows.csv",
             "1 data rows", options=DIAG_COL_OPTS),
    Case("diagnose-collimation-csv-bad-with-report-and-json",
         (*DIAG_COL, "col_nan_value.csv", *DIAG_COL_OPTS, "--report", "report", "--json",
          "diag.json", "--trials", "0"),
         files=("csv/col_nan_value.csv",), expect=("col_nan_value.csv", "'ins_el_deg'", "'nan'"),
         absent=("report", "diag.json")),

    # ------------------------------------------------------------------ CSV: diagnose ground
    csv_case("ground-csv-missing-column", DIAG_GROUND, "ground_missing_column.csv", "'pz'",
             options=DIAG_GROUND_OPTS),
    csv_case("ground-csv-repeated-header", DIAG_GROUND, "ground_repeated_header.csv", "'px'",
             "2 times", options=DIAG_GROUND_OPTS),
    csv_case("ground-csv-non-numeric", DIAG_GROUND, "ground_non_numeric.csv", "row 6", "'y_m'",
             "'12;5'", options=DIAG_GROUND_OPTS),
    csv_case("ground-csv-empty-value", DIAG_GROUND, "ground_empty_value.csv", "row 7", "'z_m'",
             "''", options=DIAG_GROUND_OPTS),
    csv_case("ground-csv-nan", DIAG_GROUND, "ground_nan_value.csv", "row 8", "'px'", "'NaN'",
             options=DIAG_GROUND_OPTS),
    csv_case("ground-csv-inf", DIAG_GROUND, "ground_inf_value.csv", "row 9", "'pz'", "'-inf'",
             options=DIAG_GROUND_OPTS),
    csv_case("ground-csv-coordinate-1e308", DIAG_GROUND, "ground_huge_coordinate.csv", "row 10",
             "'x_m'", "1e308", options=DIAG_GROUND_OPTS),
    csv_case("ground-csv-target-at-origin", DIAG_GROUND, "ground_target_at_origin.csv",
             "row 11", "'x_m'", "(0, 0, 0)", options=DIAG_GROUND_OPTS),
    csv_case("ground-csv-target-behind-sensor", DIAG_GROUND, "ground_target_behind.csv",
             "row 15", "'x_m'", "behind", options=DIAG_GROUND_OPTS),
    csv_case("ground-csv-pixel-outside-detector", DIAG_GROUND,
             "ground_pixel_outside_detector.csv", "row 12", "'px'", "300.0",
             options=DIAG_GROUND_OPTS),
    csv_case("ground-csv-empty-session", DIAG_GROUND, "ground_empty_session.csv", "row 13",
             "'session'", "empty", options=DIAG_GROUND_OPTS),
    csv_case("ground-csv-duplicate-target", DIAG_GROUND, "ground_duplicate_target.csv", "row 5",
             "'target'", "'T03'", "repeats row 4", options=DIAG_GROUND_OPTS),
    csv_case("ground-csv-too-few-rows", DIAG_GROUND, "ground_too_few_rows.csv", "3 data rows",
             options=DIAG_GROUND_OPTS),
    csv_case("ground-csv-empty-file", DIAG_GROUND, "empty.csv", "not a readable CSV",
             options=DIAG_GROUND_OPTS),
    Case("ground-csv-is-directory", (*DIAG_GROUND, "csvdir", *DIAG_GROUND_OPTS),
         setup={"csvdir": None}, expect=("csvdir", "directory")),
    Case("ground-csv-bad-with-report-and-json",
         (*DIAG_GROUND, "ground_target_at_origin.csv", *DIAG_GROUND_OPTS, "--report", "report",
          "--json", "diag.json", "--trials", "0"),
         files=("csv/ground_target_at_origin.csv",),
         expect=("ground_target_at_origin.csv", "row 11"), absent=("report", "diag.json")),

    # ------------------------------------------------------------------ CSV: stabilization
    csv_case("stabilization-csv-times-not-increasing", ESTIMATE, "stab_times_not_increasing.csv",
             "row 23", "'t_s'", "0.2"),
    csv_case("stabilization-csv-times-repeated", ESTIMATE, "stab_times_repeated.csv", "row 32",
             "'t_s'", "0.29"),
    csv_case("stabilization-csv-gimbal-pitch-beyond-89", ESTIMATE, "stab_pitch_beyond_89.csv",
             "row 42", "'eps_rad'", "1.56"),
    csv_case("stabilization-csv-missing-column", ESTIMATE, "stab_missing_column.csv",
             "'los_z_px'"),
    csv_case("stabilization-csv-non-numeric", ESTIMATE, "stab_non_numeric.csv", "row 52",
             "'gyro_y'", "'0.1 rad/s'"),
    csv_case("stabilization-csv-gyro-rate-1e5", ESTIMATE, "stab_gyro_rate_huge.csv", "row 62",
             "'gyro_z'", "1e5"),
    csv_case("stabilization-csv-too-few-rows", ESTIMATE, "stab_too_few_rows.csv", "5 data rows"),
    csv_case("stabilization-csv-binary-file", ESTIMATE, "binary.csv", "not a readable CSV"),
    Case("stabilization-csv-is-directory", ("stabilization", "estimate", "csvdir"),
         setup={"csvdir": None}, expect=("csvdir", "directory")),

    # ------------------------------------------------------------------ CSV: diagnose camera
    *[Case(f"camera-{id}", ("diagnose", "camera", model, views, "--pixel-sigma-px", "0.2",
                            "--report", "report", "--emit-errors", "e.toml"),
           files=(f"csv/{model}", f"csv/{views}"), expect=expect, absent=("report", "e.toml"))
      for id, model, views, expect in (
          ("model-unknown-unit", "camera_model_unknown_unit.csv", CAM_VIEWS,
           ("camera_model_unknown_unit.csv", "row 6", "'unit'", "'furlong'")),
          ("model-mixed-units", "camera_model_mixed_unit.csv", CAM_VIEWS,
           ("camera_model_mixed_unit.csv", "row 9", "'unit'", "'cm'")),
          ("model-repeated-id", "camera_model_repeated_id.csv", CAM_VIEWS,
           ("camera_model_repeated_id.csv", "row 4", "'id'", "'2'")),
          ("model-nan-x", "camera_model_nan_x.csv", CAM_VIEWS,
           ("camera_model_nan_x.csv", "row 7", "'X'", "'nan'")),
          ("model-missing-column", "camera_model_missing_column.csv", CAM_VIEWS,
           ("camera_model_missing_column.csv", "'Y'")),
          ("views-unknown-id", CAM_MODEL, "camera_views_unknown_id.csv",
           ("camera_views_unknown_id.csv", "row 12", "'id'", "'99'")),
          ("views-repeated-point", CAM_MODEL, "camera_views_repeated_point.csv",
           ("camera_views_repeated_point.csv", "row 14", "'id'", "'12'", "'V1'")),
          ("views-non-numeric-u", CAM_MODEL, "camera_views_non_numeric_u.csv",
           ("camera_views_non_numeric_u.csv", "row 20", "'u'", "'12px'")),
          ("views-two-views", CAM_MODEL, "camera_views_two_views.csv",
           ("camera_views_two_views.csv", "'view'", "2 views")),
          ("views-view-with-three-points", CAM_MODEL, "camera_views_view_with_three_points.csv",
           ("camera_views_view_with_three_points.csv", "row 34", "'view'", "'V3'", "3 points")),
      )],
    Case("camera-pixel-sigma-zero", ("diagnose", "camera", CAM_MODEL, CAM_VIEWS,
                                     "--pixel-sigma-px", "0"),
         files=(f"csv/{CAM_MODEL}", f"csv/{CAM_VIEWS}"), expect=("--pixel-sigma-px", "'0'")),
    Case("camera-emit-errors-into-missing-directory",
         ("diagnose", "camera", CAM_MODEL, CAM_VIEWS, "--pixel-sigma-px", "0.2",
          "--emit-errors", "nodir/e.toml"),
         files=(f"csv/{CAM_MODEL}", f"csv/{CAM_VIEWS}"), expect=("nodir/e.toml",),
         absent=("nodir",)),
    Case("run-errors-file-with-a-study-table", ("run", "valid_ground.toml", "--errors",
                                                "errors_extra_table.toml", "--quiet"),
         files=(VALID_STUDY, "studies/errors_extra_table.toml"),
         expect=("errors_extra_table.toml", "[errors]", "study"), absent=("results",)),
    Case("size-errors-file-negative-sigma", ("size", "--limit", "3", "--errors",
                                             "errors_negative_sigma.toml"),
         files=("studies/errors_negative_sigma.toml",),
         expect=("errors_negative_sigma.toml", "errors.pixel_px", "-0.3"), absent=("results",)),

    # ------------------------------------------------------------------ CSV: budget --from-sizing
    csv_case("budget-answers-missing-relation-column", ("budget", *BUDGET_CHEAP, "--from-sizing"),
             "answers_missing_relation.csv", "'pixel_relation'"),
    csv_case("budget-answers-unknown-relation", ("budget", *BUDGET_CHEAP, "--from-sizing"),
             "answers_unknown_relation.csv", "row 2", "'pixel_relation'", "'both'"),
    csv_case("budget-answers-non-numeric", ("budget", *BUDGET_CHEAP, "--from-sizing"),
             "answers_bad_value.csv", "row 2", "L_m", "'far'"),
    csv_case("budget-answers-nan", ("budget", *BUDGET_CHEAP, "--from-sizing"),
             "answers_nan_value.csv", "row 3", "H_m", "'nan'"),
    csv_case("budget-answers-no-row-for-relation", ("budget", *BUDGET_CHEAP, "--from-sizing"),
             "answers_no_common_row.csv", "common", options=("--relations", "common")),
    csv_case("budget-answers-empty-file", ("budget", *BUDGET_CHEAP, "--from-sizing"),
             "empty.csv", "not a readable CSV"),
]


def _param(case: Case):
    marks = [pytest.mark.xfail(reason=case.defect, strict=True)] if case.defect else []
    return pytest.param(case, id=case.id, marks=marks)


def snapshot(root: Path) -> dict[str, tuple]:
    """Every path under ``root`` (hidden ones too) with its type and mode, and a file's size,
    modification time and content hash."""
    tree: dict[str, tuple] = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            path = Path(dirpath) / name
            rel = path.relative_to(root).as_posix()
            st = path.lstat()
            if stat.S_ISREG(st.st_mode):
                digest = hashlib.sha256(path.read_bytes()).hexdigest()
                tree[rel] = ("file", st.st_mode, st.st_size, st.st_mtime_ns, digest)
            elif stat.S_ISDIR(st.st_mode):
                tree[rel] = ("dir", st.st_mode)
            else:
                tree[rel] = ("other", st.st_mode, os.readlink(path) if path.is_symlink() else "")
    return tree


def prepare(case: Case, work: Path) -> None:
    """Copy the case's input files into ``work`` and create the user's own files and folders."""
    for name in case.files:
        source = DATA / name
        assert source.is_file(), f"manifest names a missing data file: {source}"
        shutil.copy2(source, work / source.name)
    for rel, text in case.setup.items():
        path = work / rel
        if text is None:
            path.mkdir(parents=True, exist_ok=True)
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
    for rel, target in case.links.items():
        (work / rel).symlink_to(target)


def fill(text: str, work: Path) -> str:
    """``text`` with the placeholder ``{tmp}`` replaced by the case's working directory."""
    return text.replace("{tmp}", str(work))


@dataclass
class Outcome:
    """What one run of the command line did."""

    work: Path
    before: dict[str, tuple]
    after: dict[str, tuple] | None = None
    returncode: int | None = None
    stdout: str = ""
    stderr: str = ""
    timed_out: bool = False


def run_case(case: Case, work: Path, cli: ForkedCli) -> Outcome:
    """Run one case in its own fresh working directory ``work`` (its output kept beside it)."""
    work.mkdir(parents=True)
    prepare(case, work)
    outcome = Outcome(work, snapshot(work))
    out, err = work.with_suffix(".stdout"), work.with_suffix(".stderr")
    reply = cli.run([fill(a, work) for a in case.argv], work, out, err, TIMEOUT)
    outcome.returncode, outcome.timed_out = reply["returncode"], reply["timed_out"]
    outcome.stdout, outcome.stderr = out.read_text(), err.read_text()
    outcome.after = snapshot(work)
    return outcome


def run_cases(cases: list[tuple[Case, Path]]) -> dict[str, Outcome]:
    """Run ``cases`` one after another on one server."""
    cli = ForkedCli()
    try:
        return {case.id: run_case(case, work, cli) for case, work in cases}
    finally:
        cli.close()


def _workers() -> int:
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    return max(2, min(8, cores))


def _case_of(item: pytest.Item) -> Case | None:
    callspec = getattr(item, "callspec", None)
    case = callspec.params.get("case") if callspec is not None else None
    return case if isinstance(case, Case) else None


@pytest.fixture(scope="session")
def outcomes(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
             ) -> dict[str, Outcome]:
    """The outcome of every selected case, run a few at a time, each worker a server that
    imports the libraries once (see the module's docstring)."""
    selected = [c for c in map(_case_of, request.session.items) if c is not None]
    root = tmp_path_factory.mktemp("bad_inputs")
    work = [(c, root / f"case{i:03d}") for i, c in enumerate(selected)]
    workers = _workers()
    with ThreadPoolExecutor(max_workers=workers) as pool:
        shares = pool.map(run_cases, [work[k::workers] for k in range(workers)])
        return {case_id: o for share in shares for case_id, o in share.items()}


def test_manifest_is_consistent():
    ids = [c.id for c in CASES]
    assert len(ids) == len(set(ids)), "case ids repeat"
    assert len(CASES) >= 70
    used = {Path(f).name for c in CASES for f in c.files}
    for c in CASES:
        for f in c.files:
            assert (DATA / f).is_file(), f"{c.id}: no such data file {f}"
        for rel in c.unchanged:
            assert rel in c.setup, f"{c.id}: unchanged file {rel} is not made by setup"
    for folder in ("studies", "csv"):
        unused = sorted(p.name for p in (DATA / folder).iterdir()
                        if p.name not in used and not p.name.startswith("valid_"))
        assert not unused, f"data files no case uses: {unused}"


@pytest.mark.parametrize("case", [_param(c) for c in CASES])
def test_bad_input_is_refused(case: Case, outcomes: dict[str, Outcome]):
    o = outcomes[case.id]
    work, before, after = o.work, o.before, o.after
    assert after is not None
    shown = f"exit {o.returncode}; stderr:\n{o.stderr[-3000:]}"
    lines = o.stderr.splitlines()

    assert not o.timed_out, f"no answer within {TIMEOUT} s"
    assert "Traceback" not in o.stderr + o.stdout, shown
    assert o.returncode == 2, shown
    assert len(lines) == 1, shown
    line = lines[0]
    assert line.startswith("error: "), shown
    for word in (fill(w, work) for w in case.expect):
        assert word in line, f"the error line does not name {word!r}: {line}"

    for rel in case.absent:
        assert not (work / rel).exists() and not (work / rel).is_symlink(), \
            f"{rel} exists after a refused run"
    for rel in case.unchanged:
        assert after.get(rel) == before[rel], f"the user's file {rel} was changed"
    leftovers = sorted(rel for rel in after if ".tmp" in Path(rel).name)
    assert not leftovers, f"temporary files left behind: {leftovers}"
    added = sorted(set(after) - set(before))
    removed = sorted(set(before) - set(after))
    changed = sorted(rel for rel in set(before) & set(after) if before[rel] != after[rel])
    assert not (added or removed or changed), \
        f"the working directory changed: added {added}, removed {removed}, changed {changed}"
