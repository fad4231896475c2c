"""Qualisys calibration parsing: a tiny synthetic file and the real pose2sim demo."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from physpose.errors import PhysposeError
from physpose.multiview.qualisys import load_qualisys

# One camera 3 m along lab -y at 1.5 m height looking along +y (level): the camera-to-lab
# matrix of Qualisys has the optical axis as its third column, image "up" as its second.
_CAMERA = """
    <camera active="1" serial="{serial}">
      <fov_video bottom="959" left="0" right="639" top="0"/>
      <transform r11="1" r12="0" r13="0" r21="0" r22="0" r23="1" r31="0" r32="-1" r33="0"
                 x="0" y="-3000" z="1500"/>
      <intrinsic centerPointU="{cu}" centerPointV="30720" focalLengthU="64000"
                 focalLengthV="64000" radialDistortion1="0.01" radialDistortion2="0"
                 radialDistortion3="0" tangentalDistortion1="0" tangentalDistortion2="0"
                 skew="0"/>
    </camera>"""


def _write(tmp_path: Path, cameras: str) -> Path:
    path = tmp_path / "Calib.qca.txt"
    path.write_text(f"<?xml version='1.0'?>\n<calibration><cameras>{cameras}</cameras>"
                    "</calibration>\n")
    return path


def test_synthetic_calibration(tmp_path):
    path = _write(tmp_path, _CAMERA.format(serial="a", cu=20480) + _CAMERA.format(serial="b",
                                                                                  cu=19200))
    cams = load_qualisys(path)
    assert [c.name for c in cams] == ["a", "b"]
    cam = cams[0]
    assert cam.image_size == (640, 960)
    np.testing.assert_allclose(cam.K, [[1000, 0, 320], [0, 1000, 480], [0, 0, 1]])
    np.testing.assert_allclose(cam.dist, [0.01, 0, 0, 0, 0])
    np.testing.assert_allclose(cam.center, [0, -3, 1.5])
    # OpenCV axes: the camera looks along lab +y, its image y axis points down (lab -z)
    np.testing.assert_allclose(cam.R_world2cam[2], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(cam.R_world2cam[1], [0, 0, -1], atol=1e-12)
    # a point straight ahead at camera height lands on the principal point; one higher lands above
    uv = cam.project(np.array([[0.0, 0.0, 1.5], [0.0, 0.0, 2.0]]))
    np.testing.assert_allclose(uv[0], [320, 480], atol=1e-9)
    assert uv[1, 1] < 480
    np.testing.assert_allclose(cam.undistort(cam.project(np.array([0.4, 1.0, 2.1]))),
                               (cam.projection @ [0.4, 1.0, 2.1, 1])[:2]
                               / (cam.projection @ [0.4, 1.0, 2.1, 1])[2], atol=1e-3)
    assert cams[1].K[0, 2] == 300


def test_image_size_adaptation(tmp_path):
    cam = load_qualisys(_write(tmp_path, _CAMERA.format(serial="a", cu=20480)))[0]
    assert cam.for_image_size(640, 960) is cam
    crop = cam.for_image_size(636, 960)  # a few pixels cut at the right: same intrinsics
    np.testing.assert_array_equal(crop.K, cam.K)
    assert crop.image_size == (636, 960)
    half = cam.for_image_size(320, 480)
    np.testing.assert_allclose(half.K[:2, :], cam.K[:2, :] / 2)
    with pytest.raises(PhysposeError, match="calibrated for 640x960"):
        cam.for_image_size(960, 640, source="v.mp4")


@pytest.mark.parametrize("text, message", [
    ("<calibration><cameras>", "not a readable XML"),
    ("<calibration><cameras></cameras></calibration>", "no active <camera>"),
    (_CAMERA.format(serial="a", cu=20480).replace('r11="1"', 'r11="x"'), "r11='x' is not a number"),
    (_CAMERA.format(serial="a", cu=20480).replace('r11="1"', 'r11="2"'), "not a rotation"),
    (_CAMERA.format(serial="a", cu=20480).replace("<intrinsic", "<other"), "no <intrinsic>"),
    (_CAMERA.format(serial="a", cu=20480) * 2, "duplicate camera"),
])
def test_malformed_files(tmp_path, text, message):
    path = tmp_path / "bad.qca.txt"
    path.write_text(text if text.startswith("<calibration") else
                    f"<calibration><cameras>{text}</cameras></calibration>")
    with pytest.raises(PhysposeError, match=message) as info:
        load_qualisys(path)
    assert str(path) in str(info.value)


def test_missing_file(tmp_path):
    with pytest.raises(PhysposeError, match="not found"):
        load_qualisys(tmp_path / "nope.qca.txt")


def test_pose2sim_demo_calibration(pose2sim_demo):
    cams = load_qualisys(pose2sim_demo / "calibration" / "Calib.qca.txt")
    assert [c.name for c in cams] == ["cam01", "cam02", "cam03", "cam04"]
    for cam in cams:
        assert cam.image_size == (1088, 1920)  # portrait sensor window
        assert 1600 < cam.K[0, 0] < 1750 and abs(cam.K[0, 0] - cam.K[1, 1]) < 1
        assert 1.6 < cam.center[2] < 2.2     # cameras 1.6-2.2 m above the lab floor (z up)
        R = cam.R_world2cam
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-6)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-6)
        # every camera looks slightly down towards the capture volume around the lab origin
        forward = R[2]
        assert -0.6 < forward[2] < 0
        assert forward @ (-cam.center) > 0
        # the image's down axis points roughly down in the lab (portrait videos, upright)
        assert R[1, 2] < -0.8
