"""The rules of ``compare_runs`` on small results written by hand: which rows are exact, the
relative tolerance of a paired comparison, the width of an independent interval for each
statistic (scipy's normal quantile as the reference), the verdicts, and the refusals of
``load_run`` and ``compare_runs``. No study is run."""

import json
import math
import re

import numpy as np
import pandas as pd
import pytest
from scipy.stats import norm

from montecarlo.errors import InputError
from montecarlo.output.compare import Run, compare_runs, load_run, paired, verdict_counts


def _run(tag, values, *, stat="p95", std=1.0, count=100, sampling="random", confidence=0.95,
         name="hand", L=None, lo=None, hi=None, path="x"):
    """A result with one row per value (grid key ``geometry.L_m``), ``tag`` as study hash."""
    m = len(values)
    summary = pd.DataFrame({
        "point": range(m), "geometry.L_m": L if L is not None else [10.0 * (i + 1)
                                                                   for i in range(m)],
        "variant": "raw", "metric": "rotation_angle", "unit": "mrad",
        "sampling": sampling, "count": count, "std": std, stat: values})
    if lo is not None:
        summary[f"{stat}_lo"], summary[f"{stat}_hi"] = lo, hi
    prov = {"kind": "run", "study": name, "study_hash": tag,
            "resolved_study": {"study": {"confidence": confidence}}}
    return Run(path, summary, prov)


def test_paired_rows_are_exact_and_judged_on_the_relative_tolerance():
    """Same study hash: the difference is exact (interval of zero width), 'same' within
    rtol max(|a|, |b|), otherwise the smaller magnitude is better. Row 3: 4 - 2^-18 against 4
    with rtol 2^-20 is exactly at the tolerance 2^-20 * 4 (binary, no rounding): same. Row 4:
    -3.5 against -3 is larger in magnitude: worse although the difference is negative."""
    a = _run("h", [1.0, 1.0, 2.0, 4.0, -3.0, 0.0], stat="mean")
    b = _run("h", [1.0 + 2.0 ** -22, 1.0 + 2.0 ** -19, 1.5, 4.0 - 2.0 ** -18, -3.5, 0.5],
             stat="mean")
    assert paired(a, b)
    t = compare_runs(a, b, "mean", rtol=2.0 ** -20)
    assert list(t["verdict"]) == ["same", "worse", "better", "same", "worse", "worse"]
    assert set(t["comparison"]) == {"paired"} and set(t["statistic"]) == {"mean"}
    np.testing.assert_array_equal(t["diff"], [2.0 ** -22, 2.0 ** -19, -0.5, -2.0 ** -18, -0.5,
                                              0.5])
    np.testing.assert_array_equal(t["diff_lo"], t["diff"])
    np.testing.assert_array_equal(t["diff_hi"], t["diff"])
    np.testing.assert_allclose(t["rel_diff"][:5], [2.0 ** -22, 2.0 ** -19, -0.25, -2.0 ** -20,
                                                   -0.5 / 3.0], rtol=1e-15)
    assert math.isnan(t["rel_diff"][5])  # a = 0: no relative difference
    assert list(t["a"]) == [1.0, 1.0, 2.0, 4.0, -3.0, 0.0]
    assert list(t["point"]) == list(range(6)) and set(t["unit"]) == {"mrad"}
    # the tolerance is relative to the larger magnitude: 1 against 3 at rtol 0.7 is within
    # 0.7 * 3 = 2.1, not within 0.7 * 1
    one = compare_runs(_run("h", [1.0], stat="mean"), _run("h", [3.0], stat="mean"), "mean",
                       rtol=0.7)
    assert list(one["verdict"]) == ["same"]
    assert list(compare_runs(_run("h", [3.0], stat="mean"), _run("h", [1.0], stat="mean"),
                             "mean", rtol=0.7)["verdict"]) == ["same"]
    # the default tolerance is 1e-9
    default = compare_runs(_run("h", [1.0, 1.0], stat="mean"),
                           _run("h", [1.0 + 5e-10, 1.0 + 2e-9], stat="mean"), "mean")
    assert list(default["verdict"]) == ["same", "worse"]


