"""End to end on a real video: `physpose fit` on one pose2sim view, the ground against the
calibration (slow: MediaPipe on 50 frames unless cached, then the full SO+GT fit)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from physpose.cli import main
from physpose.multiview.qualisys import load_qualisys
from physpose.reconstruction import Reconstruction
from physpose.video import probe


@pytest.mark.slow
def test_fit_cam01_of_the_pose2sim_demo(pose2sim_demo, tmp_path):
    video = pose2sim_demo / "videos" / "cam01.mp4"
    info = probe(video)
    camera = load_qualisys(next((pose2sim_demo / "calibration").glob("*.qca.txt")))[0]
    camera = camera.for_image_size(info.width, info.height, source=video)
    k_file = tmp_path / "K.json"
    k_file.write_text(json.dumps({"K": camera.K.tolist()}))
    out = tmp_path / "fit"
    assert main(["fit", str(video), "--out", str(out), "--camera", str(k_file), "--fps", "30",
                 "--no-overlay"]) == 0
    rec = Reconstruction.load(out)
    assert rec.num_frames >= 45 and np.isfinite(rec.joints_kinematic).all()
    # The estimated floor against the calibrated one (z up in the lab frame).
    n_est = rec.camera_T_world2cam[:3, :3] @ [0.0, 0.0, 1.0]
    n_true = camera.R_world2cam @ [0.0, 0.0, 1.0]
    angle = np.degrees(np.arccos(np.clip(n_est @ n_true, -1.0, 1.0)))
    height = -(rec.camera_T_world2cam[:3, :3].T @ rec.camera_T_world2cam[:3, 3])[2]
    assert angle < 10.0, angle
    assert abs(height - camera.center[2]) / camera.center[2] < 0.2, height
    # Feet on the ground: the lowest heel/toe joint sits near z = 0 in most frames.
    feet = [rec.joint_names.index(n) for n in ("l_heel", "r_heel", "l_toe", "r_toe")]
    assert np.median(rec.joints_kinematic[:, feet, 2].min(axis=1)) < 0.03
