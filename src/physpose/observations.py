"""`Observations`: the per-frame 2d/3d landmark evidence every later stage reads.

Two ways in: the observe stage (video -> MediaPipe) and precomputed keypoints files
(`physpose.keypoints_io`). Both produce this one type, stored as `observations.npz`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from physpose.errors import PhysposeError
from physpose.joints import NUM_LANDMARKS
from physpose.npz_io import write_npz

FORMAT_VERSION = 1
CAMERA_MOTIONS = ("static", "turning", "moving")   # what `Observations.camera_motion` can say
SLOW_MOTION_RANGE = (0.05, 50.0)  # footage seconds per real second that physpose accepts
# A keypoint at least this sure is where the detector says: in the picture or near it, in pixels.
SURE_CONFIDENCE = 0.5


@dataclass(frozen=True, eq=False)
class Observations:
    """Landmarks of one person over time, MediaPipe's 33-landmark order.

    Frames where the person was not found (neither `detected` nor `interpolated`) hold zeros
    with confidence 0, so confidence-weighted losses ignore them without NaN handling.
    """

    source: str                    # the video or keypoints file these came from
    fps: float                     # rate of every per-frame array, Hz
    image_size: tuple[int, int]    # (width, height), pixels
    timestamps: np.ndarray         # (T,) seconds since the start of the source
    keypoints2d: np.ndarray        # (T, 33, 3) x, y in pixels + confidence in [0, 1]
    detected: np.ndarray           # (T,) bool, the detector found the person in this frame
    interpolated: np.ndarray       # (T,) bool, values filled across a short detection gap
    world_landmarks: np.ndarray | None = None  # (T, 33, 3) m, hip-centred, camera axes (OpenCV)
    masks: np.ndarray | None = None            # (T, h, w) uint8 person probability x 255
    camera_K: np.ndarray | None = None         # (3, 3) intrinsics, when the camera is calibrated
    frame_indices: np.ndarray | None = None    # (T,) index of each frame in the source video
    # Where the camera turned while filming (physpose.camera_motion): keypoints2d and
    # world_landmarks are then in the reference camera's image and axes, and homographies map
    # the reference image's pixels to each frame's own (T, 3, 3). camera_motion: "static",
    # "turning" or "moving" (turns and moves along: not compensated), None where not measured.
    homographies: np.ndarray | None = None
    camera_motion: str | None = None
    # (T,) bool: frames whose detection observe left out as torn (a blurred person mask,
    # physpose.mask_quality); they are gaps now. None where none was left out.
    unsure: np.ndarray | None = None

    def __post_init__(self) -> None:
        validate(self)

    @property
    def num_frames(self) -> int:
        return int(self.keypoints2d.shape[0])

    @property
    def valid(self) -> np.ndarray:
        """(T,) bool: frames that carry landmarks (detected or interpolated)."""
        return self.detected | self.interpolated

    def replace(self, **changes) -> "Observations":
        return dataclasses.replace(self, **changes)

    def save(self, path: str | Path) -> Path:
        """Write to an npz file (loadable with allow_pickle=False); returns the path."""
        path = Path(path)
        arrays = {
            "format_version": np.array(FORMAT_VERSION),
            "source": np.array(self.source),
            "fps": np.array(float(self.fps)),
            "image_size": np.array(self.image_size, dtype=np.int64),
            "timestamps": self.timestamps,
            "keypoints2d": self.keypoints2d,
            "detected": self.detected,
            "interpolated": self.interpolated,
        }
        for key in ("world_landmarks", "masks", "camera_K", "frame_indices", "homographies",
                    "camera_motion", "unsure"):
            value = getattr(self, key)
            if value is not None:
                arrays[key] = value
        return write_npz(path, arrays)

    @classmethod
    def load(cls, path: str | Path) -> "Observations":
        """Read observations written by `save` (a keypoints npz file, docs/keypoints_format.md,
        whatever its name ends with), with the keypoints reader's checks and errors."""
        from physpose.keypoints_io import load_keypoints_npz  # noqa: PLC0415 (it imports this)

        if not Path(path).is_file():
            raise PhysposeError("observations file not found", path=path,
                                remedy="run `physpose observe VIDEO --out DIR` first")
        return load_keypoints_npz(path)

    def on_real_clock(self, slow_motion: float) -> "Observations":
        """These observations timed as the filmed motion happened, where the footage plays
        `slow_motion` times slower than real time (4 for 120 fps footage played at 30 fps;
        below 1 for sped-up footage): the frame rate times it, the timestamps divided by it.
        `frame_indices` still name the video's frames."""
        check_slow_motion(slow_motion)
        if slow_motion == 1.0:
            return self
        return self.replace(fps=self.fps * slow_motion,
                            timestamps=np.asarray(self.timestamps) / slow_motion)

    def frames(self, start: int, stop: int) -> "Observations":
        """The frames [start, stop) alone (every per-frame array sliced)."""
        per_frame = ("timestamps", "keypoints2d", "detected", "interpolated", "world_landmarks",
                     "masks", "frame_indices", "homographies", "unsure")
        return self.replace(**{k: None if getattr(self, k) is None else getattr(self, k)[start:stop]
                               for k in per_frame})

    def seen_span(self) -> tuple[int, int]:
        """(first, last) frames with landmarks (detected or interpolated); (0, -1) if none."""
        seen = np.flatnonzero(self.valid)
        return (int(seen[0]), int(seen[-1])) if len(seen) else (0, -1)

    def frame_keypoints(self) -> np.ndarray:
        """keypoints2d (T, 33, 3) in each frame's own pixels: the same unless the camera turned
        (then keypoints2d are in the reference camera's image)."""
        if self.homographies is None:
            return self.keypoints2d
        return map_keypoints(self.keypoints2d, self.homographies, self.valid)