def test_enumerated_rows_of_both_runs_are_exact_the_others_count_for_bonferroni():
    """Different hashes: rows enumerated in both runs are exact; a row enumerated in one run
    only is independent. The simultaneous half-width counts the independent rows only: m = 2
    here, z = Phi^-1(1 - 0.05 / 4); se of a mean = s / sqrt(n) per run."""
    sampling_a = ["enumerated", "enumerated", "random"]
    sampling_b = ["enumerated", "random", "random"]
    a = _run("a", [1.0, 1.0, 1.0], stat="mean", sampling=sampling_a, std=2.0, count=400)
    b = _run("b", [1.0, 1.0, 1.0], stat="mean", sampling=sampling_b, std=2.0, count=400)
    assert not paired(a, b)
    t = compare_runs(a, b, "mean")
    assert list(t["comparison"]) == ["paired", "independent", "independent"]
    assert list(t["verdict"]) == ["same", "same", "same"]
    half = norm.ppf(1 - 0.05 / 4) * math.sqrt(2.0) * 2.0 / 20.0
    np.testing.assert_allclose(t["diff_hi"][1:], half, rtol=1e-12)
    np.testing.assert_allclose(t["diff_lo"][1:], -half, rtol=1e-12)
    assert t["diff_lo"][0] == t["diff_hi"][0] == 0.0


def test_a_percentile_interval_is_read_at_the_studys_confidence():
    """A percentile's interval [lo, hi] at confidence c is +-z se with z = Phi^-1(0.5 + c/2);
    with one row (no Bonferroni factor) the difference's half-width is then
    sqrt(w_a^2 + w_b^2) / 2 whatever c: widths 0.6 and 0.8 give 0.5. With three rows at
    c = 0.9 it is Phi^-1(1 - 0.1/6) / Phi^-1(0.95) times that."""
    kw = {"stat": "p95", "confidence": 0.9}
    a = _run("a", [2.0], lo=[1.7], hi=[2.3], **kw)
    b = _run("b", [3.0], lo=[2.6], hi=[3.4], **kw)
    t = compare_runs(a, b, "p95")
    assert t["diff_hi"][0] - t["diff"][0] == pytest.approx(0.5, rel=1e-12)
    assert t["diff"][0] - t["diff_lo"][0] == pytest.approx(0.5, rel=1e-12)
    assert list(t["verdict"]) == ["worse"]  # 1 +- 0.5 excludes zero
    assert list(compare_runs(b, a, "p95")["verdict"]) == ["better"]
    a3 = _run("a", [2.0] * 3, lo=[1.7] * 3, hi=[2.3] * 3, **kw)
    b3 = _run("b", [3.0] * 3, lo=[2.6] * 3, hi=[3.4] * 3, **kw)
    t3 = compare_runs(a3, b3, "p95")
    factor = norm.ppf(1 - 0.1 / 6) / norm.ppf(0.95)
    np.testing.assert_allclose(t3["diff_hi"] - t3["diff"], 0.5 * factor, rtol=1e-12)
    # a study without a stated confidence is read at 0.95
    del a3.provenance["resolved_study"]["study"]["confidence"]
    t95 = compare_runs(a3, b3, "p95")
    np.testing.assert_allclose(t95["diff_hi"] - t95["diff"],
                               0.5 * norm.ppf(1 - 0.05 / 6) / norm.ppf(0.975), rtol=1e-12)


