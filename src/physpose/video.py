"""Video decoding: probe a file, plan which frames to read at a target rate, and read them.

Frames are resampled by picking, for each target timestamp `start + k / fps`, the source frame
nearest to it (no blending). The target rate never exceeds the source rate: asking for more
frames per second than the video has gives the source rate (and `FramePlan.note` says so).
Videos are assumed to have a constant frame rate; frame i is at time i / source_fps (the observe
stage warns where the container's own times say otherwise: `timing_drift`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from physpose.errors import PhysposeError

VIDEO_EXTENSIONS = (".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm", ".mpg", ".mpeg", ".wmv")
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".gif", ".tif", ".tiff", ".webp")
MIN_TARGET_FPS, MAX_TARGET_FPS = 1.0, 240.0  # Hz, accepted range of the requested rate
MAX_SOURCE_FPS = 1000.0  # Hz; a container claiming more is treated as broken
# Decoding may end a little before the container's frame count (its metadata is an estimate);
# a shortfall larger than this fraction of the frames means the file is truncated.
_TRUNCATION_TOLERANCE = 0.02
_REENCODE = "re-encode it, e.g. `ffmpeg -i IN -r 25 -c:v libx264 OUT.mp4`"


@dataclass(frozen=True)
class VideoInfo:
    """What the container says about a video, checked by decoding its first frame."""

    path: Path
    fps: float            # native frame rate, Hz
    frame_count: int      # frames in the file
    width: int            # pixels, of decoded frames (after any rotation metadata)
    height: int

    @property
    def duration(self) -> float:
        """Seconds covered by the frames: frame_count / fps."""
        return self.frame_count / self.fps

    @property
    def image_size(self) -> tuple[int, int]:
        return (self.width, self.height)


@dataclass(frozen=True)
class FramePlan:
    """Which source frames to read: indices (T,) into the video and their times (T,) in s."""

    fps: float                 # rate of the plan, Hz (the target, or the source if lower)
    indices: np.ndarray        # (T,) int, strictly increasing source frame indices
    timestamps: np.ndarray     # (T,) s, indices / source fps
    note: str = ""             # set when the requested rate could not be honoured


def _open(path: Path) -> cv2.VideoCapture:
    # CAP_FFMPEG keeps OpenCV from reading image files as one-frame "sequences".
    cap = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
    if not cap.isOpened():
        cap.release()
        if path.is_file() and not os.access(path, os.R_OK):
            raise PhysposeError("no permission to read this file", path=path,
                                remedy="check its permissions (chmod u+r)")
        raise PhysposeError("cannot open this file as a video (no frames, corrupt, truncated "
                            "or an unsupported codec)", path=path, remedy=_REENCODE)
    # Phone videos are often stored landscape with a rotation tag that players apply; OpenCV
    # leaves it off by default, which shows the person lying on their side.
    cap.set(cv2.CAP_PROP_ORIENTATION_AUTO, 1)
    return cap


def probe(path: str | Path) -> VideoInfo:
    """Check that `path` is a decodable video and return its rate, frame count and size."""
    path = Path(path)
    if not path.exists():
        raise PhysposeError("file not found", path=path, remedy="check the path")
    if not path.is_file():
        raise PhysposeError("not a file", path=path, remedy="pass a video file (mp4, avi, mov)")
    ext = path.suffix.lower()
    if ext in IMAGE_EXTENSIONS:
        raise PhysposeError("this is an image, not a video", path=path,
                            remedy="pass a video file (mp4, avi, mov); physpose needs motion "
                                   "over several frames")
    if ext not in VIDEO_EXTENSIONS:
        raise PhysposeError(f"not a video file (extension '{ext}', expected one of "
                            f"{', '.join(VIDEO_EXTENSIONS)})", path=path,
                            remedy="pass a video file, or precomputed keypoints as .json/.npz")
    if path.stat().st_size == 0:
        raise PhysposeError("the file is empty (0 bytes)", path=path, remedy="re-export the video")
    cap = _open(path)
    try:
        fps = float(cap.get(cv2.CAP_PROP_FPS))
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        ok, frame = cap.read()
        if not ok or frame is None:
            raise PhysposeError("the video has no decodable frames (zero frames, corrupt or "
                                "truncated)", path=path, remedy=_REENCODE)
        if count <= 0:  # some containers do not store a count: count by decoding
            count = 1
            while cap.grab():
                count += 1
    finally:
        cap.release()
    # Under MIN_TARGET_FPS no accepted analysis rate fits (the plan never exceeds the source).
    if not (math.isfinite(fps) and MIN_TARGET_FPS <= fps <= MAX_SOURCE_FPS):
        raise PhysposeError(f"the container reports a frame rate of {fps:g} fps, outside "
                            f"the {MIN_TARGET_FPS:g}-{MAX_SOURCE_FPS:g} fps physpose reads",
                            path=path, remedy=_REENCODE)
    height, width = frame.shape[:2]
    return VideoInfo(path=path, fps=fps, frame_count=count, width=width, height=height)


def check_target_fps(target_fps: float) -> None:
    """PhysposeError unless the analysis rate asked for is in the accepted range."""
    if not (math.isfinite(target_fps) and MIN_TARGET_FPS <= target_fps <= MAX_TARGET_FPS):
        raise PhysposeError(f"target frame rate {target_fps:g} fps is outside "
                            f"{MIN_TARGET_FPS:g}-{MAX_TARGET_FPS:g} fps",
                            remedy="pass e.g. --fps 25 (the paper's rate)")


def plan_frames(info: VideoInfo, target_fps: float = 25.0, start: float | None = None,
                end: float | None = None) -> FramePlan:
    """Pick the source frame nearest each target timestamp start + k / fps, start <= t < end."""
    check_target_fps(target_fps)
    duration = info.duration
    t0 = 0.0 if start is None else float(start)
    t1 = duration if end is None else float(end)
    if not (math.isfinite(t0) and 0 <= t0 < duration):
        raise PhysposeError(f"start {t0:g} s is outside the video (0-{duration:.3f} s)",
                            path=info.path, remedy="pick a start time inside the video")
    if not math.isfinite(t1):
        raise PhysposeError(f"end {t1:g} s is not a time", path=info.path,
                            remedy="pick an end time in seconds inside the video, or omit it")
    if t1 <= t0:
        raise PhysposeError(f"end {t1:g} s must be after start {t0:g} s", path=info.path,
                            remedy="pick an end time after the start")
    if t1 > duration + 0.5 / info.fps:
        raise PhysposeError(f"end {t1:g} s is past the end of the video ({duration:.3f} s)",
                            path=info.path, remedy="pick an end time inside the video or omit it")
    note = ""
    fps = float(target_fps)
    if fps > info.fps:
        note = (f"requested {target_fps:g} fps but the video has only {info.fps:g} fps; "
                f"using {info.fps:g} fps (physpose never invents frames)")
        fps = info.fps
    n = max(1, math.ceil((t1 - t0) * fps - 1e-9))
    targets = t0 + np.arange(n) / fps
    indices = np.floor(targets * info.fps + 0.5).astype(np.int64)
    indices = np.clip(indices, 0, info.frame_count - 1)
    indices = np.unique(indices)  # only the clip at the end can produce repeats
    return FramePlan(fps=fps, indices=indices, timestamps=indices / info.fps, note=note)


def read_frames(info: VideoInfo, indices: np.ndarray, times: list[float] | None = None
                ) -> Iterator[tuple[int, np.ndarray]]:
    """Yield (source index, BGR image (H, W, 3) uint8) for each of the increasing `indices`;
    `times`, if given, receives each yielded frame's presentation time in the container (s).

    Raises PhysposeError if the file ends well before the frames it promised (truncated or
    corrupt); a shortfall within the container's usual counting slack just ends the iteration.
    """
    wanted = [int(i) for i in indices]
    if any(b <= a for a, b in zip(wanted, wanted[1:])):
        raise ValueError("indices must be strictly increasing")
    cap = _open(info.path)
    try:
        pos = 0  # index of the frame the next grab() returns
        for idx in wanted:
            while pos <= idx:
                if not cap.grab():
                    _check_shortfall(info, pos)
                    return
                pos += 1
            ok, frame = cap.retrieve()
            if not ok or frame is None:
                raise PhysposeError("frame could not be decoded (corrupt video)", path=info.path,
                                    frame=idx, remedy=_REENCODE)
            if times is not None:
                times.append(cap.get(cv2.CAP_PROP_POS_MSEC) / 1000.0)
            yield idx, frame
    finally:
        cap.release()


def timing_drift(info: VideoInfo, indices: np.ndarray, times: list[float]) -> float:
    """Largest gap (in source frames) between the container's times of the frames read and
    index / fps, measured from the first: about 0 for a constant frame rate; a variable-rate
    video (common from phones) is read as if its frames were evenly spaced."""
    n = min(len(indices), len(times))
    if n < 2:
        return 0.0
    nominal = (np.asarray(indices[:n], dtype=float) - indices[0]) / info.fps
    actual = np.asarray(times[:n]) - times[0]
    return float(np.max(np.abs(actual - nominal)) * info.fps)


def drift_message(info: VideoInfo, drift: float) -> str | None:
    """A warning when timing_drift exceeds half a frame, or None."""
    if drift <= 0.5:
        return None
    return (f"{info.path}: the video's frames are not evenly spaced in time (a variable frame "
            f"rate; up to {drift:.1f} frames off {info.fps:g} fps): physpose reads them as if "
            f"they were, so speeds are off where the spacing changes. For true timing, "
            f"{_REENCODE}")


def _check_shortfall(info: VideoInfo, decoded: int) -> None:
    if info.frame_count - decoded > max(2, _TRUNCATION_TOLERANCE * info.frame_count):
        raise PhysposeError(f"decoding stopped after {decoded} of {info.frame_count} frames "
                            "(the file is truncated or corrupt)", path=info.path, frame=decoded,
                            remedy=_REENCODE)
