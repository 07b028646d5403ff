"""What a user must be able to trust: results that never destroy files, verdicts that count
failures, resumes that never mix code, refused nonsense, processes that end with their run."""

import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import psutil
import pytest

from montecarlo.engine import checkpoints as ck
from montecarlo.engine.aggregate import MetricStats
from montecarlo.engine.runner import RunOptions, run_study
from montecarlo.io.files import OutputDir
from montecarlo.systems import load_study
from tests.forked_cli import montecarlo_cli

GROUND = """
[study]
name = "{name}"
system = "ground"
trials = {trials}
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
dx_m = {{ dist = "uniform", bound = 0.1 }}
pixel_px = {{ dist = "normal", sigma = 2.0 }}
pixel_relation = "common"
"""


def study_file(tmp_path, name="t", trials=2000, extra=""):
    p = tmp_path / f"{name}.toml"
    p.write_text(textwrap.dedent(GROUND.format(name=name, trials=trials)) + textwrap.dedent(extra))
    return p


def cli(*args, cwd=None, timeout=120):
    return montecarlo_cli(*args, cwd=cwd, timeout=timeout)


def one_line_exit_2(proc):
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith("error: "), proc.stderr
    assert "Traceback" not in proc.stderr


# --- 1. outputs never replace what they did not write -------------------------------------------


def test_run_out_refuses_a_users_directory_and_a_plain_file(tmp_path):
    study = study_file(tmp_path)
    users = tmp_path / "thesis"
    users.mkdir()
    (users / "chapter1.tex").write_text("years of work")
    plain = tmp_path / "notes.txt"
    plain.write_text("keep me")
    for target in (users, plain):
        one_line_exit_2(cli("run", study, "--out", target, "--quiet"))
    assert (users / "chapter1.tex").read_text() == "years of work"
    assert sorted(p.name for p in users.iterdir()) == ["chapter1.tex"]
    assert plain.read_text() == "keep me"
    assert not list(tmp_path.glob(".*tmp-*"))


def test_run_out_replaces_its_own_earlier_result_but_not_another_studys(tmp_path):
    out = tmp_path / "out"
    assert cli("run", study_file(tmp_path, "a"), "--out", out, "--quiet").returncode == 0
    assert cli("run", study_file(tmp_path, "a"), "--out", out, "--quiet").returncode == 0
    one_line_exit_2(cli("run", study_file(tmp_path, "b"), "--out", out, "--quiet"))
    assert json.loads((out / "provenance.json").read_text())["study"] == "a"


@pytest.mark.parametrize("argv", [
    ["size", "--limit", "3", "--trials", "500", "--levels", "2", "--no-confirm", "--out"],
    ["budget", "--limit", "3", "--samples", "8", "--trials", "500", "--out"],
    ["nightly", "--out"],
    ["collimation", "figures"],
], ids=["size", "budget", "nightly", "figures"])
def test_every_directory_writer_refuses_a_users_directory(tmp_path, argv):
    users = tmp_path / "mine"
    users.mkdir()
    (users / "data.csv").write_text("1,2\n")
    proc = cli(*argv, users, timeout=60)
    one_line_exit_2(proc)
    assert "is not an earlier result of this command" in proc.stderr
    assert sorted(p.name for p in users.iterdir()) == ["data.csv"]


def test_diagnose_report_refuses_a_users_directory_before_any_work(tmp_path):
    data = tmp_path / "d.csv"
    assert cli("synth", "collimation", data).returncode == 0
    users = tmp_path / "mine"
    users.mkdir()
    (users / "x").write_text("x")
    one_line_exit_2(cli("diagnose", "collimation", data, "--angle-sigma-arcsec", "2.8",
                        "--report", users))
    assert sorted(p.name for p in users.iterdir()) == ["x"]


