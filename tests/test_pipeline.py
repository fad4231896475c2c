"""The composed pipeline: config presets, the reconstruct CLI's arguments and errors, and one
end-to-end run on simulated observations (slow)."""

from __future__ import annotations

import dataclasses
import json

import mujoco
import numpy as np
import pytest

from physpose.body import build_body
from physpose.cli import main
from physpose.dynamics import PRESETS
from physpose.dynamics.synthetic import simulated_clip
from physpose.errors import PhysposeError
from physpose.diagnostics import LOW_CAMERA, TILTED_CAMERA, trimmed_message
from physpose.pipeline import (CONFIG_FILE, RECONSTRUCTION_FILE, PipelineConfig,
                               _screen_observations, reconstruct, trim_unseen_ends,
                               unsure_times)
from physpose.reconstruction import Reconstruction
from physpose.shape import BodyShape


def test_presets_compose_the_dynamics_presets():
    assert PipelineConfig.preset("fast") == PipelineConfig()
    paper = PipelineConfig.preset("paper")
    assert paper.dynamics == PRESETS["paper"] and paper.kinematics.variant == "SO+GT"
    assert json.loads(json.dumps(paper.to_json()))["dynamics"]["iterations"] == 2000
    with pytest.raises(PhysposeError, match="unknown preset"):
        PipelineConfig.preset("slow")


def test_reconstruct_cli_refuses_a_missing_video(tmp_path, capsys):
    code = main(["reconstruct", str(tmp_path / "none.mp4"), "--out", str(tmp_path / "out")])
    assert code == 2
    assert "none.mp4" in capsys.readouterr().err


def test_reconstruct_cli_refuses_a_file_as_output_folder(tmp_path, capsys):
    body = build_body(BodyShape.from_height(1.75))
    _, obs, _ = simulated_clip(body, "stand", seconds=0.4)
    keypoints = obs.save(tmp_path / "obs.npz")
    (tmp_path / "file").write_text("x")
    code = main(["reconstruct", str(keypoints), "--out", str(tmp_path / "file")])
    assert code == 2 and "not a folder" in capsys.readouterr().err


