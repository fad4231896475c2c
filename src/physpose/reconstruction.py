"""`Reconstruction`: the `reconstruction.npz` contract that benchmarks, exporters and tools read.

See ../shared/DESIGN.md ("Contract"). Beyond it: the kinematic estimate's simulator
coordinates, a travelling camera's path, and the simulation's forces (ground reaction force
per part, centres of pressure, joint torques). Kinematic-only results leave the physics fields
None.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from physpose.errors import PhysposeError, about
from physpose.joints import NUM_LANDMARKS
from physpose.json_text import strict_json
from physpose.npz_io import read_npz, write_npz
from physpose.skeleton import NUM_DOF

_REQUIRED = ("fps", "joint_names", "joints_kinematic", "camera_K", "camera_T_world2cam",
             "landmarks_kinematic", "keypoints2d")
_OPTIONAL = ("joints_physics", "qpos_physics", "landmarks_physics", "body_mjcf", "qpos_kinematic",
             "camera_travel_physics", "grf_physics", "cop_physics", "torques_physics")
# What grf_physics's second axis holds, and torques_physics's columns (skeleton.DOF_NAMES).
GRF_PARTS = ("l_foot", "r_foot", "body")


def restart_frames(windows: list[dict]) -> list[int]:
    """Frames at which a sequential dynamics run restarted from the kinematic state because
    the simulated body had strayed: the first frame of the window after one marked
    ``reset_after``. The motion is not one simulation across such a frame; it jumps there."""
    return [int(windows[i + 1]["frames"][0]) for i, w in enumerate(windows[:-1])
            if isinstance(w, dict) and w.get("reset_after")]


def frame_runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) indices of each run of True in a (T,) bool array."""
    edges = np.diff(np.concatenate([[0], np.asarray(flags, dtype=np.int8), [0]]))
    return [(int(a), int(b) - 1) for a, b in zip(np.flatnonzero(edges == 1),
                                                  np.flatnonzero(edges == -1))]


MOTIONS = ("kinematic", "physics")  # the motions a reconstruction can hold