def test_interval_verdicts_at_their_ends_and_without_an_interval():
    """Independent runs: 'same' when the interval contains zero, its ends included; 'better'
    or 'worse' by magnitude when it excludes it; 'undecided' without an interval (max, or a
    missing value on one side); two missing values are 'same'. Mean, s = 1, n = 1: se =
    sqrt(2), so a difference of exactly z sqrt(2) (m = 5 rows) puts an end at zero."""
    z = norm.ppf(1 - 0.05 / 10)
    edge = z * math.sqrt(2.0)
    a = _run("a", [0.0, 0.0, 0.0, -1.0, 1.0], stat="mean", count=1)
    b = _run("b", [edge, 2 * edge, -2 * edge, -1.0 - 2 * edge, 1.0], stat="mean", count=1)
    t = compare_runs(a, b, "mean")
    assert t["diff_lo"][0] == pytest.approx(0.0, abs=1e-12)
    assert list(t["verdict"][1:]) == ["worse", "worse", "worse", "same"]
    # at the end itself the verdict turns on the sign of a rounding error: test it exactly
    a1 = _run("a", [0.0], stat="mean", count=4, std=1.0)
    b1 = _run("b", [2.0], stat="mean", count=4, std=1.0)
    t1 = compare_runs(a1, b1, "mean")
    assert list(t1["verdict"]) == ["worse"]  # 2 - 1.96 * sqrt(1/4 + 1/4) = 0.614 > 0
    nan = _run("a", [np.nan, np.nan, 1.0], stat="mean")
    other = _run("b", [np.nan, 1.0, np.nan], stat="mean")
    assert list(compare_runs(nan, other, "mean")["verdict"]) == ["same", "undecided",
                                                                  "undecided"]
    maxima = compare_runs(_run("a", [1.0], stat="max"), _run("b", [9.0], stat="max"), "max")
    assert list(maxima["verdict"]) == ["undecided"]
    assert np.isnan(maxima["diff_lo"][0]) and np.isnan(maxima["diff_hi"][0])
    assert list(compare_runs(_run("h", [1.0], stat="max"), _run("h", [9.0], stat="max"),
                             "max")["verdict"]) == ["worse"]


def test_an_interval_end_exactly_at_zero_is_same():
    """lo = 0 exactly: percentile runs with widths 6 and 8 at one row give a half-width of
    sqrt(36 + 64) / 2 = 5 (exact in floating point), and a difference of 5."""
    a = _run("a", [0.0], lo=[-3.0], hi=[3.0])
    b = _run("b", [5.0], lo=[1.0], hi=[9.0])
    t = compare_runs(a, b, "p95")
    assert t["diff_lo"][0] == 0.0
    assert list(t["verdict"]) == ["same"]
    t = compare_runs(b, a, "p95")
    assert t["diff_hi"][0] == 0.0
    assert list(t["verdict"]) == ["same"]


def test_the_standard_error_of_std_with_one_and_two_trials():
    """se(s) = s / sqrt(2 (n - 1)): n = 2 and s = 1 give 1/sqrt(2) per run, 1 combined, so the
    half-width is z = 1.95996; n = 1 has no spread (infinite interval: same)."""
    t = compare_runs(_run("a", [1.0], stat="std", count=2), _run("b", [1.0], stat="std",
                                                                  count=2), "std")
    assert t["diff_hi"][0] == pytest.approx(norm.ppf(0.975), rel=1e-12)
    one = compare_runs(_run("a", [1.0], stat="std", count=1), _run("b", [50.0], stat="std",
                                                                    count=1), "std")
    assert one["diff_hi"][0] == np.inf and list(one["verdict"]) == ["same"]