def map_keypoints(keypoints2d: np.ndarray, homographies: np.ndarray, valid: np.ndarray
                  ) -> np.ndarray:
    """(T, 33, 3) keypoints with the pixels of the valid frames mapped by (T, 3, 3)
    homographies; confidences kept, other frames zero."""
    xy = np.concatenate([keypoints2d[..., :2], np.ones(keypoints2d.shape[:-1] + (1,))], axis=-1)
    mapped = np.einsum("tij,tnj->tni", homographies, xy)
    out = np.array(keypoints2d, dtype=float)
    out[..., :2] = np.where(valid[:, None, None], mapped[..., :2] / mapped[..., 2:], 0.0)
    return out


def check_slow_motion(slow_motion: float) -> None:
    """Raise PhysposeError unless `slow_motion` (footage seconds per real second) is usable."""
    lo, hi = SLOW_MOTION_RANGE
    if not (np.isfinite(slow_motion) and lo <= slow_motion <= hi):
        raise PhysposeError(f"slow motion {slow_motion:g}x is outside {lo:g}-{hi:g}x",
                            remedy="pass how many times slower than real time the footage "
                                   "plays, e.g. --slow-motion 4 for 120 fps footage played at "
                                   "30 fps (1: real time)")


def validate(obs: Observations) -> None:
    """Raise PhysposeError naming the source and frame if any array is malformed."""
    src = obs.source

    def fail(problem: str, frame: int | None = None,
             remedy: str = "check how the file was produced (see docs/keypoints_format.md)"
             ) -> None:
        raise PhysposeError(problem, path=src, frame=frame, remedy=remedy)

    if not (np.isfinite(obs.fps) and 0.5 <= obs.fps <= 1000):
        fail(f"frame rate {obs.fps} Hz is outside 0.5-1000 Hz")
    if len(obs.image_size) != 2 or not all(np.isfinite(v) and v > 0 for v in obs.image_size):
        fail(f"image size {obs.image_size} must be (width, height) in positive pixels")
    kp = np.asarray(obs.keypoints2d)
    if kp.ndim != 3 or kp.shape[1:] != (NUM_LANDMARKS, 3):
        fail(f"keypoints2d has shape {kp.shape}, expected (T, {NUM_LANDMARKS}, 3)")
    t = kp.shape[0]
    if t == 0:
        fail("no frames")
    for name in ("timestamps", "detected", "interpolated", "frame_indices"):
        value = getattr(obs, name)
        if value is not None and np.asarray(value).shape != (t,):
            fail(f"{name} has shape {np.asarray(value).shape}, expected ({t},)")
    for name in ("detected", "interpolated"):  # integer flags would index frames, not mask them
        if np.asarray(getattr(obs, name)).dtype != bool:
            fail(f"{name} has type {np.asarray(getattr(obs, name)).dtype}, expected bool",
                 remedy=f"pass {name}=np.asarray({name}, bool)")
    bad = ~np.isfinite(kp).all(axis=(1, 2))
    if bad.any():
        fail("keypoints2d contains NaN or infinite values", int(np.argmax(bad)))
    conf = kp[..., 2]
    if (conf < 0).any() or (conf > 1).any():
        fail("keypoint confidences must lie in [0, 1]", int(np.argmax(((conf < 0) | (conf > 1)).any(1))))
    sure = conf >= SURE_CONFIDENCE
    if sure.any() and max(obs.image_size) >= 64 and np.abs(kp[..., :2][sure]).max() <= 1.5:
        w, h = obs.image_size
        fail(f"every sure keypoint lies within 1.5 px of the image's corner: the coordinates "
             f"look normalised to [0, 1], not pixels of the {w}x{h} image",
             remedy=f"multiply x by the width ({w}) and y by the height ({h})")
    if obs.world_landmarks is not None:
        wl = np.asarray(obs.world_landmarks)
        if wl.shape != (t, NUM_LANDMARKS, 3):
            fail(f"world_landmarks has shape {wl.shape}, expected ({t}, {NUM_LANDMARKS}, 3)")
        bad = ~np.isfinite(wl).all(axis=(1, 2))
        if bad.any():
            fail("world_landmarks contains NaN or infinite values", int(np.argmax(bad)))
    if obs.masks is not None and (np.asarray(obs.masks).ndim != 3 or len(obs.masks) != t):
        fail(f"masks has shape {np.asarray(obs.masks).shape}, expected ({t}, h, w)")
    if obs.camera_K is not None and np.asarray(obs.camera_K).shape != (3, 3):
        fail(f"camera_K has shape {np.asarray(obs.camera_K).shape}, expected (3, 3)")
    if obs.homographies is not None and np.asarray(obs.homographies).shape != (t, 3, 3):
        fail(f"homographies has shape {np.asarray(obs.homographies).shape}, expected ({t}, 3, 3)")
    if obs.unsure is not None and (np.asarray(obs.unsure).shape != (t,)
                                   or np.asarray(obs.unsure).dtype != bool):
        fail(f"unsure has shape {np.asarray(obs.unsure).shape} and type "
             f"{np.asarray(obs.unsure).dtype}, expected ({t},) bool")
    if obs.camera_motion is not None and obs.camera_motion not in CAMERA_MOTIONS:
        fail(f"camera_motion {obs.camera_motion!r} is not one of {', '.join(CAMERA_MOTIONS)}")
