"""The observations as the fit uses them: confidence weights, MediaPipe's 3d in the ray frame,
seed frames, and arrays padded to a few lengths so compiled objectives are reused."""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from physpose.errors import PhysposeError
from physpose.kinematics.losses import Data
from physpose.observations import Observations
from physpose.pinhole import hip_ray_frames

_MIN_LANDMARKS = 8  # a frame with fewer confident landmarks carries no evidence


@dataclass(frozen=True, eq=False)
class Evidence:
    """Per-frame evidence of T frames (camera axes, metres, pixels)."""

    fps: float
    uv: np.ndarray          # (T, 33, 2) px
    weight: np.ndarray      # (T, 33) confidence, 0 below the threshold and in empty frames
    world_ray: np.ndarray   # (T, 33, 3) MediaPipe's hip-centred landmarks, ray frame
    R_ray: np.ndarray       # (T, 3, 3) camera from ray frame (identity if not ray-aligned)
    valid: np.ndarray       # (T,) frames with evidence

    @property
    def num_frames(self) -> int:
        return int(self.uv.shape[0])

    def world_cam(self, depth_scale: float = 1.0, scale: float = 1.0) -> np.ndarray:
        """(T, 33, 3) MediaPipe's landmarks in camera axes, depth (along the ray) scaled."""
        w = self.world_ray * np.array([1.0, 1.0, depth_scale]) * scale
        return np.einsum("tij,tpj->tpi", self.R_ray, w)

    def nearest_valid(self) -> np.ndarray:
        """(T,) index of the nearest frame with evidence (itself where valid)."""
        good = np.flatnonzero(self.valid)
        frames = np.arange(self.num_frames)
        after = np.clip(np.searchsorted(good, frames), 0, len(good) - 1)
        before = np.clip(after - 1, 0, len(good) - 1)
        pick = np.where(np.abs(good[before] - frames) <= np.abs(good[after] - frames),
                        good[before], good[after])
        return pick


def gather_evidence(obs: Observations, K: np.ndarray, min_confidence: float,
                    ray_aligned: bool) -> Evidence:
    """Evidence from observations; PhysposeError if there is nothing to fit."""
    if obs.world_landmarks is None:
        raise PhysposeError("the kinematic fit needs MediaPipe's metric world landmarks, and "
                            "these observations have none", path=obs.source,
                            remedy="observe the video with `physpose observe`, or add "
                                   "world_landmarks to the keypoints file")
    kp = np.asarray(obs.keypoints2d, dtype=float)
    conf = np.where(kp[..., 2] >= min_confidence, kp[..., 2], 0.0)
    conf[~obs.valid] = 0.0
    valid = (conf > 0).sum(axis=1) >= _MIN_LANDMARKS
    conf[~valid] = 0.0
    if not valid.any():
        raise PhysposeError(f"no frame has {_MIN_LANDMARKS} or more landmarks with confidence "
                            f">= {min_confidence:g}", path=obs.source,
                            remedy="check that the person is visible (see the observe overlay)")
    uv = kp[..., :2]
    if ray_aligned:
        R_ray = hip_ray_frames(uv, conf, K)
        R_ray[~valid] = np.eye(3)
    else:
        R_ray = np.broadcast_to(np.eye(3), (len(kp), 3, 3)).copy()
    world = np.asarray(obs.world_landmarks, dtype=float)
    return Evidence(fps=float(obs.fps), uv=uv, weight=conf, world_ray=world, R_ray=R_ray,
                    valid=valid)


def seed_frames(ev: Evidence, n: int, spacing: int) -> np.ndarray:
    """Up to n frames with the highest mean confidence, at least `spacing` frames apart while
    enough such frames exist (sorted)."""
    score = np.where(ev.valid, ev.weight.mean(axis=1), -1.0)
    order = np.argsort(-score, kind="stable")
    order = order[score[order] > 0]
    for gap in range(max(spacing, 0), -1, -1):
        chosen: list[int] = []
        for f in order:
            if all(abs(int(f) - c) >= gap for c in chosen):
                chosen.append(int(f))
                if len(chosen) == n:
                    return np.array(sorted(chosen))
        if gap == 0:
            return np.array(sorted(chosen))
    raise AssertionError("unreachable")


def padded_length(t: int) -> int:
    """The smallest of 16, 24, 32, 48, 64, 96, ... (2^k and 1.5 x 2^k) that holds t frames."""
    size = 16
    while size < t:
        size = size * 3 // 2 if size & (size - 1) == 0 else size * 4 // 3
    return size


def pad(a: np.ndarray, length: int) -> np.ndarray:
    """Repeat the last row of a (T, ...) array up to `length` rows."""
    a = np.asarray(a)
    if len(a) >= length:
        return a
    return np.concatenate([a, np.repeat(a[-1:], length - len(a), axis=0)])


def data_for(ev: Evidence, frames: np.ndarray, m_per_px: np.ndarray, plane: np.ndarray,
             length: int, support: np.ndarray | None = None) -> Data:
    """Objective data for the given frames (indices into ev), padded to `length` frames.

    m_per_px: (len(frames),) metres per pixel at the person; plane: (4,) n, d; support:
    (len(frames),) m above the plane where the feet stand (default 0, the floor).
    """
    n = len(frames)
    if support is not None and np.shape(support) != (n,):
        raise ValueError(f"support heights of shape {np.shape(support)} for {n} frames")
    weight = np.zeros(length)
    weight[:n] = 1.0
    w2d = pad(ev.weight[frames], length) * weight[:, None]
    return Data(
        uv=jnp.asarray(pad(ev.uv[frames], length)), w2d=jnp.asarray(w2d),
        m_per_px=jnp.asarray(pad(m_per_px, length)),
        world=jnp.asarray(pad(ev.world_ray[frames], length)), w3d=jnp.asarray(w2d),
        R_ray=jnp.asarray(pad(ev.R_ray[frames], length)), frame_weight=jnp.asarray(weight),
        plane=jnp.asarray(np.asarray(plane, dtype=float)), fps=jnp.asarray(ev.fps),
        support=jnp.asarray(pad(np.zeros(n) if support is None
                                else np.asarray(support, dtype=float), length)))
