"""`montecarlo bench` runs and reports every figure (no timing is asserted: benchmarks measure,
tests check)."""

import json
import subprocess
import sys

import pytest

from montecarlo.engine.runner import available_cores


@pytest.mark.slow
def test_bench_quick_json_has_every_figure():
    out = subprocess.run([sys.executable, "-m", "montecarlo", "bench", "--quick", "--json",
                          "--repeats", "2"], capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    rates = ("naive_trials_per_s", "reference_trials_per_s", "fast_trials_per_s_1core",
             "fast_trials_per_s_2core", "stabilization_reference_trials_per_s",
             "stabilization_fast_trials_per_s")
    for key in rates:  # measured: a positive, finite rate (no timing is asserted)
        assert 0 < r[key] < float("inf"), key
    # each ratio is the quotient of the figures it names
    for ratio, top, bottom in (
            ("ratio_2core_to_naive", "fast_trials_per_s_2core", "naive_trials_per_s"),
            ("ratio_1core_to_reference", "fast_trials_per_s_1core", "reference_trials_per_s"),
            ("ratio_2core_to_1core", "fast_trials_per_s_2core", "fast_trials_per_s_1core"),
            ("stabilization_ratio", "stabilization_fast_trials_per_s",
             "stabilization_reference_trials_per_s")):
        assert r[ratio] == pytest.approx(r[top] / r[bottom], rel=1e-12), ratio
    # (d) is the largest run of the scaling series; 10^6 trials stay in the calling process,
    # 10^7 go to the workers, both on the fused kernel
    assert [s["trials"] for s in r["scaling"]] == [10**6, 10**7]
    assert r["fast_trials_per_s_2core"] == r["scaling"][-1]["trials_per_s"]
    cores = available_cores()  # the runner's default --n-jobs
    assert [(s["kernel"], s["workers"]) for s in r["scaling"]] == [
        ("fast", 0), ("fast", cores if cores > 1 else 0)]
    # memory: the polled peak of the 10^6-trial study; a process that imported numpy, pandas
    # and numba holds more than 50 MB (0 would mean it was never seen running)
    assert set(r["memory_by_trials"]) == {str(10**6)}
    big = r["memory_by_trials"][str(r["peak_memory_trials"])]
    assert r["peak_rss_mb"] == big["max_process_rss_mb"] > 50.0
    assert big["tree_rss_mb"] >= big["max_process_rss_mb"]
    assert big["tree_pss_mb"] <= big["tree_rss_mb"]
    assert r["compile_seconds_cold_cache"] is None  # measured by --full only
    # the camera diagnosis on Zhang's data at 0.25 px, measured once; it names k1 first
    [zhang] = r["camera_diagnoses"]
    assert zhang["pixel_sigma_px"] == "0.25" and zhang["named"][0] == "radial_k1"
    assert 0 < zhang["wall_s"] < float("inf") and 0 < zhang["cpu_s"] < float("inf")
    assert len(r["host_probe_atan2_per_s"]) == 2 and min(r["host_probe_atan2_per_s"]) > 0
    stages = r["roofline"]["stages"]
    assert [s["stage"] for s in stages] == ["draws", "solve", "metrics", "accumulation"]
    for s in stages:
        assert s["ns_per_trial"] > 0 and s["ceiling_ns_per_trial"] > 0
        assert s["fraction"] == pytest.approx(s["ceiling_ns_per_trial"] / s["ns_per_trial"])
        # the binding ceiling is the larger of the stage's ceilings
        assert s["bound_ns_per_trial"] >= s["ceiling_ns_per_trial"]
        assert s["bound_fraction"] == pytest.approx(s["bound_ns_per_trial"] / s["ns_per_trial"])
    assert r["roofline"]["total_ns_per_trial"] == pytest.approx(
        sum(s["ns_per_trial"] for s in stages), rel=0.2)  # medians of each, not of the sum
    floor = r["roofline"]["floor_ns_per_trial"]
    assert floor == pytest.approx(sum(s["bound_ns_per_trial"] for s in stages), rel=1e-12)
    assert r["roofline"]["floor_speedup"] == pytest.approx(
        r["roofline"]["total_ns_per_trial"] / floor, rel=1e-12)
    assert "every stage at its binding ceiling" in subprocess.run(
        [sys.executable, "-c", "from montecarlo.tools.bench import format_bench; import json, "
         "sys; print(format_bench(json.load(sys.stdin)))"], input=out.stdout,
        capture_output=True, text=True, check=True).stdout