def test_stale_staging_of_a_dead_process_is_removed_a_live_ones_is_kept(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    stale = tmp_path / f".out.tmp-{dead}-abc"
    live = tmp_path / f".out.tmp-{os.getpid()}-def"
    for d in (stale, live):
        d.mkdir()
    with OutputDir(tmp_path / "out", "run") as staging:
        (staging / "f").write_text("x")
    assert not stale.exists() and live.exists() and (tmp_path / "out" / "f").exists()


def test_a_failure_leaves_no_staging_and_the_old_result(tmp_path):
    out = tmp_path / "out"
    with OutputDir(out, "run") as staging:
        (staging / "provenance.json").write_text(json.dumps({"kind": "run"}))
    with pytest.raises(RuntimeError), OutputDir(out, "run") as staging:
        (staging / "half").write_text("x")
        raise RuntimeError
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert sorted(p.name for p in out.iterdir()) == ["provenance.json"]


# --- 2. a verdict counts trials that could not be solved ---------------------------------------


def test_verdict_fails_where_a_third_of_the_trials_have_no_solution(tmp_path):
    """ψ near the edge of the 90° field: at 44.9° a third of the trials put a target outside the
    field. p95 over the solved trials is *lower* there than at 30° (only the lucky trials remain),
    yet the calibration fails a third of the time: the verdict must be 'fails'."""
    study = study_file(tmp_path, trials=20000, extra="""
        [spec]
        metric = "rotation_angle"
        variant = "normalised"
        statistic = "p95"
        limit = 20.0

        [[sweep]]
        "mounting.psi_deg" = [30.0, 44.6, 44.9]
        """)
    out = tmp_path / "out"
    assert cli("run", study, "--out", out, "--quiet").returncode == 0
    s = pd.read_csv(out / "summary.csv")
    rows = s[(s.metric == "rotation_angle") & (s.variant == "normalised")].set_index("point")
    assert rows.loc[2, "invalid_fraction"] > 0.25
    assert rows.loc[2, "p95"] < rows.loc[0, "p95"] < 20.0  # over the solved trials alone
    assert rows["verdict"].tolist() == ["meets", "meets", "fails"]
    assert rows.loc[2, "spec_value"] == np.inf
    assert (s["percentiles_over"] == "valid").all()
    others = s[(s.metric != "rotation_angle") | (s.variant != "normalised")]
    assert others["verdict"].isna().all()
    assert "invalid_fraction" in (out / "report.md").read_text()


# --- 3. resume never mixes code versions or implementations ------------------------------------


def test_checkpoint_key_covers_the_code_and_the_reference_option(tmp_path, monkeypatch):
    study = load_study(study_file(tmp_path))
    fast, reference = ck.Checkpoints(tmp_path, study), ck.Checkpoints(tmp_path, study, True)
    assert fast.dir != reference.dir
    monkeypatch.setattr(ck, "code_fingerprint", lambda: "another version of the code")
    assert ck.Checkpoints(tmp_path, study).dir != fast.dir


def test_code_fingerprint_changes_with_any_module():
    before = ck.code_fingerprint()
    ck.code_fingerprint.cache_clear()
    try:
        assert ck.code_fingerprint() == before
        module = Path(ck.__file__)
        text = module.read_text()
        module.write_text(text + "\n")
        try:
            ck.code_fingerprint.cache_clear()
            assert ck.code_fingerprint() != before
        finally:
            module.write_text(text)
    finally:
        ck.code_fingerprint.cache_clear()


def test_python_api_writes_no_checkpoint_unless_asked(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    study = load_study(study_file(tmp_path))
    run_study(study, RunOptions(n_jobs=1, progress=False))
    run_study(study, RunOptions(n_jobs=1, progress=False))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.toml"]


def test_a_resumed_run_says_so_in_its_provenance(tmp_path):
    study = load_study(study_file(tmp_path, extra='[[sweep]]\n"geometry.L_m" = [50.0, 70.0]\n'))
    options = RunOptions(n_jobs=1, progress=False, checkpoint_dir=tmp_path / "ck")
    first = run_study(study, options)
    assert first.resumed == {}
    again = run_study(study, options)
    assert again.resumed["points"] == [0, 1] and str(tmp_path / "ck") in again.resumed["from"]
    pd.testing.assert_frame_equal(first.to_frame(), again.to_frame())


# --- 4. values that must be refused, and memory that does not grow ------------------------------


@pytest.mark.parametrize(("change", "needle"), [
    (("L_m = 100.0", "L_m = nan"), "geometry.L_m: not a finite number"),
    (("H_m = 2.0", "H_m = inf"), "geometry.H_m: not a finite number"),
    (("L_m = 100.0", "L_m = 1e300"), "geometry.L_m"),
    (("trials = 2000", "trials = 1e15"), "study.trials"),
    (("trials = 2000", "trials = 1000000000000000"), "study.trials"),
    (("bound = 0.1", "bound = nan"), "not a finite number"),
], ids=["nan", "inf", "1e300", "trials-float", "trials-1e15", "nan-source"])
def test_nonsense_values_are_refused(tmp_path, change, needle):
    path = study_file(tmp_path)
    path.write_text(path.read_text().replace(*change))
    proc = cli("run", path, "--quiet")
    one_line_exit_2(proc)
    assert needle in proc.stderr and str(path) in proc.stderr


def test_a_nan_base_value_is_refused_even_when_a_sweep_replaces_it(tmp_path):
    path = study_file(tmp_path, extra='[[sweep]]\n"geometry.L_m" = [50.0, 70.0]\n')
    path.write_text(path.read_text().replace("L_m = 100.0", "L_m = nan"))
    one_line_exit_2(cli("run", path, "--quiet"))


def test_repeated_sweep_points_are_refused(tmp_path):
    proc = cli("run", study_file(tmp_path, extra='[[sweep]]\n"geometry.L_m" = [50.0, 50.0]\n'),
               "--quiet")
    one_line_exit_2(proc)
    assert "points 0 and 1 are the same" in proc.stderr


def test_statistics_keep_only_the_blocks_that_arrived_out_of_order():
    m = MetricStats()
    values = np.random.default_rng(0).random((1000, 10))
    for b in range(1, 1000):  # block 0 late: everything waits for it
        m.add_block(b, values[b])
    assert len(m.pending) == 999
    m.add_block(0, values[0])
    assert not m.pending and m.next_block == 1000 and m.count == 10000
    assert m.mean_std()[0] == pytest.approx(values.mean(), rel=1e-12)


def test_a_huge_study_starts_in_bounded_memory_and_says_how_long_it_would_take(tmp_path):
    """10^12 trials: the tasks are generated as needed, so memory stays flat; the planned trials
    and an estimate of the time left are printed before the run has got anywhere."""
    path = study_file(tmp_path, trials=10**12)
    proc = psutil.Popen([sys.executable, "-m", "montecarlo", "run", str(path), "--n-jobs", "1",
                         "--out", str(tmp_path / "out")], stderr=subprocess.PIPE, text=True,
                        start_new_session=True)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stderr), daemon=True)
    reader.start()
    try:
        peak = 0.0
        # the loop ends at the first estimate; the deadline only bounds a run that never gives
        # one (a fresh clone compiles the kernel first, slowly on a loaded machine)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not any("left at" in line for line in lines):
            tree = [proc, *proc.children(recursive=True)]
            peak = max(peak, sum(p.memory_info().rss for p in tree if p.is_running()) / 2**20)
            time.sleep(0.2)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        reader.join(timeout=10)
        proc.stderr.close()
    text = "".join(lines)
    assert "1,000,000,000,000 trials" in text
    assert "left at" in text
    assert peak < 1500, peak


