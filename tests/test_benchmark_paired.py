"""Paired comparison of benchmark variants: `paired_differences`, the report and `physpose compare`."""

from __future__ import annotations

import json
import math

import pytest

from physpose.benchmark.material import MaterialConfig
from physpose.benchmark.paired import merge_results, paired_differences, run_labels
from physpose.benchmark.report import render_markdown, write_results
from physpose.benchmark.runner import BenchmarkConfig, results_document
from physpose.benchmark.scoring import TRUTH_ROW
from physpose.cli import main
from physpose.errors import PhysposeError


def _record(variant: str, clip: str, kind: str = "mocap", **metrics) -> dict:
    return {"variant": variant, "kind": kind, "clip": clip, "source": f"{clip}.bvh", "frames": 10,
            "fps": 25.0, "metrics": metrics, "ground": {}, "time_s": {"variant": 1.0}}


def _results() -> list[dict]:
    """Three clips: the variant's MPJPE-G is the base's + 1, + 2 and + 6 mm."""
    rows = []
    for clip, base_g, diff in (("a", 100.0, 1.0), ("b", 120.0, 2.0), ("c", 140.0, 6.0)):
        rows.append(_record(TRUTH_ROW, clip, foot_skate_pct=0.0))
        rows.append(_record("base", clip, mpjpe_g_mm=base_g, foot_skate_pct=4.0))
        rows.append(_record("new", clip, mpjpe_g_mm=base_g + diff, foot_skate_pct=2.0))
    return rows


def test_per_clip_differences_give_their_mean_and_standard_error():
    paired = paired_differences(_results(), "base")
    assert list(paired) == ["mocap"] and list(paired["mocap"]) == ["new"]  # no truth row
    g = paired["mocap"]["new"]["mpjpe_g_mm"]
    diffs = [1.0, 2.0, 6.0]
    sd = math.sqrt(sum((d - 3.0) ** 2 for d in diffs) / 2)
    assert g["clips"] == 3 and g["base"] == pytest.approx(120.0)
    assert g["variant"] == pytest.approx(123.0) and g["difference"] == pytest.approx(3.0)
    assert g["standard_error"] == pytest.approx(sd / math.sqrt(3))
    skate = paired["mocap"]["new"]["foot_skate_pct"]
    assert skate["difference"] == pytest.approx(-2.0) and skate["standard_error"] == 0.0


def test_only_clips_with_finite_figures_on_both_sides_are_paired():
    rows = _results()
    rows[2]["metrics"]["mpjpe_g_mm"] = float("nan")          # clip a: the variant failed a figure
    rows = [r for r in rows if not (r["clip"] == "c" and r["variant"] == "base")]  # c: no base
    g = paired_differences(rows, "base")["mocap"]["new"]["mpjpe_g_mm"]
    assert g["clips"] == 1 and g["difference"] == pytest.approx(2.0)
    assert g["standard_error"] is None                        # one clip: no spread to measure


def test_videos_are_paired_on_the_figures_they_have():
    rows = [_record("base", "v", "video", mpjpe_2d_px=10.0, mpjpe_g_mm=5.0),
            _record("new", "v", "video", mpjpe_2d_px=12.0, mpjpe_g_mm=9.0)]
    figures = paired_differences(rows, "base")["video"]["new"]
    assert set(figures) == {"mpjpe_2d_px"}                    # no 3d error without a truth


def test_the_results_pair_every_variant_against_the_first_and_report_it(tmp_path):
    results = _results()
    doc = results_document(results, [], BenchmarkConfig(variants=("base", "new")))
    assert doc["paired_against"] == "base"
    assert doc["paired"]["mocap"]["new"]["mpjpe_g_mm"]["difference"] == pytest.approx(3.0)
    md = render_markdown(doc)
    assert "## Paired against `base`: Motion capture" in md
    assert "| new | 3 | 120 -> 123 (+3.0 +- 1.5) |" in md
    json_path, _ = write_results(doc, tmp_path)
    assert json.loads(json_path.read_text())["paired_against"] == "base"
    single = results_document(results, [], BenchmarkConfig(variants=("base",)))
    assert single["paired"] == {} and "Paired against" not in render_markdown(single)
    chosen = results_document(results, [], BenchmarkConfig(variants=("new", "base"),
                                                            paired_against="base"))
    assert list(chosen["paired"]["mocap"]) == ["new"]


