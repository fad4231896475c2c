"""A camera that turns while filming: measured from the background, and the detections mapped
into one camera (physpose.camera_motion)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import numpy as np
import pytest

from physpose.camera_motion import (CameraMotion, estimate_camera_motion, frame_cameras,
                                    nearest_rotations, stabilize)
from physpose.diagnostics import camera_message, warning_lines
from physpose.joints import NUM_LANDMARKS
from physpose.observations import Observations
from physpose.observe import ObserveConfig, observe
from physpose.pinhole import intrinsics
from physpose.video import plan_frames, probe

SIZE = (640, 360)
FOCAL = 500.0
SHARED_VIDEOS = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "video"


def _turn(yaw: float, pitch: float = 0.0) -> np.ndarray:
    """Directions in the reference camera -> the turned camera's."""
    return cv2.Rodrigues(np.array([pitch, 0.0, 0.0]))[0] @ cv2.Rodrigues(
        np.array([0.0, yaw, 0.0]))[0]


def _no_person(n: int) -> Observations:
    return Observations(source="synthetic", fps=25.0, image_size=SIZE,
                        timestamps=np.arange(n) / 25.0,
                        keypoints2d=np.zeros((n, NUM_LANDMARKS, 3)),
                        detected=np.zeros(n, bool), interpolated=np.zeros(n, bool))


def _write(path: Path, warps: list[np.ndarray]) -> Path:
    """A video of a smooth random texture (three times the frame) seen through each warp
    (texture pixels, centred on the frame -> frame pixels)."""
    rng = np.random.default_rng(0)
    w, h = SIZE
    texture = cv2.GaussianBlur(rng.uniform(0, 255, (3 * h, 3 * w, 3)).astype(np.uint8), (0, 0), 2)
    centre = np.array([[1.0, 0.0, -w], [0.0, 1.0, -h], [0.0, 0.0, 1.0]])
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25, SIZE)
    for warp in warps:
        writer.write(cv2.warpPerspective(texture, warp @ centre, SIZE))
    writer.release()
    return path


def _motion(path: Path, n: int):
    info = probe(path)
    return estimate_camera_motion(info, plan_frames(info, 25), _no_person(n))