def test_grids_must_match_unless_allowed_and_then_rows_match_on_the_sweep_values():
    a = _run("a", [1.0, 2.0, 3.0], stat="mean", L=[10.0, 20.0, 30.0])
    b = _run("b", [1.0, 2.0], stat="mean", L=[20.0, 30.0])
    with pytest.raises(InputError, match=r"x and x are results of different studies "
                                         r"\(hand and hand, or different grids\); add "
                                         r"--allow-different"):
        compare_runs(a, b, "mean")
    t = compare_runs(a, b, "mean", allow_different=True)
    assert list(t["geometry.L_m"]) == [20.0, 30.0] and list(t["point"]) == [1, 2]
    np.testing.assert_array_equal(t["diff"], [-1.0, -1.0])
    renamed = _run("b", [1.0, 2.0, 3.0], stat="mean", name="other")
    with pytest.raises(InputError, match="hand and other"):
        compare_runs(a, renamed, "mean")
    assert len(compare_runs(a, renamed, "mean", allow_different=True)) == 3
    same_grid = _run("b", [5.0, 6.0, 7.0], stat="mean", L=[10.0, 20.0, 30.0])
    assert len(compare_runs(a, same_grid, "mean")) == 3
    shifted = _run("b", [5.0, 6.0, 7.0], stat="mean", L=[10.0, 20.0, 31.0])
    with pytest.raises(InputError, match="different studies"):
        compare_runs(a, shifted, "mean")
    disjoint = _run("b", [1.0], stat="mean", L=[99.0])
    with pytest.raises(InputError, match=r"^x and x have no grid point in common$"):
        compare_runs(a, disjoint, "mean", allow_different=True)
    with pytest.raises(InputError, match=r"^--statistic: 'p42' is not one of mean, std, p50, "
                                         r"p90, p95, p99, cvar95, max$"):
        compare_runs(a, a, "p42")


def test_the_superquantile_interval_is_read_like_a_percentiles():
    """cvar95 carries its interval as cvar95_lo/_hi (normal, widened by the bin bounds): at
    c = 0.95 with one row, widths 0.2 and 0.4 (asymmetric about the estimate) give the
    difference a half-width sqrt(0.2^2 + 0.4^2) / 2 = sqrt(0.05) about the difference of the
    estimates, 0.45 - 0.3 = 0.15: the interval [-0.0736, 0.3736] holds zero, so 'same'."""
    a = _run("a", [0.3], stat="cvar95", lo=[0.25], hi=[0.45])
    b = _run("b", [0.45], stat="cvar95", lo=[0.3], hi=[0.7])
    t = compare_runs(a, b, "cvar95")
    assert t["diff"][0] == pytest.approx(0.15, rel=1e-12)
    assert t["diff_hi"][0] - t["diff"][0] == pytest.approx(math.sqrt(0.05), rel=1e-12)
    assert t["diff"][0] - t["diff_lo"][0] == pytest.approx(math.sqrt(0.05), rel=1e-12)
    assert list(t["verdict"]) == ["same"] and set(t["statistic"]) == {"cvar95"}


def test_a_run_knows_its_name_and_sweep_keys():
    run = _run("a", [1.0], stat="mean")
    assert run.name == "hand" and run.sweep_keys == ["geometry.L_m"]
    assert Run("x", run.summary, {}).name == "None"


