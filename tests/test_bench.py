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
    assert [s["trials"] for s in r["scaling"]] == [10**4, 10**5, 10**6]
    assert r["compile_seconds_cold_cache"] > 0