def test_a_turning_camera_is_measured_with_its_focal_length(tmp_path):
    k = intrinsics(SIZE, FOCAL)
    n = 30
    yaws = np.radians(np.linspace(-8.0, 8.0, n))
    turns = [_turn(a, 0.25 * a) for a in yaws]
    motion = _motion(_write(tmp_path / "pan.avi", [k @ r @ np.linalg.inv(k) for r in turns]), n)
    assert motion.kind == "turning" and motion.reference == n // 2
    assert motion.focal == pytest.approx(FOCAL, rel=0.05)
    truth = np.array(turns) @ turns[n // 2].T      # the reference camera -> frame t's
    angle = np.degrees(np.arccos(np.clip((np.trace(
        motion.rotations @ np.swapaxes(truth, 1, 2), axis1=1, axis2=2) - 1) / 2, -1, 1)))
    assert angle.max() < 0.3
    assert motion.turned_deg == pytest.approx(np.degrees(np.linalg.norm(
        cv2.Rodrigues(truth[0])[0])), abs=0.3)


def test_a_still_camera_is_static_and_a_travelling_or_zooming_one_is_moving(tmp_path):
    n = 20
    still = _motion(_write(tmp_path / "still.avi", [np.eye(3)] * n), n)
    assert still.kind == "static" and still.turned_deg < 0.2
    # A camera travelling 0.6 m sideways 1.5 m above a floor that fills the picture, looking
    # 30 degrees down: the floor shears as no turn of the camera can make it (parallax).
    k = intrinsics(SIZE, FOCAL)
    floor = np.array([0.0, np.cos(np.radians(30)), np.sin(np.radians(30))])  # camera axes
    travels = [k @ (np.eye(3) + np.outer([x, 0.0, 0.0], floor) / 1.5) @ np.linalg.inv(k)
               for x in np.linspace(0.0, 0.6, n)]
    assert _motion(_write(tmp_path / "travel.avi", travels), n).kind == "moving"
    # Zooming in by 30 % changes the focal length, which no turn does either.
    w, h = SIZE
    zooms = [np.array([[z, 0, (1 - z) * w / 2], [0, z, (1 - z) * h / 2], [0, 0, 1.0]])
             for z in np.linspace(1.0, 1.3, n)]
    assert _motion(_write(tmp_path / "zoom.avi", zooms), n).kind == "moving"


def test_stabilized_detections_are_in_the_reference_camera_and_map_back():
    n = 5
    k = intrinsics(SIZE, FOCAL)
    turns = np.array([_turn(a) for a in np.radians(np.linspace(-6, 6, n))])
    homographies = k @ turns @ np.linalg.inv(k)
    rng = np.random.default_rng(1)
    reference = np.concatenate([rng.uniform(100, 300, (n, NUM_LANDMARKS, 2)),
                                np.full((n, NUM_LANDMARKS, 1), 0.9)], axis=-1)
    direction = rng.normal(size=(n, NUM_LANDMARKS, 3))
    seen = np.concatenate([reference[..., :2], np.ones((n, NUM_LANDMARKS, 1))], axis=-1)
    seen = np.einsum("tij,tnj->tni", homographies, seen)
    obs = dataclasses.replace(_no_person(n), detected=np.ones(n, bool),
                              keypoints2d=np.concatenate([seen[..., :2] / seen[..., 2:],
                                                          reference[..., 2:]], axis=-1),
                              world_landmarks=np.einsum("tij,tnj->tni", turns, direction))
    motion = CameraMotion(kind="turning", reference=2, homographies=homographies,
                          rotations=turns, focal=FOCAL, turned_deg=6.0, skew=0.0)
    out = stabilize(obs, motion)
    np.testing.assert_allclose(out.keypoints2d, reference, atol=1e-6)
    np.testing.assert_allclose(out.world_landmarks, direction, atol=1e-9)
    np.testing.assert_allclose(out.frame_keypoints(), obs.keypoints2d, atol=1e-6)
    np.testing.assert_allclose(out.camera_K, k)
    assert out.camera_motion == "turning"
    # Each frame's camera for drawing: the reference camera turned.
    t_ref = np.eye(4)
    t_ref[:3, 3] = [0.1, 1.2, 3.0]
    cameras = frame_cameras(homographies, k, t_ref)
    np.testing.assert_allclose(cameras[:, :3, :3], turns, atol=1e-9)
    np.testing.assert_allclose(nearest_rotations(homographies, k), turns, atol=1e-9)
    # Static and moving cameras leave the detections as they are.
    for kind in ("static", "moving"):
        kept = stabilize(obs, dataclasses.replace(motion, kind=kind))
        assert kept.keypoints2d is obs.keypoints2d and kept.homographies is None
        assert kept.camera_motion == kind


def test_camera_fields_survive_save_and_load(tmp_path):
    n = 4
    obs = dataclasses.replace(_no_person(n), homographies=np.repeat(np.eye(3)[None], n, 0),
                              camera_motion="turning")
    back = Observations.load(obs.save(tmp_path / "obs.npz"))
    assert back.camera_motion == "turning"
    np.testing.assert_allclose(back.homographies, obs.homographies)


def test_a_moving_camera_is_warned_about():
    assert camera_message("static") is None and camera_message("turning") is None
    assert camera_message(None) is None
    assert "camera moves" in camera_message("moving")
    assert any("camera moves" in line for line in warning_lines({"camera_motion": "moving"}, 25))


def test_a_real_view_filmed_by_a_turning_camera_is_seen_as_by_the_still_one(pose2sim_demo,
                                                                            tmp_path):
    """pose2sim's cam01 warped as if its camera turned 10 degrees either way (and tilted):
    the stabilized detections land where the still camera's are (the middle frame's camera
    is the still one, to within 0.2 degrees)."""
    video = pose2sim_demo / "videos" / "cam01.mp4"
    source = cv2.VideoCapture(str(video))
    n = int(source.get(cv2.CAP_PROP_FRAME_COUNT))
    k = np.array([[1681.2, 0.0, 533.0], [0.0, 1681.1, 948.1], [0.0, 0.0, 1.0]])  # calibrated
    path = tmp_path / "turning.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 60, (1080, 1920))
    for i in range(n):
        _, image = source.read()
        a = np.radians(10.0) * np.sin(np.pi * i / (n - 1) - np.pi / 2)
        turn = _turn(a, np.radians(2.5) * np.sin(2 * np.pi * i / (n - 1)))
        writer.write(cv2.warpPerspective(image, k @ turn @ np.linalg.inv(k), (1080, 1920)))
    writer.release()
    still = observe(video, ObserveConfig(use_cache=False), progress=False)
    turned = observe(path, ObserveConfig(use_cache=False), progress=False)
    assert still.camera_motion == "static" and still.homographies is None
    assert turned.camera_motion == "turning"
    both = still.detected & turned.detected
    seen = still.keypoints2d[..., 2] > 0.5
    error = np.linalg.norm(turned.keypoints2d[..., :2] - still.keypoints2d[..., :2], axis=-1)
    assert both.mean() > 0.9 and np.median(error[both][seen[both]]) < 15.0
    assert turned.camera_K[0, 0] == pytest.approx(1681.0, rel=0.05)   # self-calibrated
    # Taken as static, the same detections are hundreds of pixels off at the ends.
    raw = observe(path, ObserveConfig(use_cache=False, stabilize=False), progress=False)
    assert raw.camera_motion is None
    assert np.median(np.linalg.norm(raw.keypoints2d[0, :, :2] - still.keypoints2d[0, :, :2],
                                    axis=-1)) > 150.0


@pytest.mark.parametrize("name, kind", [("taichi_static.mp4", "static"),
                                        ("running_track_panning.mp4", "moving"),
                                        ("walking_road_moving_camera.mp4", "moving")])
def test_the_shared_videos_cameras(name, kind):
    """The tripod clip is static; the two clips filmed by a camera that travels with the person
    (parallax: the near floor slides past faster than the far wall) are moving."""
    path = SHARED_VIDEOS / name
    if not path.is_file():
        pytest.skip(f"{path} not found (evaluation material in ../shared/data)")
    obs = observe(path, ObserveConfig(end=3.0), progress=False)
    assert obs.camera_motion == kind
