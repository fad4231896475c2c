import numpy as np
import pytest

from physpose.errors import PhysposeError
from physpose.joints import (
    JOINT_NAMES,
    LANDMARK_INDEX,
    NUM_LANDMARKS,
    joint_confidence,
    joints_from_landmarks,
)
from physpose.observations import Observations


def _obs(t: int = 4, **changes) -> Observations:
    rng = np.random.default_rng(0)
    kp = np.concatenate([rng.uniform(0, 100, (t, NUM_LANDMARKS, 2)),
                         rng.uniform(0, 1, (t, NUM_LANDMARKS, 1))], axis=-1)
    fields = dict(source="clip.mp4", fps=25.0, image_size=(640, 480),
                  timestamps=np.arange(t) / 25.0, keypoints2d=kp,
                  detected=np.ones(t, bool), interpolated=np.zeros(t, bool),
                  world_landmarks=rng.normal(size=(t, NUM_LANDMARKS, 3)))
    fields.update(changes)
    return Observations(**fields)


def test_save_load_roundtrip(tmp_path):
    obs = _obs()
    back = Observations.load(obs.save(tmp_path / "o.npz"))
    np.testing.assert_array_equal(back.keypoints2d, obs.keypoints2d)
    np.testing.assert_array_equal(back.world_landmarks, obs.world_landmarks)
    assert back.image_size == (640, 480) and back.fps == 25.0 and back.masks is None
    assert back.unsure is None


def test_frames_left_out_as_torn_are_saved_and_sliced_with_the_rest(tmp_path):
    unsure = np.array([1, 0, 0, 1], bool)
    obs = _obs(detected=~unsure, unsure=unsure)
    back = Observations.load(obs.save(tmp_path / "o.npz"))
    assert back.unsure.dtype == bool and back.unsure.tolist() == [1, 0, 0, 1]
    assert obs.frames(1, 4).unsure.tolist() == [0, 0, 1]


def test_nan_keypoints_name_file_and_frame():
    kp = _obs().keypoints2d.copy()
    kp[2, 5, 0] = np.nan
    with pytest.raises(PhysposeError, match=r"clip\.mp4, frame 2: keypoints2d contains NaN"):
        _obs(keypoints2d=kp)


@pytest.mark.parametrize("change, message", [
    (dict(fps=0.0), "frame rate"),
    (dict(keypoints2d=np.zeros((4, 17, 3))), "expected"),
    (dict(detected=np.ones(3, bool)), "detected has shape"),
    (dict(unsure=np.zeros(5, bool)), "unsure has shape"),
    (dict(unsure=np.array([0, 2, 0, 0])), "expected \\(4,\\) bool"),
    (dict(detected=np.ones(4, int)), "detected has type int64, expected bool"),
    (dict(image_size=(float("nan"), 480)), "image size"),
    (dict(frame_indices=np.arange(5)), "frame_indices has shape \\(5,\\), expected \\(4,\\)"),
    (dict(interpolated=np.zeros(4)), "interpolated has type float64, expected bool"),
])
def test_malformed_fields_are_rejected(change, message):
    with pytest.raises(PhysposeError, match=message):
        _obs(**change)


def test_load_missing_file_gives_remedy(tmp_path):
    with pytest.raises(PhysposeError, match="physpose observe"):
        Observations.load(tmp_path / "nope.npz")


def test_joint_proxies_from_landmarks():
    lm = np.arange(NUM_LANDMARKS * 3, dtype=float).reshape(NUM_LANDMARKS, 3)
    joints = joints_from_landmarks(lm)
    assert joints.shape == (len(JOINT_NAMES), 3)
    np.testing.assert_allclose(joints[0], 0.5 * (lm[23] + lm[24]))  # pelvis = mid-hips


def test_a_proxy_joint_is_as_sure_as_its_least_sure_landmark():
    conf = np.ones((2, NUM_LANDMARKS))
    conf[1, LANDMARK_INDEX["right_hip"]] = 0.0             # one hip lost in the second frame
    joints = joint_confidence(conf)
    assert joints.shape == (2, len(JOINT_NAMES)) and (joints[0] == 1.0).all()
    lost = {JOINT_NAMES[j] for j in np.flatnonzero(joints[1] == 0.0)}
    assert lost == {"pelvis", "spine", "r_hip"}             # the mean would have kept 0.5
    assert (joints[1][[JOINT_NAMES.index(n) for n in JOINT_NAMES if n not in lost]] == 1).all()