def _check_motion(which: str) -> None:
    """`which` names a motion, or is "best" (the physics where there is one)."""
    if which != "best" and which not in MOTIONS:
        raise PhysposeError(f"unknown motion {which!r}",
                            remedy=f"use one of best, {', '.join(MOTIONS)}")


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """World-frame motion (z up, ground z = 0, metres) at the analysis frame rate."""

    fps: float
    joint_names: tuple[str, ...]
    joints_kinematic: np.ndarray        # (T, J, 3) kinematic estimate
    camera_K: np.ndarray                # (3, 3)
    camera_T_world2cam: np.ndarray      # (4, 4), OpenCV camera axes
    landmarks_kinematic: np.ndarray     # (T, 33, 3) world positions of the landmark sites
    keypoints2d: np.ndarray             # (T, 33, 3) detections used: pixels + confidence
    joints_physics: np.ndarray | None = None     # (T, J, 3) simulated motion at the frames
    qpos_physics: np.ndarray | None = None       # (T, nq) simulator coordinates at the frames
    landmarks_physics: np.ndarray | None = None  # (T, 33, 3)
    body_mjcf: str | None = None                 # MJCF of the body and scene
    qpos_kinematic: np.ndarray | None = None     # (T, nq) the kinematic estimate in the same model
    # (T, 3) m: where the camera travelled with the person, how far it had moved by each frame
    # in the physics world (camera_T_world2cam sees the physics moved back by it; `as_filmed`)
    camera_travel_physics: np.ndarray | None = None
    # Forces of the simulation, each the mean over the steps within half a frame of the frame:
    # (T, 3, 3) N, the floor's and obstacles' force on GRF_PARTS (left foot, right foot, the
    # rest of the body), world frame; (T, 2, 3) m, the centre of pressure under each foot (NaN
    # where it carries no weight); (T, 48) N m, the torque across each hinge (DOF_NAMES): its
    # servo's, damping included, plus the joint-limit reaction (forces.joint_torques).
    grf_physics: np.ndarray | None = None
    cop_physics: np.ndarray | None = None
    torques_physics: np.ndarray | None = None
    meta: dict = dataclasses.field(default_factory=dict)  # JSON-able extras (config, timings)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise PhysposeError(f"reconstruction frame rate {self.fps} must be positive",
                                remedy="give the rate of the motion's frames")
        t = self.joints_kinematic.shape[0]
        if t < 1:
            raise PhysposeError("the reconstruction has no frames",
                                remedy="reconstruct a span of the video that shows the person")
        j = len(self.joint_names)
        checks = {
            "joints_kinematic": (t, j, 3), "landmarks_kinematic": (t, NUM_LANDMARKS, 3),
            "keypoints2d": (t, NUM_LANDMARKS, 3), "camera_K": (3, 3),
            "camera_T_world2cam": (4, 4), "joints_physics": (t, j, 3),
            "landmarks_physics": (t, NUM_LANDMARKS, 3), "camera_travel_physics": (t, 3),
            "grf_physics": (t, len(GRF_PARTS), 3), "cop_physics": (t, 2, 3),
            "torques_physics": (t, NUM_DOF),
        }
        for key, shape in checks.items():
            value = getattr(self, key)
            if value is not None and np.shape(value) != shape:
                raise PhysposeError(f"reconstruction field {key} has shape {np.shape(value)}, "
                                    f"expected {shape}")
        for key in ("qpos_physics", "qpos_kinematic"):
            value = getattr(self, key)
            if value is not None and np.shape(value)[0] != t:
                raise PhysposeError(f"{key} has {np.shape(value)[0]} frames, expected {t}")

    @property
    def num_frames(self) -> int:
        return int(self.joints_kinematic.shape[0])

    @property
    def has_physics(self) -> bool:
        return self.joints_physics is not None

    @property
    def slow_motion(self) -> float:
        """How many times slower than real time the footage played (meta["slow_motion"];
        1 where not recorded). `fps` and every time, speed and force are on the real clock."""
        return float(self.meta.get("slow_motion") or 1.0)

    @property
    def video_times(self) -> np.ndarray | None:
        """(T,) seconds into the footage (what --start/--end take) of each frame, from
        meta["timestamps"] (the observations' clock) times `slow_motion`; None for results
        written before physpose recorded them (stop 74)."""
        stamps = self.meta.get("timestamps")
        if stamps is None or len(stamps) != self.num_frames:
            return None
        return np.asarray(stamps, dtype=float) * self.slow_motion

    @property
    def video_frames(self) -> np.ndarray | None:
        """(T,) index of each frame in the source video (meta["frame_indices"]), or None."""
        frames = self.meta.get("frame_indices")
        if frames is None or len(frames) != self.num_frames:
            return None
        return np.asarray(frames, dtype=np.int64)

    @property
    def restarts(self) -> list[int]:
        """Frames at which the physics motion restarts from the kinematic estimate (it jumps
        there), from meta["dynamics"]; empty without physics or restarts."""
        dynamics = self.meta.get("dynamics") or {}
        if "restarts" in dynamics:
            return [int(f) for f in dynamics["restarts"]]
        return restart_frames(dynamics.get("windows") or [])

    @property
    def undetected(self) -> np.ndarray:
        """(T,) bool: frames without a detection (every keypoint's confidence 0); the motion
        there is inferred from the neighbouring frames, not observed. Short gaps filled by
        interpolation at observe time carry confidences and are not flagged."""
        return self.keypoints2d[..., 2].max(axis=1) <= 0

    @property
    def detected(self) -> np.ndarray:
        """(T,) bool: frames in which the detector found the person (meta["detected"]);
        frames filled across a short gap at observe time, and undetected ones, are False.
        Results written before physpose recorded it (stop 75): the frames with confidences."""
        flags = self.meta.get("detected")
        if flags is None or len(flags) != self.num_frames:
            return ~self.undetected
        return np.asarray(flags, dtype=bool)

    @property
    def restart_flags(self) -> np.ndarray:
        """(T,) bool: True at each of `restarts` (the physics motion jumps there)."""
        flags = np.zeros(self.num_frames, dtype=bool)
        flags[[f for f in self.restarts if 0 <= f < self.num_frames]] = True
        return flags

    @property
    def invalid_physics(self) -> np.ndarray | None:
        """(T,) bool: frames of dynamics windows in which no simulated sample stayed valid (the
        physics motion there is the least bad fall, not a reconstruction), from meta
        ["diagnostics"]["invalid_windows"]; None where not recorded (a result made outside
        `physpose.pipeline.reconstruct`)."""
        runs = (self.meta.get("diagnostics") or {}).get("invalid_windows")
        if runs is None:
            return None
        flags = np.zeros(self.num_frames, dtype=bool)
        for first, last in runs:
            flags[int(first):int(last) + 1] = True
        return flags

    @property
    def undetected_runs(self) -> list[tuple[int, int]]:
        """(first, last) frames of each run of `undetected` frames."""
        return frame_runs(self.undetected)

    def joints(self, which: str = "best") -> np.ndarray:
        """(T, J, 3) physics joints if present (or which='physics'), else kinematic."""
        _check_motion(which)
        if which == "kinematic" or (which == "best" and not self.has_physics):
            return self.joints_kinematic
        if self.joints_physics is None:
            raise PhysposeError("this reconstruction has no physics result",
                                remedy="run `physpose reconstruct` instead of `physpose fit`")
        return self.joints_physics

    def camera_travel(self, motion: str = "best") -> np.ndarray | None:
        """(T, 3) m: the camera's travel that a motion ('kinematic', 'physics' or 'best', as in
        `joints`) was filmed through: camera_travel_physics for the physics where the camera
        travelled with the person, None otherwise (a still camera)."""
        _check_motion(motion)
        physics = motion == "physics" or (motion == "best" and self.has_physics)
        if not physics or self.camera_travel_physics is None:
            return None
        return np.asarray(self.camera_travel_physics, dtype=float)

    def as_filmed(self, points: np.ndarray, motion: str = "best") -> np.ndarray:
        """Points (T, ..., 3) of a motion where camera_T_world2cam saw them: moved back by the
        camera's travel (`camera_travel`) where there is one, otherwise as given."""
        travel = self.camera_travel(motion)
        if travel is None:
            return points
        points = np.asarray(points, dtype=float)
        return points - travel.reshape((len(travel),) + (1,) * (points.ndim - 2) + (3,))

    def replace(self, **changes) -> "Reconstruction":
        return dataclasses.replace(self, **changes)

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        arrays = {key: getattr(self, key) for key in _REQUIRED + _OPTIONAL
                  if getattr(self, key) is not None}
        arrays["fps"] = np.array(float(self.fps))
        arrays["joint_names"] = np.array(self.joint_names)
        if self.body_mjcf is not None:
            arrays["body_mjcf"] = np.array(self.body_mjcf)
        arrays["meta_json"] = np.array(strict_json(self.meta, default=str))  # NaN as null
        return write_npz(path, arrays)

    @staticmethod
    def file_in(result: str | Path) -> Path:
        """The reconstruction file of a result folder (or the file itself)."""
        result = Path(result)
        return result / "reconstruction.npz" if result.is_dir() else result

    @classmethod
    def load(cls, path: str | Path) -> "Reconstruction":
        path = cls.file_in(path)
        if not path.is_file():
            raise PhysposeError("reconstruction not found", path=path,
                                remedy="pass a folder written by `physpose fit` or "
                                       "`physpose reconstruct`")
        d = read_npz(path, what="reconstruction", remedy="re-run the reconstruction")
        missing = [k for k in _REQUIRED if k not in d]
        if missing:
            raise PhysposeError(f"reconstruction lacks keys {missing}", path=path,
                                remedy="re-run the reconstruction with this physpose version")
        fields = {k: d[k] for k in _REQUIRED + _OPTIONAL if k in d}

        def damaged(problem: str) -> PhysposeError:
            return PhysposeError(problem, path=path, remedy="re-run the reconstruction")

        fps = fields["fps"]
        if fps.shape != () or fps.dtype.kind not in "iuf" or not (np.isfinite(fps) and fps > 0):
            raise damaged(f"its frame rate {fps.tolist()!r} is not a positive, finite number")
        fields["fps"] = float(fps)
        if fields["joint_names"].ndim != 1 or fields["joints_kinematic"].ndim != 3:
            raise damaged("its joint names or kinematic joints are not arrays of the right "
                          "dimensions")
        fields["joint_names"] = tuple(str(n) for n in fields["joint_names"])
        if "body_mjcf" in fields:
            fields["body_mjcf"] = str(fields["body_mjcf"])
        try:
            meta = json.loads(str(d["meta_json"])) if "meta_json" in d else {}
        except json.JSONDecodeError as exc:
            raise damaged(f"its metadata is not JSON ({exc})") from None
        if not isinstance(meta, dict):
            raise damaged("its metadata is not a JSON object")
        with about(path, "re-run the reconstruction with this physpose version"):  # a shape
            return cls(meta=meta, **fields)
