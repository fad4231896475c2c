"""A travelling camera: its path read off the estimate's standing feet (dynamics/travel.py), the
re-projection term through it, and reconstructions seen through it."""

from __future__ import annotations

import numpy as np
import pytest

from physpose.body import build_body, standing_qpos
from physpose.dynamics import DynamicsConfig
from physpose.dynamics.objective import evaluate_terms, make_reference, project
from physpose.dynamics.rollout import FrameSamples
from physpose.dynamics.synthetic import virtual_camera
from physpose.dynamics.travel import camera_travel, camera_travels, weighted_median
from physpose.errors import PhysposeError
from physpose.fk import fk_mujoco
from physpose.metrics import transform_points
from physpose.outputs import motion_metrics
from physpose.render.overlay import _filming
from physpose.shape import BodyShape
from physpose.skeleton import DOF_NAMES
from synthetic_result import make_reconstruction

FPS = 25.0
FRAMES = 50


@pytest.fixture(scope="module")
def body():
    return build_body(BodyShape.from_height(1.75))


def standing_on_left(body) -> np.ndarray:
    """(FRAMES, 55): the left foot stands still, the right one is lifted and swings fore and
    aft (about 0.5 m/s at the foot)."""
    qpos = np.tile(standing_qpos(body), (FRAMES, 1))
    swing = 0.4 * np.sin(np.linspace(0.0, 2.0 * np.pi, FRAMES))
    qpos[:, 7 + DOF_NAMES.index("r_knee_y")] += 0.9
    qpos[:, 7 + DOF_NAMES.index("r_hip_y")] += swing - 0.3
    return qpos


def test_which_cameras_travel():
    assert camera_travels("auto", "moving")
    assert not camera_travels("auto", "static") and not camera_travels("auto", None)
    assert not camera_travels("auto", "turning")
    assert not camera_travels("still", "moving")
    assert camera_travels("travelling", None)
    with pytest.raises(PhysposeError, match="camera"):
        DynamicsConfig(camera="dolly")


def test_weighted_median():
    assert weighted_median(np.array([3.0, 1.0, 2.0]), np.ones(3)) == 2.0
    assert weighted_median(np.array([0.0, 10.0]), np.array([1.0, 3.0])) == 10.0


def test_a_still_camera_does_not_travel(body):
    travel = camera_travel(body.model, standing_on_left(body), FPS)
    assert travel.shape == (FRAMES, 3)
    assert np.abs(travel).max() < 0.01  # the swinging foot is in the air: it does not count


def test_travel_is_read_off_the_standing_foot(body):
    """A camera moving at 1.5 m/s along x sees the body (and its standing foot) go back."""
    qpos = standing_on_left(body)
    speed = np.array([1.5, -0.3])
    moved = qpos.copy()
    moved[:, :2] -= np.arange(FRAMES)[:, None] / FPS * speed
    travel = camera_travel(body.model, moved, FPS)
    expected = np.arange(FRAMES)[:, None] / FPS * speed
    assert np.allclose(travel[:, :2], expected, atol=0.03)
    assert np.all(travel[:, 2] == 0.0)


def test_reprojection_through_the_travelling_camera(body):
    """The motion in the world scores as the travelling camera filmed it."""
    world = standing_on_left(body)[:10]
    travel = np.zeros((10, 3))
    travel[:, 0] = np.linspace(0.0, 0.5, 10)
    filmed = world.copy()
    filmed[:, :3] -= travel
    K, T = virtual_camera()
    _, filmed_landmarks = fk_mujoco(body, filmed)
    uv = project(filmed_landmarks, K, T)
    keypoints = np.concatenate([uv, np.full(uv.shape[:-1] + (1,), 0.9)], axis=-1)
    joints, landmarks = fk_mujoco(body, world)
    samples = FrameSamples(qpos=world[None], landmarks=landmarks[None], joints=joints[None],
                           com=world[None, :, :3], broken=np.zeros((1, 10), dtype=bool))
    frames = np.arange(10)
    following = make_reference(body.model, world, keypoints, K, T, FPS, camera_travel=travel)
    still = make_reference(body.model, world, keypoints, K, T, FPS)
    assert evaluate_terms(samples, following, frames)["reprojection"][0] < 1e-9
    assert evaluate_terms(samples, still, frames)["reprojection"][0] > 1e-3


def test_a_reconstruction_as_filmed(tmp_path):
    rec = make_reconstruction(physics=True)
    t = rec.num_frames
    travel = np.zeros((t, 3))
    travel[:, 0] = np.linspace(0.0, 2.0, t)
    moved = rec.replace(camera_travel_physics=travel)
    assert np.allclose(moved.as_filmed(moved.joints_physics), rec.joints_physics - travel[:, None])
    assert np.allclose(moved.as_filmed(moved.joints_physics, "physics")[:, 0],
                       rec.joints_physics[:, 0] - travel)
    assert moved.as_filmed(moved.joints_kinematic, "kinematic") is moved.joints_kinematic
    assert rec.as_filmed(rec.joints_physics) is rec.joints_physics  # a still camera
    loaded = type(rec).load(moved.save(tmp_path / "reconstruction.npz"))
    assert np.array_equal(loaded.camera_travel_physics, travel)
    with pytest.raises(PhysposeError, match="camera_travel_physics"):
        rec.replace(camera_travel_physics=np.zeros((t + 1, 3)))


def test_image_error_of_a_travelling_camera_is_taken_as_filmed():
    """Physics that is the estimate moved on by the camera's travel projects where the
    estimate does."""
    rec = make_reconstruction(physics=True)
    travel = np.zeros((rec.num_frames, 3))
    travel[:, :2] = np.linspace(0.0, 1.5, rec.num_frames)[:, None]
    moved = rec.replace(joints_physics=rec.joints_kinematic + travel[:, None],
                        landmarks_physics=rec.landmarks_kinematic + travel[:, None],
                        camera_travel_physics=travel)
    kinematic = motion_metrics(moved, "kinematic")["mpjpe_2d_px"]
    assert motion_metrics(moved, "physics")["mpjpe_2d_px"] == pytest.approx(kinematic)
    assert motion_metrics(moved.replace(camera_travel_physics=None),
                          "physics")["mpjpe_2d_px"] > kinematic + 3.0


def test_the_overlay_films_the_physics_through_the_travelling_camera():
    rec = make_reconstruction(physics=True)
    travel = np.zeros((rec.num_frames, 3))
    travel[:, 0] = np.linspace(0.0, 3.0, rec.num_frames)
    moved = rec.replace(camera_travel_physics=travel)
    t = rec.num_frames - 1
    camera = _filming(moved, "physics", rec.camera_T_world2cam, t)
    seen = transform_points(camera, moved.joints_physics[t])
    filmed = transform_points(rec.camera_T_world2cam, moved.as_filmed(moved.joints_physics)[t])
    assert np.allclose(seen, filmed)
    assert np.array_equal(_filming(moved, "kinematic", rec.camera_T_world2cam, t),
                          rec.camera_T_world2cam)
