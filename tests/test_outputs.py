"""physpose.outputs: metrics without ground truth and every output file of a result folder."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import physpose.report as report
from physpose.errors import PhysposeError
from physpose.outputs import (DEFAULT_FORMATS, METRIC_LABELS, metrics_table, summarize,
                              write_outputs)
from physpose.reconstruction import Reconstruction
from synthetic_result import make_reconstruction, save_result, write_video


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    return save_result(tmp_path_factory.mktemp("outputs"), num_frames=8)


def test_summarize_scores_both_motions(result):
    metrics = summarize(result)
    assert set(metrics) == {"kinematic", "physics"}
    for values in metrics.values():
        assert set(values) == set(METRIC_LABELS)
        assert all(np.isfinite(v) and v >= 0 for v in values.values())
    # The synthetic detections are the kinematic landmarks projected exactly; the physics
    # motion is a phase-shifted walk, so it is further from them.
    assert metrics["kinematic"]["mpjpe_2d_px"] < 1e-6
    assert metrics["physics"]["mpjpe_2d_px"] > 1.0


def test_mpjpe_2d_ignores_undetected_frames(tmp_path):
    rec = make_reconstruction(num_frames=6, physics=False)
    kp = rec.keypoints2d.copy()
    kp[2] = 0.0  # an undetected frame: zeros with confidence 0
    rec.replace(keypoints2d=kp).save(tmp_path / "reconstruction.npz")
    assert summarize(tmp_path)["kinematic"]["mpjpe_2d_px"] < 1e-6


def test_metrics_table_has_one_column_per_motion():
    table = metrics_table({"kinematic": {"float_pct": 12.5}, "physics": {"float_pct": 0.0}})
    header, row = table.splitlines()
    assert header.split()[-2:] == ["kinematic", "physics"]
    assert row.split()[-2:] == ["12.5", "0"]
    # metrics.json writes a NaN as null, which reads back as None: shown as "-"
    _, row = metrics_table({"kinematic": {"float_pct": None}}).splitlines()
    assert row.split()[-1] == "-"


def test_write_outputs_writes_every_file(tmp_path):
    folder = save_result(tmp_path, num_frames=6)
    video = write_video(tmp_path / "clip.mp4", num_frames=6, fps=25.0)
    written = write_outputs(folder, video=video, formats=("bvh", "csv"),
                            report=report.BUNDLE.is_file(), progress=False)
    expected = {"metrics", "overlay", "overlay_png", "bvh", "csv"} | (
        {"report"} if report.BUNDLE.is_file() else set())
    assert set(written) == expected
    assert all(p.parent == folder and p.stat().st_size > 0 for p in written.values())
    stored = json.loads(written["metrics"].read_text())
    assert stored == summarize(folder)
    meta = Reconstruction.load(folder).meta
    assert meta["metrics"] == stored and meta["image_size"] == [320, 240]
    if "report" in written:
        page = written["report"].read_text()
        assert METRIC_LABELS["foot_skate_pct"] in page


def test_kinematic_only_result_has_no_physics_column(tmp_path):
    folder = save_result(tmp_path, num_frames=5, physics=False)
    written = write_outputs(folder, formats=("csv", "forces"), report=False, overlay=False)
    assert set(json.loads(written["metrics"].read_text())) == {"kinematic"}
    assert "forces" not in written  # nothing simulated, no forces table


def test_default_exports_include_the_forces_of_a_physics_result(tmp_path):
    folder = save_result(tmp_path, num_frames=5)
    written = write_outputs(folder, report=False, overlay=False)
    assert set(written) == {"metrics", *DEFAULT_FORMATS} and "forces" in DEFAULT_FORMATS
    assert written["forces"] == folder / "forces.csv"


def test_a_rerun_into_the_folder_leaves_no_outputs_of_the_earlier_run(tmp_path, caplog):
    """A second reconstruction into a folder, asked for fewer outputs, had left the first
    run's joints.csv (4.5 cm off the new result) and overlay beside the new
    reconstruction.npz, unmentioned; and a run killed while writing had left its temporary
    file for good (a helper's findings)."""
    import subprocess
    import sys

    folder = save_result(tmp_path, num_frames=5)
    write_outputs(folder, formats=("bvh", "csv"), report=False, overlay=False)
    assert (folder / "joints.csv").is_file() and (folder / "motion.bvh").is_file()
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    killed = folder / f".overlay.{int(gone.stdout)}.0123abcd.tmp.mp4"   # its writer is gone
    live = folder / f".overlay.{os.getpid()}.0123abcd.tmp.mp4"          # this process's
    killed.write_bytes(b"half a video")
    live.write_bytes(b"being written")
    written = write_outputs(folder, formats=("bvh",), report=False, overlay=False)
    assert set(written) == {"metrics", "bvh"} and (folder / "motion.bvh").is_file()
    assert not (folder / "joints.csv").exists() and not killed.exists() and live.exists()
    assert "removed joints.csv, written there by an earlier run" in caplog.text
    assert "motion.bvh" not in caplog.text  # written again: nothing to say


def test_unknown_format_is_refused_before_writing(tmp_path):
    folder = save_result(tmp_path, num_frames=4)
    with pytest.raises(PhysposeError, match="unknown export format"):
        write_outputs(folder, formats=("fbx",))
    assert not (folder / "metrics.json").exists()


def test_missing_result_folder(tmp_path):
    with pytest.raises(PhysposeError, match="result folder not found"):
        summarize(tmp_path / "nope")


def test_simulated_forces_round_trip_and_are_shape_checked(tmp_path):
    rec = make_reconstruction(num_frames=6)
    loaded = Reconstruction.load(rec.save(tmp_path / "reconstruction.npz"))
    for key in ("grf_physics", "cop_physics", "torques_physics"):
        np.testing.assert_array_equal(getattr(loaded, key), getattr(rec, key))
    with pytest.raises(PhysposeError, match=r"grf_physics has shape \(6, 2, 3\)"):
        rec.replace(grf_physics=np.zeros((6, 2, 3)))
    with pytest.raises(PhysposeError, match="torques_physics"):
        rec.replace(torques_physics=np.zeros((5, 48)))


def _damage(path, how):
    if how == "truncated":
        path.write_bytes(path.read_bytes()[:2000])
    elif how == "empty":
        path.write_bytes(b"")
    else:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
        if how == "meta not JSON":
            arrays["meta_json"] = np.array("{not json")
        elif how == "fps 0":
            arrays["fps"] = np.array(0.0)
        elif how == "fps two numbers":
            arrays["fps"] = np.array([25.0, 30.0])
        elif how == "fps text":
            arrays["fps"] = np.array("fast")
        elif how == "meta a list":
            arrays["meta_json"] = np.array("[1, 2]")
        elif how == "joints 0-d":
            arrays["joints_kinematic"] = np.array(1.0)
        elif how == "a field of the wrong shape":
            arrays["landmarks_kinematic"] = arrays["landmarks_kinematic"][:, :5]
        elif how == "no frames":
            frames = len(arrays["joints_kinematic"])
            arrays = {k: v[:0] if v.ndim and len(v) == frames else v for k, v in arrays.items()}
        np.savez(path, **arrays)


@pytest.mark.parametrize("how, message", [
    ("truncated", "not a readable reconstruction npz"),
    ("empty", "not a readable reconstruction npz"),
    ("meta not JSON", "its metadata is not JSON"),
    ("fps 0", "frame rate 0.0 is not a positive, finite number"),
    ("fps two numbers", r"frame rate \[25.0, 30.0\] is not"),
    ("fps text", "frame rate 'fast' is not"),
    ("meta a list", "metadata is not a JSON object"),
    ("joints 0-d", "not arrays of the right dimensions"),
    ("a field of the wrong shape", "landmarks_kinematic has shape"),
    ("no frames", "has no frames"),
])
def test_a_damaged_reconstruction_is_named_in_the_error(tmp_path, how, message):
    """Whatever is wrong with reconstruction.npz, the error names the file (export, report and
    overlay all load it this way)."""
    path = make_reconstruction(num_frames=6).save(tmp_path / "reconstruction.npz")
    _damage(path, how)
    with pytest.raises(PhysposeError, match=message) as caught:
        Reconstruction.load(tmp_path)
    assert caught.value.path == str(path) and caught.value.remedy


def test_metadata_is_strict_json_for_other_tools(tmp_path):
    """A metric undefined on a short clip (NaN) or an invalid sample's loss (infinity) is
    written as null, which JSON readers outside Python accept."""
    meta = {"metrics": {"physics": {"jitter_mps2": float("nan")}},
            "dynamics": {"windows": [{"loss": float("inf")}]}}
    path = make_reconstruction(num_frames=4, meta=meta).save(tmp_path / "reconstruction.npz")
    with np.load(path) as data:
        text = str(data["meta_json"])

    def refuse(token):
        raise ValueError(f"non-standard JSON token {token}")
    stored = json.loads(text, parse_constant=refuse)
    assert stored["metrics"]["physics"]["jitter_mps2"] is None
    assert stored["dynamics"]["windows"][0]["loss"] is None


def test_positions_that_are_not_numbers_are_a_clear_error_naming_the_motion(tmp_path):
    folder = save_result(tmp_path, num_frames=6)
    rec = Reconstruction.load(folder)
    joints = rec.joints("physics").copy()
    joints[2, 1] = np.nan
    rec.replace(joints_physics=joints).save(folder / "reconstruction.npz")
    with pytest.raises(PhysposeError, match="physics motion holds positions that are not"):
        summarize(folder)
