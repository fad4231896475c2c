"""The kinematic fit end to end on synthetic clips: exact recovery from perfect observations,
every variant on noisy ones, the cache, and bad input."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_kinematics_fixtures import synthetic_clip

from physpose.errors import PhysposeError
from physpose.fk import fk_qpos
from physpose.kinematics import KinematicConfig, fit_kinematics
from physpose.kinematics.config import VARIANT_NAMES, GroundConfig, PoseConfig
from physpose.kinematics import fit as fit_module
from physpose.kinematics.fit import fit_variants
from physpose.joints import LANDMARK_INDEX
from physpose.metrics import foot_points, transform_points
from physpose.skeleton import DOF_NAMES


def _camera_landmarks(fit) -> np.ndarray:
    return transform_points(fit.T_world2cam, fit.landmarks)


@pytest.fixture(scope="module")
def perfect():
    return synthetic_clip(frames=10)


def test_recovers_known_pose_and_camera_from_perfect_landmarks(perfect):
    fit = fit_kinematics(perfect.observations, KinematicConfig.preset("SO", use_cache=False),
                         height=perfect.shape.height)
    err = np.linalg.norm(_camera_landmarks(fit) - perfect.landmarks_cam, axis=-1)
    assert err.mean() < 0.01 and np.percentile(err, 95) < 0.02, err.mean()
    assert np.allclose(fit.camera_K, perfect.K)
    assert np.abs(fit.shape.bones() - perfect.shape.bones()).max() < 0.01
    # The body re-projects onto the detections to well under a pixel.
    uv = _camera_landmarks(fit) @ fit.camera_K.T
    px = np.linalg.norm(uv[..., :2] / uv[..., 2:] - perfect.observations.keypoints2d[..., :2],
                        axis=-1)
    assert px.mean() < 0.5


def test_the_depth_scale_prior_is_centred_where_configured():
    """A detector whose depth along the ray is 0.61 x the body's: a prior centred at 1 / 0.61
    recovers the body as if the depth were right, the default prior (centred at 1) less well."""
    clip = synthetic_clip(frames=10, depth_scale=0.61)
    errors, factors = [], []
    for centre in (1.0, 1.0 / 0.61):
        cfg = KinematicConfig.preset("SO", use_cache=False)
        cfg = dataclasses.replace(cfg, pose=dataclasses.replace(
            cfg.pose, depth_scale_prior_centre=centre))
        fit = fit_kinematics(clip.observations, cfg, height=clip.shape.height)
        errors.append(np.linalg.norm(_camera_landmarks(fit) - clip.landmarks_cam, axis=-1))
        factors.append(fit.losses["depth_scale"])
    default, centred = errors
    assert centred.mean() < 0.01 and np.percentile(centred, 95) < 0.02, centred.mean()
    assert centred.mean() < 0.7 * default.mean(), (centred.mean(), default.mean())
    assert abs(factors[1] * 0.61 - 1.0) < 0.05, factors  # the fit undid the compression


@pytest.mark.parametrize("bad", [dict(depth_scale_prior_centre=0.0),
                                 dict(depth_scale_prior_centre=5.0),
                                 dict(depth_scale_log_sigma=0.0)])
def test_bad_depth_scale_priors_are_refused(bad):
    with pytest.raises(PhysposeError, match="depth_scale"):
        PoseConfig(**bad)


def _raise_arms(qpos: np.ndarray) -> np.ndarray:
    """Both arms abducted 120-170 degrees (overhead), elbows slightly bent."""
    t = np.arange(len(qpos)) / 25.0
    abduction = np.radians(145.0 + 25.0 * np.sin(2 * np.pi * 0.7 * t))
    for side, sign in (("l", 1.0), ("r", -1.0)):
        qpos[:, 7 + DOF_NAMES.index(f"{side}_shoulder_x")] = sign * abduction
        qpos[:, 7 + DOF_NAMES.index(f"{side}_shoulder_y")] = 0.0
        qpos[:, 7 + DOF_NAMES.index(f"{side}_elbow_y")] = -0.3
    return qpos


def test_arms_raised_overhead_are_recovered():
    """The initial IK must pick the Euler form an overhead shoulder needs; started from the
    clipped other form, the fit stayed 16 cm off at the wrists (stop 35)."""
    clip = synthetic_clip(frames=16, noise_px=2.0, noise_3d=0.02, seed=1, edit_qpos=_raise_arms)
    fit = fit_kinematics(clip.observations, KinematicConfig.preset("SO", use_cache=False),
                         height=clip.shape.height)
    err = np.linalg.norm(_camera_landmarks(fit) - clip.landmarks_cam, axis=-1)
    wrists = [LANDMARK_INDEX["left_wrist"], LANDMARK_INDEX["right_wrist"]]
    assert err[:, wrists].mean() < 0.06, err[:, wrists].mean()  # old IK: 0.16 m


def test_result_is_consistent_in_the_world_frame(perfect):
    fit = fit_kinematics(perfect.observations, KinematicConfig.preset("SO+G", use_cache=False),
                         height=perfect.shape.height)
    joints, landmarks = fk_qpos(fit.shape.bones(), fit.qpos)
    assert np.allclose(joints, fit.joints) and np.allclose(landmarks, fit.landmarks)
    assert np.allclose(np.linalg.norm(fit.qpos[:, 3:7], axis=1), 1.0)
    R = fit.T_world2cam[:3, :3]
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-9)
    # The estimated floor is the true one (the true normal in camera axes, within 2 degrees).
    n_true = perfect.T_world2cam[:3, :3] @ [0.0, 0.0, 1.0]
    angle = np.degrees(np.arccos(np.clip(R @ [0.0, 0.0, 1.0] @ n_true, -1, 1)))
    assert angle < 2.0, angle
    # Origin under the first pelvis; the lowest sole sample touches the floor.
    assert np.allclose(fit.qpos[0, :2], 0.0, atol=1e-6)
    assert fit.ground_estimated and fit.variant == "SO+G"


@pytest.fixture(scope="module")
def noisy_fits():
    clip = synthetic_clip(frames=16, noise_px=2.0, noise_3d=0.03, seed=1, with_K=False)
    return clip, fit_variants(clip.observations, VARIANT_NAMES, KinematicConfig(use_cache=False))


@pytest.mark.parametrize("variant", VARIANT_NAMES)
def test_every_variant_runs(noisy_fits, variant):
    clip, fits = noisy_fits
    fit = fits[variant]
    n = clip.observations.num_frames
    assert fit.variant == variant
    assert fit.qpos.shape == (n, 55) and fit.joints.shape == (n, 21, 3)
    assert np.isfinite(fit.qpos).all() and np.isfinite(fit.landmarks).all()
    assert fit.ground_estimated == ("G" in variant)
    # Estimated intrinsics (none were given) and a sensible body.
    assert fit.camera_K[0, 0] > 0 and 1.4 < fit.shape.height < 2.1
    # Root-relative (the focal length, hence the depth, is only a prior without K).
    est, true = _camera_landmarks(fit), clip.landmarks_cam
    err = np.linalg.norm((est - est[:, 23:25].mean(1, keepdims=True))
                         - (true - true[:, 23:25].mean(1, keepdims=True)), axis=-1)
    assert np.median(err) < 0.06, (variant, np.median(err))
    assert {"shape", "init"} <= set(fit.timings)


def test_temporal_term_smooths(noisy_fits):
    _, fits = noisy_fits
    acc = {v: np.abs(np.diff(fits[v].joints, 2, axis=0)).mean() for v in ("SO", "SO+T")}
    assert acc["SO+T"] < 0.7 * acc["SO"], acc


def test_feet_that_stay_raised_stand_still_on_their_support():
    """A person standing still, on the floor, then on a 1 m platform for 1.1 s, then on the
    floor again, seen with noise: the ground and skate terms hold the feet on the platform's
    top as they hold them on the floor (without the support pass the raised feet jitter over
    three times as fast as the floor's, 0.26 against 0.07 m/s, and stand 8 mm off the top)."""
    def on_a_platform(q):
        q[:] = q[0]
        q[15:43, 2] += 1.0
        return q

    clip = synthetic_clip(frames=58, noise_px=2.0, noise_3d=0.05, seed=2,
                          edit_qpos=on_a_platform)
    fit = fit_kinematics(clip.observations, KinematicConfig(use_cache=False))
    soles = foot_points(fit.joints)
    speed = np.linalg.norm(np.diff(soles.mean(axis=2)[..., :2], axis=0), axis=-1) * fit.fps
    floor = np.r_[speed[:12], speed[46:]].mean()
    raised = speed[18:40].mean()
    assert raised < 1.5 * floor, (raised, floor)
    lowest = soles[18:40, ..., 2].min(axis=-1)
    assert np.abs(lowest - 1.0).mean() < 0.004
    # The fit says what it stood them on: the platform's top there, the floor elsewhere.
    assert fit.support_heights[18:40] == pytest.approx(1.0, abs=0.01)
    assert (fit.support_heights[:12] == 0).all() and (fit.support_heights[46:] == 0).all()


def test_without_raised_feet_the_support_pass_changes_nothing(noisy_fits):
    clip, fits = noisy_fits
    off = fit_variants(clip.observations, ("SO+GT",), KinematicConfig(
        use_cache=False, ground_plane=GroundConfig(raised_supports=False)))["SO+GT"]
    assert fits["SO+GT"].support_heights is None
    assert np.array_equal(off.qpos, fits["SO+GT"].qpos)


def test_progress_shows_a_bar_per_step_and_changes_nothing(perfect, capsys):
    """A clip of minutes spends minutes in a step: its bar counts the L-BFGS iterations."""
    cfg = KinematicConfig.preset("SO+GT", use_cache=False)
    logged: list[str] = []
    quiet = fit_kinematics(perfect.observations, cfg, height=perfect.shape.height)
    assert capsys.readouterr().err == ""
    shown = fit_kinematics(perfect.observations, cfg, height=perfect.shape.height,
                           log=logged.append, progress=True)
    err = capsys.readouterr().err
    for step in ("init", "pose", "temporal", "ground_plane", "ground_pose"):
        assert f"kinematics {step}:" in err and f"{step} done in" in " ".join(logged), step
    assert "it/s" in err
    assert np.array_equal(quiet.qpos, shown.qpos)


def test_cache_returns_the_same_fit(perfect, tmp_path, monkeypatch):
    monkeypatch.setenv("PHYSPOSE_CACHE_DIR", str(tmp_path))
    cfg = KinematicConfig.preset("S")
    first = fit_kinematics(perfect.observations, cfg)
    assert list((tmp_path / "kinematics").glob("*.npz"))
    second = fit_kinematics(perfect.observations, cfg)
    assert np.array_equal(first.qpos, second.qpos) and first.shape == second.shape
    other = fit_kinematics(perfect.observations, cfg, height=1.6)  # a new key, a new fit
    assert abs(other.shape.height - 1.6) < 1e-6


def test_a_fit_stopped_midway_resumes_after_its_finished_steps(perfect, tmp_path, monkeypatch):
    """Ctrl-C in the ground-plane step of a long clip's fit used to lose the minutes of the
    steps before it: they are kept, read back, and the resumed fit is the unbroken one."""
    monkeypatch.setenv("PHYSPOSE_CACHE_DIR", str(tmp_path))
    cfg = KinematicConfig.preset("SO+GT")
    unbroken = fit_kinematics(perfect.observations, dataclasses.replace(cfg, use_cache=False))
    estimate_ground = fit_module._estimate_ground

    def interrupted(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(fit_module, "_estimate_ground", interrupted)
    with pytest.raises(KeyboardInterrupt):
        fit_kinematics(perfect.observations, cfg)
    steps = tmp_path / "kinematics_steps"
    assert len(list(steps.glob("*.npz"))) == 3  # init, pose, temporal
    monkeypatch.setattr(fit_module, "_estimate_ground", estimate_ground)
    logged: list[str] = []
    resumed = fit_kinematics(perfect.observations, cfg, log=logged.append)
    for step in ("init", "pose", "temporal"):
        assert f"{step}: finished by an earlier run, read back" in logged, step
    assert not any("ground_pose: finished" in line for line in logged)
    assert np.array_equal(resumed.qpos, unbroken.qpos)
    assert np.array_equal(resumed.T_world2cam, unbroken.T_world2cam)
    assert resumed.losses == unbroken.losses
    assert not list(steps.glob("*.npz"))  # the whole fit is cached now


def test_bad_input_is_reported(perfect):
    obs = perfect.observations
    with pytest.raises(PhysposeError, match="world landmarks"):
        fit_kinematics(obs.replace(world_landmarks=None), KinematicConfig(use_cache=False))
    blind = obs.keypoints2d.copy()
    blind[..., 2] = 0.0
    with pytest.raises(PhysposeError, match="no frame"):
        fit_kinematics(obs.replace(keypoints2d=blind), KinematicConfig(use_cache=False))
    with pytest.raises(PhysposeError, match="unknown kinematic variant"):
        KinematicConfig.preset("SOG")
    with pytest.raises(PhysposeError, match="need the pose optimisation"):
        KinematicConfig(optimize_pose=False, ground=True)
    with pytest.raises(PhysposeError, match="pinhole"):
        fit_kinematics(obs, KinematicConfig(use_cache=False), camera_K=np.eye(2))
    with pytest.raises(PhysposeError, match="height"):
        fit_kinematics(obs, KinematicConfig(use_cache=False), height=7.0)


def test_the_fit_runs_in_double_precision_under_old_and_new_jax(monkeypatch):
    """JAX 0.8 made 64-bit mode a config context manager (``jax.enable_x64``) and later releases
    removed ``jax.experimental.enable_x64``, which older ones need: physpose once failed to
    import under JAX 0.11. Whichever this JAX has, the fit's arrays are float64 inside."""
    import jax
    import jax.numpy as jnp

    from physpose.kinematics.precision import double_precision
    with double_precision():
        assert jnp.zeros(2).dtype == jnp.float64
    assert jnp.zeros(2).dtype == jnp.float32
    asked = []
    monkeypatch.setattr(jax, "enable_x64", lambda value: asked.append(value) or "context",
                        raising=False)
    assert double_precision() == "context" and asked == [True]
