"""The multi-view reference: folder layout checks (fast) and the real pose2sim demo (slow)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from physpose.errors import PhysposeError
from physpose.multiview.detector_error import detector_errors
from physpose.multiview.reference import (ReferenceConfig, build_multiview_reference,
                                          fill_missing, find_multiview_files)
from physpose.observe import ObserveConfig

_CALIB = """<calibration><cameras>{}</cameras></calibration>"""
_CAMERA = """<camera serial="{}"><fov_video bottom="479" left="0" right="639" top="0"/>
<transform r11="1" r12="0" r13="0" r21="0" r22="0" r23="1" r31="0" r32="-1" r33="0"
 x="0" y="-3000" z="1500"/><intrinsic centerPointU="20480" centerPointV="15360"
 focalLengthU="32000" focalLengthV="32000"/></camera>"""


def _folder(tmp_path: Path, cameras: list[str], videos: list[str]) -> Path:
    (tmp_path / "calibration").mkdir(parents=True)
    (tmp_path / "videos").mkdir()
    (tmp_path / "calibration" / "Calib.qca.txt").write_text(
        _CALIB.format("".join(_CAMERA.format(c) for c in cameras)))
    for v in videos:
        (tmp_path / "videos" / v).write_bytes(b"")
    return tmp_path


def test_videos_pair_with_cameras_by_name_then_order(tmp_path):
    by_name = find_multiview_files(_folder(tmp_path / "a", ["c2", "c1"], ["c1.mp4", "c2.mp4"]))
    assert [v.stem for v in by_name.videos] == ["c2", "c1"]
    by_order = find_multiview_files(_folder(tmp_path / "b", ["x", "y"], ["a.avi", "b.mov"]))
    assert [v.name for v in by_order.videos] == ["a.avi", "b.mov"]


@pytest.mark.parametrize("cameras, videos, message", [
    (["c1", "c2"], ["c1.mp4"], "1 videos in videos/ for 2 calibrated cameras"),
    (["c1"], ["c1.mp4"], "at least two views"),
])
def test_bad_folders(tmp_path, cameras, videos, message):
    with pytest.raises(PhysposeError, match=message):
        find_multiview_files(_folder(tmp_path, cameras, videos))


def test_missing_calibration(tmp_path):
    (tmp_path / "videos").mkdir()
    with pytest.raises(PhysposeError, match="expected one calibration"):
        find_multiview_files(tmp_path)
    with pytest.raises(PhysposeError, match="not found"):
        find_multiview_files(tmp_path / "nope")


def test_fill_missing_interpolates_and_holds_ends():
    pts = np.arange(5, dtype=float)[:, None, None] * np.ones((5, 1, 3))
    valid = np.array([[False], [True], [False], [True], [False]])
    out = fill_missing(np.where(valid[..., None], pts, np.nan), valid)
    np.testing.assert_allclose(out[:, 0, 0], [1, 1, 2, 3, 3])


@pytest.mark.slow
def test_reference_on_pose2sim_demo(pose2sim_demo, tmp_path, monkeypatch):
    # a copy under another name: unseen folders of the same layout must work
    folder = tmp_path / "lab_take"
    shutil.copytree(pose2sim_demo, folder)
    monkeypatch.setenv("PHYSPOSE_CACHE_DIR", str(tmp_path / "cache"))
    cfg = ReferenceConfig(observe=ObserveConfig(target_fps=30.0, mask_long_side=0))
    ref = build_multiview_reference(folder, cfg)
    assert ref.num_frames == 50 and len(ref.cameras) == 4
    assert [c.image_size[0] for c in ref.cameras] == [1080, 1080, 1088, 1088]
    summary = ref.reprojection_summary()
    assert summary["median_px"] < 20          # ~13 px measured
    assert summary["points_triangulated_fraction"] > 0.95
    assert 0.0 < summary["foot_height_median_m"] < 0.08   # feet on the lab floor (z up)
    head = ref.joints[:, 4, 2]
    assert 1.3 < np.median(head) < 1.8
    np.testing.assert_allclose(ref.camera_heights, [1.90, 1.69, 2.09, 1.88], atol=0.01)
    for i in range(4):  # cameras look down: the floor normal points up the image (-y)
        assert ref.floor_normal_in_camera(i)[1] < -0.8
    errors = detector_errors(ref)
    assert all(5 < e.err2d_in_sample_median_px < 30 for e in errors)
    assert all(50 < e.err3d_joints_mm < 300 and e.err3d_joints_pa_mm < e.err3d_joints_mm
               for e in errors)
    # MediaPipe's depth is flatter than the body's, yet unscaled it predicts it best
    # (measured: 0.51-0.75, 1.00-1.08, correlation 0.72-0.88)
    assert all(e.depth_scale_ratio < 0.85 and 0.85 < e.depth_predictor < 1.25
               and 0.6 < e.depth_correlation < 0.95 for e in errors)
    again = build_multiview_reference(folder, cfg)  # cache hit: identical arrays
    np.testing.assert_array_equal(again.landmarks, ref.landmarks)
