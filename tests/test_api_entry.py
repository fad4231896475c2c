"""The Python API refuses plausible mistakes at the entry of a stage, with a remedy: a preset's
name where its config belongs, arguments in the wrong order, impossible settings. They had
failed with an AttributeError or TypeError deep inside, some only after the kinematic fit."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from synthetic_result import make_reconstruction
from test_mocap import bvh_rows, write_bvh

from physpose.body import build_body
from physpose.dynamics import PRESETS, ablated, optimize_dynamics
from physpose.dynamics.synthetic import simulated_clip
from physpose.errors import PhysposeError
from physpose.kinematics.config import CameraConfig, GroundConfig, PoseConfig, PoseWeights
from physpose.kinematics.fit import fit_kinematics
from physpose.mocap import load_mocap
from physpose.observe import ObserveConfig
from physpose.pipeline import PipelineConfig, reconstruct
from physpose.shape import BodyShape


@pytest.fixture(scope="module")
def clip():
    body = build_body(BodyShape.from_height(1.75))
    fit, obs, _ = simulated_clip(body, "stand", seconds=0.4)
    return body, fit, obs


def test_a_preset_name_where_a_config_belongs_is_refused_before_the_work(clip, tmp_path):
    body, fit, obs = clip
    with pytest.raises(PhysposeError, match="PipelineConfig.dynamics must be DynamicsConfig, "
                                            "not str 'paper'"):
        PipelineConfig.preset("fast", dynamics="paper")
    with pytest.raises(PhysposeError, match="reconstruct's config must be PipelineConfig"):
        reconstruct(obs, tmp_path / "out", "fast", progress=False)
    assert not (tmp_path / "out").exists()
    with pytest.raises(PhysposeError, match="fit_kinematics' config must be KinematicConfig"):
        fit_kinematics(obs, "SO+GT")
    with pytest.raises(PhysposeError, match="optimize_dynamics' config must be DynamicsConfig"):
        optimize_dynamics(body, fit, obs, "fast", checkpoints=False)
    with pytest.raises(PhysposeError, match="ablated's config must be DynamicsConfig"):
        ablated("fast", "no2d")


def test_arguments_in_the_wrong_place_are_named(clip):
    body, fit, obs = clip
    with pytest.raises(PhysposeError, match="optimize_dynamics' body must be Body, not "
                                            "KinematicFit"):
        optimize_dynamics(fit, obs, PRESETS["fast"], checkpoints=False)
    with pytest.raises(PhysposeError, match="fit_kinematics' observations must be "
                                            "Observations, not str 'k.json'"):
        fit_kinematics("k.json")
    with pytest.raises(PhysposeError, match="build_body's shape must be BodyShape, not float"):
        build_body(1.75)


def test_a_body_of_other_bones_than_the_fit_is_refused(clip):
    _, fit, obs = clip  # (a 1.5 m body had run on a 1.75 m fit: window loss 7.18, not 0.04)
    with pytest.raises(PhysposeError, match="bones differ from the kinematic fit's by up to"):
        optimize_dynamics(build_body(BodyShape.from_height(1.5)), fit, obs, PRESETS["fast"],
                          checkpoints=False)


@pytest.mark.parametrize("change, match", [
    (dict(popsize=1), "DynamicsConfig.popsize=1 must be at least 2"),
    (dict(window=float("inf")), "window=inf must be finite"),
    (dict(iterations=20.0), "iterations=20.0 must be a whole number"),
    (dict(seed=True), "seed=True must be a whole number"),
    (dict(weights={"pose": 1.0}), "weights must be ObjectiveWeights, not dict"),
    (dict(refine=6), "refine must be RefineConfig, not int 6"),
    (dict(ground_snap=-0.01), "ground_snap=-0.01 must be >= 0"),
])
def test_impossible_dynamics_settings_are_refused_when_configured(change, match):
    with pytest.raises(PhysposeError, match=match):
        dataclasses.replace(PRESETS["fast"], **change)


@pytest.mark.parametrize("make, match", [
    (lambda: PoseWeights(reprojection=-1.0), "PoseWeights.reprojection=-1.0 must be finite"),
    (lambda: PoseConfig(sigma_2d=0.0), "PoseConfig.sigma_2d=0.0 must be finite and > 0"),
    (lambda: GroundConfig(rounds=0), "GroundConfig.rounds=0 must be at least 1"),
])
def test_impossible_kinematic_settings_are_refused(make, match):
    with pytest.raises(PhysposeError, match=match):
        make()


@pytest.mark.parametrize("fov", [0.0, -55.0, 180.0, float("nan")])
def test_an_impossible_field_of_view_is_refused(fov):
    with pytest.raises(PhysposeError, match="field of view"):
        CameraConfig(diagonal_fov_deg=fov)


def test_motion_capture_rates_and_lengths_are_checked(tmp_path):
    path = write_bvh(tmp_path / "a.bvh", bvh_rows(8))
    for rate in (-25.0, 0.0, float("nan")):
        with pytest.raises(PhysposeError, match="must be a positive rate"):
            load_mocap(path, target_fps=rate)
    with pytest.raises(PhysposeError, match="1 frame of motion"):
        load_mocap(write_bvh(tmp_path / "one.bvh", bvh_rows(1)))


def test_a_misspelt_motion_is_refused_not_read_as_the_physics():
    rec = make_reconstruction(num_frames=10)
    assert rec.joints("kinematic") is rec.joints_kinematic
    for name in ("kinematics", "dynamics"):
        with pytest.raises(PhysposeError, match=f"unknown motion '{name}'"):
            rec.joints(name)  # had returned the physics joints
        with pytest.raises(PhysposeError, match="use one of best, kinematic, physics"):
            rec.camera_travel(name)


def test_a_reconstruction_without_a_positive_rate_is_refused():
    rec = make_reconstruction(num_frames=10)
    with pytest.raises(PhysposeError, match="frame rate 0.0 must be positive"):
        rec.replace(fps=0.0)


def test_an_analysis_rate_out_of_range_is_refused_when_configured():
    # (with --slow-motion it had been clamped into range without a word)
    with pytest.raises(PhysposeError, match="target frame rate -25 fps is outside 1-240"):
        ObserveConfig(target_fps=-25.0)


@pytest.mark.parametrize("change, match", [
    ("zero_root", "root orientation is not a unit quaternion"),
    ("camera_K", "camera_K has shape \\(3, 4\\)"),
    ("T_world2cam", "T_world2cam has shape \\(4, 4\\) or non-finite"),
])
def test_a_hand_built_kinematic_fit_is_checked(clip, change, match):
    # (zero root quaternions had failed inside the ground forces' least squares; a wrong
    # camera had run to a loss of inf)
    body, fit, obs = clip
    if change == "zero_root":
        qpos = fit.qpos.copy()
        qpos[2, 3:7] = 0.0
        fit = dataclasses.replace(fit, qpos=qpos)
    elif change == "camera_K":
        fit = dataclasses.replace(fit, camera_K=np.zeros((3, 4)))
    else:
        fit = dataclasses.replace(fit, T_world2cam=np.full((4, 4), np.nan))
    with pytest.raises(PhysposeError, match=match):
        optimize_dynamics(body, fit, obs, PRESETS["fast"], checkpoints=False)