# --- 5. processes --------------------------------------------------------------------------------


def test_n_jobs_is_capped_at_the_cores(tmp_path):
    proc = cli("run", study_file(tmp_path, trials=500), "--n-jobs", "500", "--quiet",
               "--out", tmp_path / "out")
    assert proc.returncode == 0
    assert f"this machine has {len(os.sched_getaffinity(0))} cores" in proc.stderr


def test_loky_workers_do_not_outlive_a_killed_run(tmp_path):
    path = study_file(tmp_path, trials=10**10)
    proc = subprocess.Popen([sys.executable, "-m", "montecarlo", "run", str(path), "--quiet",
                             "--n-jobs", "2", "--out", str(tmp_path / "out")])
    deadline = time.monotonic() + 60
    workers = []
    while time.monotonic() < deadline and len(workers) < 2:
        workers = [p for p in psutil.Process(proc.pid).children(recursive=True)
                   if "LokyProcess" in " ".join(p.cmdline())]
        time.sleep(0.2)
    assert len(workers) == 2
    os.kill(proc.pid, signal.SIGKILL)  # the parent alone, as a crash or the OOM killer would
    proc.wait()
    _, alive = psutil.wait_procs(workers, timeout=30)
    for p in alive:
        p.kill()
    assert not alive


def test_ctrl_c_ends_with_one_line_that_says_a_rerun_resumes(tmp_path):
    path = study_file(tmp_path, trials=10**7,
                      extra='[[sweep]]\n"geometry.L_m" = [50.0, 70.0, 90.0, 110.0, 130.0]\n')
    out = tmp_path / "runs" / "out"
    # Ctrl-C as a terminal delivers it, also when the tests run as a background job (whose
    # children inherit an ignored SIGINT)
    proc = subprocess.Popen([sys.executable, "-m", "montecarlo", "run", str(path), "--quiet",
                             "--n-jobs", "1", "--out", str(out)],
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    checkpoints = out.parent / ".checkpoints"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not list(checkpoints.glob("*/point-*.pkl")):
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("stopped: ") and "rerun the same command to resume" in err, err
    assert not out.exists() and not list(out.parent.glob(".out.*"))


# --- 6. inputs that used to end in a traceback ---------------------------------------------------


def test_a_directory_given_as_study_or_csv(tmp_path):
    one_line_exit_2(cli("run", tmp_path))
    one_line_exit_2(cli("collimation", "fit", tmp_path))
    one_line_exit_2(cli("diagnose", "ground", tmp_path, "--fov-deg", "90", "90", "--pixels",
                        "512", "512", "--pixel-sigma-px", "0.3"))


@pytest.mark.parametrize("address", ["notanaddress", "http://localhost:8786"])
def test_a_scheduler_that_is_not_an_address(tmp_path, address):
    proc = cli("run", study_file(tmp_path), "--backend", "dask", "--scheduler", address)
    one_line_exit_2(proc)
    assert "not a dask scheduler address" in proc.stderr


def test_a_scheduler_address_where_no_dask_scheduler_answers(tmp_path):
    """A port that speaks something else (here: a server that sends garbage) is refused within
    the connection timeout, not after a silent hang or a 3 EiB allocation."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    port = server.getsockname()[1]

    def serve():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            conn.sendall(b"HTTP/1.1 400 Bad Request\r\n" + b"\xff" * 64)

    threading.Thread(target=serve, daemon=True).start()
    start = time.monotonic()
    proc = cli("run", study_file(tmp_path), "--backend", "dask", "--scheduler",
               f"tcp://127.0.0.1:{port}", timeout=90)
    server.close()
    one_line_exit_2(proc)
    assert "no dask scheduler answers" in proc.stderr
    assert time.monotonic() - start < 60


@pytest.mark.slow
def test_a_dask_run_whose_workers_all_die_says_so_within_a_minute(tmp_path):
    """An external scheduler with one worker (no nanny to restart it); the worker is killed
    mid-run: the run ends with one line saying no worker is left, not a freeze."""
    port = _free_port()
    scheduler = subprocess.Popen([Path(sys.executable).parent / "dask", "scheduler", "--port",
                                  str(port), "--no-dashboard"], stderr=subprocess.DEVNULL)
    worker = None
    try:
        time.sleep(4)
        worker = subprocess.Popen([Path(sys.executable).parent / "dask", "worker",
                                   f"tcp://127.0.0.1:{port}", "--no-nanny", "--nthreads", "1",
                                   "--no-dashboard"], stderr=subprocess.DEVNULL)
        time.sleep(5)
        run = subprocess.Popen([sys.executable, "-m", "montecarlo", "run",
                                str(study_file(tmp_path, trials=10**10)), "--quiet",
                                "--backend", "dask", "--scheduler", f"tcp://127.0.0.1:{port}",
                                "--out", str(tmp_path / "out")], stderr=subprocess.PIPE,
                               text=True)
        time.sleep(10)
        worker.kill()
        killed = time.monotonic()
        _, err = run.communicate(timeout=120)
        assert time.monotonic() - killed < 60
        assert run.returncode == 1 and err.count("\n") == 1, err
        assert "no dask worker" in err and "Traceback" not in err
    finally:
        for p in (worker, scheduler):
            if p is not None:
                p.kill()
                p.wait()


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_unwritable_outputs_are_found_before_any_work(tmp_path):
    data = tmp_path / "c.csv"
    assert cli("collimation", "simulate", data).returncode == 0
    missing = tmp_path / "no" / "such" / "dir" / "fit.json"
    one_line_exit_2(cli("collimation", "fit", data, "--json", missing))
    one_line_exit_2(cli("collimation", "fit", data, "--json", tmp_path))
    one_line_exit_2(cli("diagnose", "collimation", data, "--angle-sigma-arcsec", "2.8",
                        "--json", missing))


@pytest.mark.parametrize("argv", [
    ["air", "--seed", "-1"],
    ["transfer-alignment", "--seed", "-1"],
    ["collimation", "simulate", "{tmp}/c.csv", "--seed", "-1"],
    ["stabilization", "simulate", "{tmp}/s.csv", "--seed", "-1"],
    ["collimation", "simulate", "{tmp}/c.csv", "--n-azimuth", "-3"],
    ["collimation", "simulate", "{tmp}/c.csv", "--n-azimuth", "0", "--n-pitch", "0"],
])
def test_flags_out_of_range(tmp_path, argv):
    one_line_exit_2(cli(*(a.format(tmp=tmp_path) for a in argv)))
    assert not list(tmp_path.iterdir())  # no header-only CSV, nothing at all


# --- 7. CSV checks -------------------------------------------------------------------------------


def _collimation_csv(tmp_path):
    path = tmp_path / "c.csv"
    assert cli("collimation", "simulate", path).returncode == 0
    return path, path.read_text().splitlines()


def test_a_repeated_csv_header_is_refused(tmp_path):
    path, lines = _collimation_csv(tmp_path)
    path.write_text("\n".join([lines[0] + ",ins_el_deg", *(r + ",0" for r in lines[1:])]) + "\n")
    proc = cli("collimation", "fit", path)
    one_line_exit_2(proc)
    assert "'ins_el_deg' appears 2 times" in proc.stderr


@pytest.mark.parametrize(("column", "value"), [("theodolite_el_deg", "91"),
                                               ("ins_az_deg", "400"),
                                               ("theodolite_az_deg", "1e308")])
def test_angles_outside_their_range_are_refused(tmp_path, column, value):
    path, lines = _collimation_csv(tmp_path)
    cells = lines[3].split(",")
    cells[lines[0].split(",").index(column)] = value
    path.write_text("\n".join([*lines[:3], ",".join(cells), *lines[4:]]) + "\n")
    proc = cli("collimation", "fit", path)
    one_line_exit_2(proc)
    assert f"row 4, column '{column}'" in proc.stderr


def test_a_ground_coordinate_of_1e308_is_refused(tmp_path):
    path = tmp_path / "g.csv"
    assert cli("synth", "ground", path).returncode == 0
    lines = path.read_text().splitlines()
    cells = lines[5].split(",")
    cells[1] = "1e308"
    path.write_text("\n".join([*lines[:5], ",".join(cells), *lines[6:]]) + "\n")
    proc = cli("diagnose", "ground", path, "--fov-deg", "90", "90", "--pixels", "512", "512",
               "--pixel-sigma-px", "0.3")
    one_line_exit_2(proc)
    assert "row 6, column 'x_m'" in proc.stderr


# --- 8. dependencies -----------------------------------------------------------------------------


def test_declared_dependencies():
    import tomllib

    project = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())["project"]
    runtime = " ".join(project["dependencies"])
    assert "joblib>=1.5" in runtime  # loky workers' initializer (exit with their parent): 1.5
    assert "scipy>=1.12" in runtime  # stats.quantile_test (a test's reference) is new in 1.12
    assert "statsmodels" not in runtime  # used by a test only
    assert any(d.startswith("statsmodels") for d in project["optional-dependencies"]["dev"])
    assert (Path(__file__).parents[1] / "LICENSE").read_text().startswith("MIT License")


# --- 9. provenance of every command that writes results -----------------------------------------


@pytest.mark.slow
def test_provenance_of_json_outputs(tmp_path):
    data = tmp_path / "c.csv"
    assert cli("collimation", "simulate", data).returncode == 0
    assert cli("collimation", "fit", data, "--json", tmp_path / "f.json").returncode == 0
    record = json.loads((tmp_path / "f.json").read_text())["provenance"]
    assert record["kind"] == "collimation fit" and record["cpu"] and record["code_fingerprint"]
    run = tmp_path / "s.csv"
    assert cli("stabilization", "simulate", run, "--duration", "10").returncode == 0
    est = cli("stabilization", "estimate", run, "--json", "--passes", "1")
    assert json.loads(est.stdout)["provenance"]["kind"] == "stabilization estimate"


def test_provenance_of_a_study_run(tmp_path):
    out = tmp_path / "out"
    assert cli("run", study_file(tmp_path), "--out", out, "--quiet").returncode == 0
    record = json.loads((out / "provenance.json").read_text())
    for key in ("kind", "study", "study_hash", "seed", "package_version", "git_commit",
                "code_fingerprint", "libraries", "cpu", "resolved_study", "run_options"):
        assert key in record, key
    assert record["kind"] == "run" and record["resumed"] is None


# --- 10. tests that would catch the bugs that used to slip through ------------------------------


def test_percentile_rank_at_an_integer_p_times_n():
    """Inverted CDF: for n = 100 and p = 0.95 the estimate is the 95th smallest value, not the
    96th (p n = 95 exactly is where an off-by-one rank rule shows)."""
    values = np.arange(1.0, 101.0)
    m = MetricStats()
    m.add_block(0, values)
    for p, rank in ((0.95, 95), (0.5, 50), (0.99, 99), (0.9, 90)):
        est, _, _ = m.quantile(p, False, 0.95)
        assert est == pytest.approx(rank, rel=2**-10), p
        assert np.percentile(values, 100 * p, method="inverted_cdf") == rank


def test_invalid_counts_agree_between_the_fast_kernel_and_the_reference(tmp_path):
    """A study with trials outside the field (ψ at the edge of a 90° field) through both paths:
    the counts of invalid trials, by reason, and the fraction are the same."""
    study = load_study(study_file(tmp_path, trials=4096, extra="""
        [[sweep]]
        "mounting.psi_deg" = [44.6, 44.9]
        """))
    fast, ref = (run_study(study, RunOptions(n_jobs=1, progress=False, reference=r)).to_frame()
                 for r in (False, True))
    cols = ["point", "variant", "metric", "trials", "count", "invalid", "invalid_fraction",
            *(c for c in fast.columns if c.startswith("invalid_") and c != "invalid_fraction")]
    assert (fast["invalid"] > 0).all()
    pd.testing.assert_frame_equal(fast[cols], ref[cols])


def test_asymmetric_field_of_view_reaches_the_model_unswapped(tmp_path):
    """fov [60, 40] deg, pixels [640, 480] through a study file: every worst-case corner equals
    the literal solver run with Camera(60°, 40°, 640, 480) directly (a swap would differ)."""
    from montecarlo.geometry.camera import Camera
    from montecarlo.seed000 import ground

    path = tmp_path / "asym.toml"
    path.write_text(textwrap.dedent("""
        [study]
        name = "asym"
        system = "ground"
        trials = 1
        seed = 1
        per_trial = true
        [sensor]
        fov_deg = [60.0, 40.0]
        pixels = [640, 480]
        [mounting]
        psi_deg = 20.0
        theta_deg = 12.0
        gamma_deg = 5.0
        [geometry]
        L_m = 80.0
        H_m = 1.5
        [errors]
        evaluation = "worst_case"
        dx_m = { dist = "corners", bound = 0.1 }
        pixel_px = { dist = "corners", bound = 0.7 }
        pixel_relation = "independent"
        """))
    study = load_study(path)
    trials = run_study(study, RunOptions(n_jobs=1, progress=False)).trials[0]
    system = study.system
    prepared = study.points[0].prepared
    true, e = system.draws(prepared, None, 0, trials.shape[0])
    camera = Camera.from_degrees(60.0, 40.0, 640, 480)
    solved = ground.simulate(camera, true, 80.0, 1.5, dx=e[0], dy=e[1], dh1=e[2], dh=e[3],
                             pixel_error_a=e[4:6].T, pixel_error_b=e[6:8].T)
    expected = ground.solution_metrics(solved["normalised"], true)["rotation_angle"]
    np.testing.assert_allclose(trials["normalised/rotation_angle"], expected, rtol=0, atol=1e-15)
    swapped = Camera.from_degrees(40.0, 60.0, 480, 640)
    other = ground.solution_metrics(ground.simulate(
        swapped, true, 80.0, 1.5, dx=e[0], dy=e[1], dh1=e[2], dh=e[3], pixel_error_a=e[4:6].T,
        pixel_error_b=e[6:8].T)["normalised"], true)["rotation_angle"]
    assert not np.allclose(other, expected)  # a swap would be seen


def test_summary_values_are_in_the_unit_they_are_labelled_with(tmp_path):
    """mrad in the summary = 1000 x rad of the per-trial values (checked on mean and max)."""
    path = study_file(tmp_path, trials=3000)
    path.write_text(path.read_text().replace("seed = 1", "seed = 1\nper_trial = true"))
    result = run_study(load_study(path), RunOptions(n_jobs=1, progress=False))
    row = result.to_frame().set_index(["variant", "metric"]).loc[("raw", "rotation_angle")]
    values = result.trials[0]["raw/rotation_angle"].to_numpy()
    assert row["unit"] == "mrad"
    assert row["max"] == pytest.approx(1e3 * np.nanmax(values), rel=1e-12)
    assert row["mean"] == pytest.approx(1e3 * np.nanmean(values), rel=1e-9)
    axis = result.to_frame().set_index(["variant", "metric"]).loc[("raw", "delta_psi")]
    assert axis["max"] == pytest.approx(
        1e3 * np.nanmax(np.abs(result.trials[0]["raw/delta_psi"])), rel=1e-12)