def test_the_base_must_be_among_the_variants_run(tmp_path, capsys):
    with pytest.raises(PhysposeError, match="not among the variants run"):
        BenchmarkConfig(variants=("a", "b"), paired_against="c")
    assert main(["benchmark", "--variant", "baseline", "--variant", "SO", "--paired-against",
                 "SO+GT", "--mocap", str(tmp_path / "x.bvh"), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err        # refused before the (missing) material is looked at
    assert "'SO+GT' is not among the variants run" in err and "--variant" in err


def _run(tmp_path, name: str, variants: tuple[str, ...], results: list[dict]):
    doc = results_document(results, [], BenchmarkConfig(variants=variants))
    return write_results(doc, tmp_path / name)[0]


def test_compare_pairs_variants_across_runs(tmp_path, capsys):
    rows = _results()
    old = _run(tmp_path, "old", ("base",), [r for r in rows if r["variant"] != "new"])
    new = _run(tmp_path, "new", ("new",), [r for r in rows if r["variant"] == "new"])
    assert main(["compare", str(old), str(new.parent), "--base", "base",
                 "--out", str(tmp_path / "cmp.md")]) == 0
    out = capsys.readouterr().out
    assert "| new | 3 | 120 -> 123 (+3.0 +- 1.5) |" in out
    assert "(+3.0 +- 1.5)" in (tmp_path / "cmp.md").read_text()
    assert main(["compare", str(old), str(new), "--base", "base",
                 "--out", str(tmp_path / "cmp.json")]) == 0
    saved = json.loads((tmp_path / "cmp.json").read_text())
    assert saved["paired"]["mocap"]["new"]["mpjpe_g_mm"]["clips"] == 3


def test_compare_errors_name_the_file_and_the_remedy(tmp_path, capsys):
    run = _run(tmp_path, "run", ("base", "new"), _results())
    assert main(["compare", str(run), "--base", "nope"]) == 2
    err = capsys.readouterr().err
    assert str(run) in err and "choose from: base, new" in err
    assert main(["compare", str(tmp_path / "missing"), "--base", "base"]) == 2
    assert "benchmark results not found" in capsys.readouterr().err
    assert main(["compare", str(run), "--base", "base", "--out", str(tmp_path)]) == 2
    assert "--out is a folder; it names the file to write" in capsys.readouterr().err
    junk = tmp_path / "junk.json"
    junk.write_text("{not json")
    assert main(["compare", str(junk), "--base", "base"]) == 2
    assert "not a benchmark results file" in capsys.readouterr().err
    junk.write_text(json.dumps({"results": [{"variant": "base"}]}))  # a record without its clip
    assert main(["compare", str(junk), "--base", "base"]) == 2
    assert "not a benchmark results file" in capsys.readouterr().err
    record = {"kind": "mocap", "clip": "a", "variant": "base", "metrics": {}}
    for broken in ({"metrics": [1, 2]}, {"variant": 1}, {"clip": ["a"]}):
        junk.write_text(json.dumps({"results": [dict(record, **broken)]}))
        assert main(["compare", str(junk), "--base", "base"]) == 2
        err = capsys.readouterr().err
        assert "not a benchmark results file" in err and "Traceback" not in err
    junk.write_text(json.dumps({"results": [record], "config": "hello"}))
    assert main(["compare", str(junk), "--base", "base"]) == 2
    assert "its config is not an object" in capsys.readouterr().err
    junk.write_text(json.dumps({"results": []}))
    assert main(["compare", str(junk), "--base", "base"]) == 2
    assert "holds no results" in capsys.readouterr().err
    only = _run(tmp_path, "only", ("base",), [r for r in _results() if r["variant"] != "new"])
    assert main(["compare", str(only), "--base", "base"]) == 2
    assert "nothing to compare" in capsys.readouterr().err
    assert main(["compare", str(run), "--base", "base", "--variant", "base"]) == 2
    assert "nothing to compare" in capsys.readouterr().err


def test_a_later_run_replaces_an_earlier_one_on_the_same_clip():
    first = {"results": [_record("base", "a", mpjpe_g_mm=1.0)]}
    second = {"results": [_record("base", "a", mpjpe_g_mm=2.0)]}
    merged = merge_results([first, second])
    assert len(merged) == 1 and merged[0]["metrics"]["mpjpe_g_mm"] == 2.0


def test_the_same_variant_in_two_runs_is_compared_by_run(tmp_path, capsys):
    rows = _results()
    old = _run(tmp_path, "old", ("base",), [r for r in rows if r["variant"] != "new"])
    again = [dict(r, metrics=dict(r["metrics"], mpjpe_g_mm=r["metrics"]["mpjpe_g_mm"] + 1.0))
             for r in rows if r["variant"] == "base"]
    new = _run(tmp_path, "new", ("base",), again)
    assert main(["compare", str(old), str(new), "--base", "base@old", "--by-run"]) == 0
    assert "| base@new | 3 | 120 -> 121 (+1.0 +- 0.0) |" in capsys.readouterr().out
    assert main(["compare", str(old), str(new), "--base", "base"]) == 2  # merged: one variant
    assert "nothing to compare" in capsys.readouterr().err
    assert main(["compare", str(old), str(new), "--base", "base", "--by-run"]) == 2
    assert "choose from: base@old, base@new" in capsys.readouterr().err
    assert run_labels([tmp_path / "a", tmp_path / "b" / "results.json", tmp_path / "x.json",
                       tmp_path / "c" / "a"]) == ["a#1", "b", "x", "a#2"]
    merged = merge_results([{"results": rows}], ["r"])
    assert {r["variant"] for r in merged} == {TRUTH_ROW, "base@r", "new@r"}


def test_pooled_runs_pair_within_each_run_and_count_every_runs_clips(tmp_path, capsys):
    # Two seeds of the same three clips: the base's figures differ between the runs, so
    # pairing across runs would be wrong; pooled, the six differences count apart.
    rows = _results()
    shifted = [dict(r, metrics={k: v + 50.0 if k == "mpjpe_g_mm" else v
                                for k, v in r["metrics"].items()}) for r in rows]
    for r in shifted:
        if r["variant"] == "new":
            r["metrics"]["mpjpe_g_mm"] += 3.0  # differences 4, 5 and 9 under the second seed
    first = _run(tmp_path, "s0", ("base", "new"), rows)
    doc = results_document(shifted, [], BenchmarkConfig(variants=("base", "new"),
                                                        material=MaterialConfig(seed=1)))
    second = write_results(doc, tmp_path / "s1")[0]
    assert main(["compare", str(first), str(second), "--base", "base", "--pool"]) == 0
    out, err = capsys.readouterr()
    # A clip's two seeds are not independent draws: the standard error is cluster-robust over
    # the three clips (sums of the deviations from the mean 4.5 per clip: a -4, b -2, c +6),
    # 1.53 where the six differences taken as independent would give 1.18.
    se = math.sqrt(3 / 2 * (4.0 ** 2 + 2.0 ** 2 + 6.0 ** 2)) / 6
    assert f"| new | 6 (3 groups) | 145 -> 150 (+4.5 +- {se:.1f}) |" in out and se > 1.5
    assert "prepared their material differently" not in err
    merged = merge_results([{"results": rows}], clip_labels=["s0"])
    assert {r["clip"] for r in merged} == {"a@s0", "b@s0", "c@s0"}
    with pytest.raises(SystemExit):  # the two ways of telling runs apart exclude each other
        main(["compare", str(first), str(second), "--base", "base", "--pool", "--by-run"])


def test_grouped_standard_error_is_the_ordinary_one_when_every_clip_is_its_own_group():
    rows = _results()
    plain = paired_differences(rows, "base")["mocap"]["new"]["mpjpe_g_mm"]
    grouped = paired_differences(rows, "base", group=lambda clip: clip)["mocap"]["new"]
    assert grouped["mpjpe_g_mm"]["standard_error"] == pytest.approx(plain["standard_error"])
    assert grouped["mpjpe_g_mm"]["groups"] == plain["groups"] == 3
    one = paired_differences(rows, "base", group=lambda clip: "all")["mocap"]["new"]
    assert one["mpjpe_g_mm"]["standard_error"] is None  # a single group: no spread to measure


def test_a_run_older_than_a_material_setting_is_not_told_apart_by_it(tmp_path, capsys):
    first = _run(tmp_path, "old", ("base", "new"), _results())
    doc = json.loads(first.read_text())
    del doc["config"]["material"]["multiview_truth"]  # written before the setting existed
    first.write_text(json.dumps(doc))
    second = _run(tmp_path, "new", ("base", "new"), _results())
    assert main(["compare", str(first), str(second), "--base", "base"]) == 0
    assert "prepared their material differently" not in capsys.readouterr().err
    other = write_results(results_document(_results(), [], BenchmarkConfig(
        variants=("base", "new"), material=MaterialConfig(multiview_truth="other-views"))),
        tmp_path / "loo")[0]
    assert main(["compare", str(first), str(other), "--base", "base"]) == 0
    assert "prepared their material differently" in capsys.readouterr().err


def test_compare_notes_a_run_written_before_it_finished(tmp_path, capsys):
    rows = _results()
    doc = results_document(rows, [], BenchmarkConfig(variants=("base", "new")),
                           pending=["later.bvh"])
    path = write_results(doc, tmp_path / "partial")[0]
    assert main(["compare", str(path), "--base", "base"]) == 0
    assert "incomplete, 1 piece(s) of material still to come" in capsys.readouterr().err


def test_the_report_says_when_variants_are_averaged_over_different_clips():
    rows = _results()
    complete = render_markdown(results_document(rows, [], BenchmarkConfig(
        variants=("base", "new"))))
    assert "Mean over 3 clip(s)." in complete
    failed = [r for r in rows if not (r["variant"] == "new" and r["clip"] == "c")]
    text = render_markdown(results_document(failed, [], BenchmarkConfig(
        variants=("base", "new"))))
    assert "Means over each variant's own clips (" in text and "base 3" in text
    assert "new 2" in text and "Mean over 3 clip(s)." not in text
