"""Camera calibration files on the command line: --camera (JSON/text K, or a Qualisys .qca.txt)
and --camera-name, for `physpose reconstruct` and `physpose fit`."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from test_kinematics_fixtures import synthetic_clip

from physpose.cli import main
from physpose.cli.camera_file import camera_intrinsics
from physpose.errors import PhysposeError


def test_json_camera(tmp_path):
    path = tmp_path / "cam.json"
    K = [[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]]
    path.write_text(json.dumps({"K": K}))
    assert np.allclose(camera_intrinsics(path, None, Path("v.mp4"), (320, 240)), K)


def test_qualisys_camera_choice(pose2sim_demo):
    calib = pose2sim_demo / "calibration" / "Calib.qca.txt"
    # All four cameras are 1088 x 1920 (the videos 1080 x 1920, a crop): the file name decides.
    k1 = camera_intrinsics(calib, None, Path("videos/cam01.mp4"), (1080, 1920))
    k3 = camera_intrinsics(calib, "cam03", Path("videos/cam01.mp4"), (1080, 1920))
    assert k1[0, 0] != k3[0, 0]
    half = camera_intrinsics(calib, "cam01", Path("x.mp4"), (544, 960))
    assert half[0, 0] == pytest.approx(k1[0, 0] / 2)
    with pytest.raises(PhysposeError, match="cannot tell which camera.*cam01 \\(1088x1920\\)"):
        camera_intrinsics(calib, None, Path("clip.mp4"), (1080, 1920))
    with pytest.raises(PhysposeError, match="no camera named 'cam9'"):
        camera_intrinsics(calib, "cam9", Path("clip.mp4"), (1080, 1920))
    with pytest.raises(PhysposeError, match="calibrated for 1088x1920"):
        camera_intrinsics(calib, "cam01", Path("clip.mp4"), (1920, 1080))


def test_fit_takes_one_camera_of_a_qualisys_calibration(pose2sim_demo, tmp_path, monkeypatch,
                                                         capsys):
    """`physpose fit` had refused a .qca.txt (only reconstruct took one); it now chooses the
    camera as reconstruct does, scaled to the input's image size."""
    monkeypatch.setenv("PHYSPOSE_CACHE_DIR", str(tmp_path / "cache"))
    calib = pose2sim_demo / "calibration" / "Calib.qca.txt"
    obs = dataclasses.replace(synthetic_clip(frames=10).observations, image_size=(540, 960),
                              camera_K=None)
    keypoints = obs.save(tmp_path / "clip.npz")
    out = tmp_path / "out"
    assert main(["fit", str(keypoints), "--out", str(out), "--variant", "S", "--no-overlay",
                 "--camera", str(calib)]) == 2
    assert "cannot tell which camera filmed clip.npz" in capsys.readouterr().err
    assert main(["fit", str(keypoints), "--out", str(out), "--variant", "S", "--no-overlay",
                 "--camera-name", "cam02"]) == 2
    assert "--camera-name chooses a camera of the --camera calibration" in capsys.readouterr().err
    assert main(["reconstruct", str(keypoints), "--out", str(out), "--camera-name", "cam02"]) == 2
    assert "--camera-name chooses a camera" in capsys.readouterr().err  # had been ignored
    assert main(["fit", str(keypoints), "--out", str(out), "--variant", "S", "--no-overlay",
                 "--camera", str(calib), "--camera-name", "cam02"]) == 0
    used = np.array(json.loads((out / "config.json").read_text())["camera_K"])
    expected = camera_intrinsics(calib, "cam02", Path("x.mp4"), (540, 960))
    assert expected[0, 0] == pytest.approx(expected[1, 1], rel=1e-3)  # half of a crop
    assert np.allclose(used, expected, rtol=1e-4)  # the fit takes fx for fy (they differ by 4e-5)