def test_reconstruction_roundtrip(tmp_path):
    from physpose.reconstruction import Reconstruction

    t = 3
    rec = Reconstruction(fps=25.0, joint_names=JOINT_NAMES,
                         joints_kinematic=np.zeros((t, len(JOINT_NAMES), 3)),
                         camera_K=np.eye(3), camera_T_world2cam=np.eye(4),
                         landmarks_kinematic=np.zeros((t, NUM_LANDMARKS, 3)),
                         keypoints2d=np.zeros((t, NUM_LANDMARKS, 3)), meta={"variant": "SO+GT"})
    back = Reconstruction.load(rec.save(tmp_path / "reconstruction.npz").parent)
    assert back.joint_names == JOINT_NAMES and back.meta == {"variant": "SO+GT"}
    assert not back.has_physics and back.joints().shape == (t, len(JOINT_NAMES), 3)


def test_slow_motion_footage_is_put_on_the_real_clock():
    obs = _obs(6, frame_indices=np.arange(6) * 4)
    real = obs.on_real_clock(4.0)
    assert real.fps == 100.0 and real.num_frames == 6
    np.testing.assert_allclose(real.timestamps, np.arange(6) / 100.0)
    # The frames still name the same images of the footage.
    np.testing.assert_array_equal(real.frame_indices, obs.frame_indices)
    np.testing.assert_array_equal(real.keypoints2d, obs.keypoints2d)
    assert obs.on_real_clock(1.0) is obs
    assert obs.on_real_clock(0.5).fps == 12.5  # sped-up footage
    for bad in (0.0, -2.0, float("nan"), 1000.0):
        with pytest.raises(PhysposeError, match="slow motion"):
            obs.on_real_clock(bad)


def test_keypoints_normalised_to_0_1_are_refused_with_the_scaling():
    pixels = _obs().keypoints2d
    normalised = pixels.copy()
    normalised[..., 0] /= 640.0
    normalised[..., 1] /= 480.0
    with pytest.raises(PhysposeError, match="look normalised") as err:
        _obs(keypoints2d=normalised)
    assert "multiply x by the width (640) and y by the height (480)" in str(err.value)
    unsure = normalised.copy()
    unsure[..., 2] = 0.1  # too unsure to tell: left to the later checks
    assert _obs(keypoints2d=unsure).num_frames == 4


@pytest.mark.parametrize("name", ["o", "o.data"])
def test_saved_under_any_name_and_loaded_back(tmp_path, name):
    obs = _obs()
    back = Observations.load(obs.save(tmp_path / name))
    np.testing.assert_array_equal(back.keypoints2d, obs.keypoints2d)


def test_a_hand_made_file_with_an_odd_frame_rate_is_named(tmp_path):
    obs = _obs()
    fields = dict(fps=np.array([25.0, 25.0]), image_size=np.array(obs.image_size),
                  timestamps=obs.timestamps, keypoints2d=obs.keypoints2d,
                  detected=obs.detected, interpolated=obs.interpolated)
    np.savez(tmp_path / "hand.npz", **fields)
    with pytest.raises(PhysposeError, match=r"hand\.npz: fps .* is not a frame rate"):
        Observations.load(tmp_path / "hand.npz")


def test_keypoints_mapped_into_a_wide_pans_middle_view_load_back(tmp_path):
    # A turning camera's keypoints live in the middle frame's image, which a pan of +-50
    # degrees stretches from about -2 to +2 pictures: observe's own file must load.
    kp = _obs().keypoints2d.copy()
    kp[0, :, 0] -= 2000.0
    kp[3, :, 0] += 2500.0
    kp[..., 2] = 0.9
    obs = _obs(keypoints2d=kp, homographies=np.repeat(np.eye(3)[None], 4, axis=0),
               camera_motion="turning")
    back = Observations.load(obs.save(tmp_path / "o.npz"))
    np.testing.assert_array_equal(back.keypoints2d, kp)