def test_load_run_reads_a_result_and_refuses_anything_else_in_one_line(tmp_path):
    good = tmp_path / "good"
    good.mkdir()
    summary = _run("a", [1.0], stat="mean").summary
    summary.to_parquet(good / "summary.parquet")
    (good / "provenance.json").write_text(json.dumps({"kind": "run", "study": "s",
                                                      "study_hash": "h"}))
    run = load_run(str(good))
    assert run.path == good and run.name == "s" and run.provenance["study_hash"] == "h"
    pd.testing.assert_frame_equal(run.summary, summary)

    def line(path, text):
        return "^" + re.escape(f"{path}: {text}") + "$"

    with pytest.raises(InputError, match=line(tmp_path / "nothing", "no such result directory")):
        load_run(tmp_path / "nothing")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(InputError, match=line(empty, "no readable provenance.json; not a result "
                                                     "of `montecarlo run`")):
        load_run(empty)
    (empty / "provenance.json").write_text("{not json")
    with pytest.raises(InputError, match=r"no readable provenance\.json"):
        load_run(empty)
    (empty / "provenance.json").write_text(json.dumps({"kind": "plan"}))
    with pytest.raises(InputError, match=line(empty, "a result of `montecarlo plan`, not of "
                                                     "`montecarlo run`")):
        load_run(empty)
    (empty / "provenance.json").write_text("[1, 2]")  # JSON, but not an object
    with pytest.raises(InputError, match=line(empty / "provenance.json", "not a JSON object; "
                                              "not a result of `montecarlo run`")):
        load_run(empty)
    (empty / "provenance.json").write_text(json.dumps({"kind": "run"}))
    with pytest.raises(InputError, match=r"provenance\.json: study: missing"):
        load_run(empty)
    (empty / "provenance.json").write_text(json.dumps({"kind": "run", "study": "s",
                                                       "study_hash": "h"}))
    with pytest.raises(InputError, match=line(empty / "summary.parquet",
                                              "missing from the result directory")):
        load_run(empty)
    (empty / "summary.parquet").write_text("not parquet")
    with pytest.raises(InputError, match=r"summary\.parquet: not a readable parquet file"):
        load_run(empty)


def test_verdict_counts_every_verdict_also_those_absent():
    table = pd.DataFrame({"verdict": ["same", "worse", "same", "undecided"]})
    assert verdict_counts(table) == {"same": 2, "better": 0, "worse": 1, "undecided": 1}


def test_the_default_statistic_is_the_p95_and_the_columns_are_the_documented_ones():
    a = _run("h", [1.0, 0.0], lo=[0.5, -1.0], hi=[1.5, 1.0])
    b = _run("h", [2.0, 0.0], lo=[1.5, -1.0], hi=[2.5, 1.0])
    t = compare_runs(a, b)
    assert set(t["statistic"]) == {"p95"}
    assert list(t.columns) == ["point", "geometry.L_m", "variant", "metric", "unit",
                               "statistic", "a", "b", "diff", "diff_lo", "diff_hi", "rel_diff",
                               "comparison", "verdict"]
    assert list(t["b"]) == [2.0, 0.0] and list(t.index) == [0, 1]
    # 0 against 0: no relative difference, and no 0/0 warning (warnings are errors here)
    assert math.isnan(t["rel_diff"][1]) and t["verdict"][1] == "same"


def test_a_provenance_without_the_resolved_study_is_read_at_95_percent():
    """Half-width of one row of widths 6 and 8 is 5 whatever the confidence (both the runs'
    own z and the simultaneous z are the same at m = 1), so the provenance has to lack the
    block for the default to be seen: with 3 rows the half-width is 5 z_3 / z_1 at 0.95."""
    kw = {"lo": [-3.0] * 3, "hi": [3.0] * 3}
    a, b = _run("a", [0.0] * 3, **kw), _run("b", [1.0] * 3, lo=[-3.0] * 3, hi=[5.0] * 3)
    for prov in ({"kind": "run", "study": "hand", "study_hash": "a"},
                 {"kind": "run", "study": "hand", "study_hash": "a", "resolved_study": {}}):
        t = compare_runs(Run("x", a.summary, prov), b, "p95")
        np.testing.assert_allclose(t["diff_hi"] - t["diff"],
                                   5.0 * norm.ppf(1 - 0.05 / 6) / norm.ppf(0.975), rtol=1e-12)


def test_a_standard_error_of_zero_over_zero_is_undecided_without_a_warning():
    """The std of one trial (std 0, n - 1 = 0) and a mean of no trials (std 0, n = 0): the
    standard error 0/0 is not a number and the row undecided; warnings are errors here."""
    for stat, count, value in (("std", 1, 0.0), ("mean", 0, 1.0)):
        t = compare_runs(_run("a", [value], stat=stat, count=count, std=0.0),
                         _run("b", [value], stat=stat, count=count, std=0.0), stat)
        assert list(t["verdict"]) == ["undecided"], stat