def test_reconstruct_cli_refuses_a_clip_of_one_frame(tmp_path, capsys):
    body = build_body(BodyShape.from_height(1.75))
    _, obs, _ = simulated_clip(body, "stand", seconds=0.4)
    keypoints = obs.frames(0, 1).save(tmp_path / "one.npz")
    code = main(["reconstruct", str(keypoints), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and "only 1 frame" in err and "one.npz" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()  # nothing left behind for a refused clip


def test_a_reconstruction_failing_in_a_later_stage_leaves_no_empty_folder(tmp_path,
                                                                        monkeypatch):
    import physpose.kinematics.fit as fit  # noqa: PLC0415 (JAX)

    def fail(*args, **kwargs):
        raise PhysposeError("the fit failed")

    monkeypatch.setattr(fit, "fit_kinematics", fail)
    body = build_body(BodyShape.from_height(1.75))
    _, obs, _ = simulated_clip(body, "stand", seconds=0.4)
    with pytest.raises(PhysposeError, match="the fit failed"):
        reconstruct(obs, tmp_path / "runs" / "out", progress=False)
    assert not (tmp_path / "runs").exists()


def test_detections_left_out_as_torn_are_timed_on_the_footages_clock():
    body = build_body(BodyShape.from_height(1.75, 70.0))
    _, obs, _ = simulated_clip(body, "stand", seconds=0.4)
    assert unsure_times(obs) == []
    unsure = np.zeros(obs.num_frames, bool)
    unsure[[0, 2]] = True
    torn = obs.replace(unsure=unsure)
    assert unsure_times(torn) == [0.0, round(2 / obs.fps, 4)]
    # Footage played 4x slower: frame 2 is 0.02 s into the motion and 0.08 s into the video.
    slow = torn.on_real_clock(4.0)
    assert np.isclose(slow.timestamps[2] - slow.timestamps[0], 0.02)
    assert unsure_times(slow, 4.0) == [round(obs.timestamps[0], 4),
                                       round(obs.timestamps[0] + 0.08, 4)]


def test_frames_before_and_after_the_person_is_in_view_are_left_out():
    body = build_body(BodyShape.from_height(1.75))
    _, obs, _ = simulated_clip(body, "stand", seconds=0.6)
    t = obs.num_frames
    unseen = np.zeros(t, bool)
    unseen[:4] = unseen[-3:] = True
    blind = obs.replace(detected=obs.detected & ~unseen, interpolated=obs.interpolated & ~unseen,
                        keypoints2d=np.where(unseen[:, None, None], 0.0, obs.keypoints2d))
    kept, trimmed = trim_unseen_ends(blind)
    assert trimmed == [4, t - 4] and kept.num_frames == t - 7
    np.testing.assert_array_equal(kept.timestamps, obs.timestamps[4:t - 3])
    np.testing.assert_array_equal(kept.keypoints2d, obs.keypoints2d[4:t - 3])
    assert kept.masks is None or len(kept.masks) == t - 7
    line = trimmed_message(trimmed, t, obs.fps)  # a result from before the times were kept
    assert f"before {4 / obs.fps:.2f} s" in line and f"after {(t - 3) / obs.fps:.2f} s" in line
    # Seconds into the video, what --start/--end take (here the clip began 2 s in).
    line = trimmed_message(trimmed, t, obs.fps, [2.0 + 4 / obs.fps, 2.0 + (t - 4) / obs.fps])
    assert f"not seen before {2 + 4 / obs.fps:.2f} s or after {2 + (t - 4) / obs.fps:.2f} s " \
           "into the video" in line and f"frames 4-{t - 4} of the {t} analysed" in line
    # A clip seen throughout, or one seen in fewer than 3 frames, is left whole.
    assert trim_unseen_ends(obs) == (obs, None)
    unseen[:-2] = True
    few = obs.replace(detected=obs.detected & ~unseen, interpolated=obs.interpolated & ~unseen)
    assert trim_unseen_ends(few)[1] is None


def test_a_person_jump_is_told_in_seconds_into_the_video(caplog):
    # The warning's remedy is --start/--end, which take seconds into the video: after the
    # unseen first frames are left out, the output's frame 11 is the video's 15th analysed.
    body = build_body(BodyShape.from_height(1.75))
    _, obs, _ = simulated_clip(body, "stand", seconds=1.2)
    unseen = np.arange(obs.num_frames) < 4
    keypoints = obs.keypoints2d.copy()
    keypoints[15:, :, 0] += 400.0  # another person, far to the side
    jumped = obs.replace(keypoints2d=np.where(unseen[:, None, None], 0.0, keypoints),
                         detected=obs.detected & ~unseen,
                         interpolated=obs.interpolated & ~unseen,
                         timestamps=obs.timestamps + 2.0)  # analysed from --start 2
    with caplog.at_level("WARNING", logger="physpose.pipeline"):
        kept, found = _screen_observations(jumped, 1.0)
    assert found["person_jumps"] == [11] and kept.num_frames == obs.num_frames - 4
    assert found["person_jump_times"] == [round(float(obs.timestamps[15]) + 2.0, 4)]
    assert f"11 ({obs.timestamps[15] + 2.0:.2f} s into the video)" in caplog.text


@pytest.mark.slow
def test_reconstruct_writes_the_contract(tmp_path):
    body = build_body(BodyShape.from_height(1.75))
    _, obs, _ = simulated_clip(body, "shift", seconds=1.2)
    cfg = PipelineConfig.preset("fast")
    recon = reconstruct(obs, tmp_path, cfg, height=1.75, progress=False)
    loaded = Reconstruction.load(tmp_path / RECONSTRUCTION_FILE)
    t = obs.num_frames
    assert loaded.has_physics and loaded.joints_physics.shape == (t, 21, 3)
    assert loaded.qpos_physics.shape == (t, 55) and loaded.landmarks_physics.shape == (t, 33, 3)
    assert loaded.body_mjcf and "<mujoco" in loaded.body_mjcf
    assert loaded.landmarks_kinematic.shape == (t, 33, 3)
    assert set(loaded.meta["timings_s"]) == {"observe", "kinematics", "body", "dynamics"}
    # Where there is no video to ask (keypoints, simulated detections), the image size and
    # each frame's time come from the observations.
    assert loaded.meta["image_size"] == list(obs.image_size)
    np.testing.assert_allclose(loaded.video_times, obs.timestamps, atol=1e-6)
    # A simulated motion is one the body can make: almost no unexplained root force.
    assert loaded.meta["dynamics"]["reference"]["root_residual_median"] < 0.05
    # A clean simulated clip raises none of the input warnings (physpose.diagnostics).
    found = dict(loaded.meta["diagnostics"])
    assert found.pop("camera_height") > LOW_CAMERA  # the floor from a standing body
    assert found.pop("camera_tilt") < TILTED_CAMERA
    assert found == {"trimmed": None, "trimmed_times": None, "observed_frames": t,
                     "camera_motion": None, "unsure_detections": [], "person_jumps": [],
                     "person_jump_times": [], "hidden_feet": 0.0, "raised": [], "supports": [], "seated": [],
                     "seats": [], "invalid_windows": [], "unrecorded_forces": [],
                     "stride_period": None, "label_exchanges": {}}
    # The simulated forces are in the contract's file: the floor carries the body's weight.
    assert loaded.grf_physics.shape == (t, 3, 3) and loaded.torques_physics.shape == (t, 48)
    weight = mujoco.MjModel.from_xml_string(loaded.body_mjcf).body_subtreemass[0] * 9.81
    assert abs(loaded.grf_physics[:, :, 2].sum(axis=1).mean() / weight - 1.0) < 0.05
    resolved = json.loads((tmp_path / CONFIG_FILE).read_text())
    assert resolved["config"]["dynamics"]["iterations"] == cfg.dynamics.iterations
    assert any((tmp_path / "dynamics_windows").iterdir())
    # The simulated body stays near the kinematic estimate and on its feet.
    gap = np.linalg.norm(recon.joints_physics - recon.joints_kinematic, axis=-1).mean()
    assert gap < 0.1
    assert recon.qpos_physics[:, 2].min() > 0.5 * recon.qpos_kinematic[:, 2].min()


@pytest.mark.slow
def test_slow_motion_footage_is_reconstructed_on_the_real_clock(tmp_path):
    body = build_body(BodyShape.from_height(1.75))
    _, obs, _ = simulated_clip(body, "shift", seconds=0.8)
    # The same motion filmed 4x slow: the footage's clock runs 4x behind the motion's.
    footage = obs.replace(fps=obs.fps / 4, timestamps=obs.timestamps * 4)
    cfg = dataclasses.replace(PipelineConfig.preset("fast"), slow_motion=4.0)
    recon = reconstruct(footage, tmp_path, cfg, height=1.75, progress=False)
    assert recon.fps == pytest.approx(obs.fps) and recon.slow_motion == 4.0
    assert json.loads((tmp_path / CONFIG_FILE).read_text())["config"]["slow_motion"] == 4.0
    # Under real gravity at the real pace the body follows the motion and stands on the floor.
    gap = np.linalg.norm(recon.joints_physics - recon.joints_kinematic, axis=-1).mean()
    assert gap < 0.1
    weight = mujoco.MjModel.from_xml_string(recon.body_mjcf).body_subtreemass[0] * 9.81
    assert abs(recon.grf_physics[:, :, 2].sum(axis=1).mean() / weight - 1.0) < 0.05
    with pytest.raises(PhysposeError, match="slow motion"):
        dataclasses.replace(cfg, slow_motion=0.0)
