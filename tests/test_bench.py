"""`montecarlo bench` runs and reports every figure (no timing is asserted: benchmarks measure,
tests check)."""

import json
import subprocess
import sys

import pytest


@pytest.mark.slow
def test_bench_quick_json_has_every_figure():
    out = subprocess.run([sys.executable, "-m", "montecarlo", "bench", "--quick", "--json",
                          "--repeats", "2"], capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    for key in ("naive_trials_per_s", "reference_trials_per_s", "fast_trials_per_s_1core",
                "fast_trials_per_s_2core", "peak_rss_mb", "stabilization_reference_trials_per_s",
                "stabilization_fast_trials_per_s"):
        assert r[key] > 0, key
    assert r["stabilization_ratio"] == pytest.approx(
        r["stabilization_fast_trials_per_s"] / r["stabilization_reference_trials_per_s"])
    assert [s["trials"] for s in r["scaling"]] == [10**5, 10**6]
    assert r["compile_seconds_cold_cache"] is None  # measured by --full only
    stages = r["roofline"]["stages"]
    assert [s["stage"] for s in stages] == ["draws", "solve", "metrics", "accumulation"]
    for s in stages:
        assert s["ns_per_trial"] > 0 and s["ceiling_ns_per_trial"] > 0
        assert s["fraction"] == pytest.approx(s["ceiling_ns_per_trial"] / s["ns_per_trial"])
    assert r["roofline"]["total_ns_per_trial"] == pytest.approx(
        sum(s["ns_per_trial"] for s in stages), rel=0.2)  # medians of each, not of the sum
    assert "roofline of the fused ground path" in subprocess.run(
        [sys.executable, "-c", "from montecarlo.tools.bench import format_bench; import json, "
         "sys; print(format_bench(json.load(sys.stdin)))"], input=out.stdout,
        capture_output=True, text=True, check=True).stdout
