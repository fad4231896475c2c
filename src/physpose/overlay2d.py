"""Overlay video of the 2d landmarks on the analysed frames, for checking detections by eye.

Each landmark and skeleton edge is coloured by confidence (red = 0 -> yellow -> green = 1);
frames without a detection and interpolated frames carry a label. Without the source video the
landmarks are drawn on a dark background of the image size.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from physpose import video as videolib
from physpose.cache import atomic_path
from physpose.errors import PhysposeError
from physpose.joints import LANDMARK_EDGES, LANDMARK_INDEX
from physpose.observations import Observations

MAX_SIDE = 1280  # px, longer side of the overlay video (frames are scaled down to it)
_EDGES = [(LANDMARK_INDEX[a], LANDMARK_INDEX[b]) for a, b in LANDMARK_EDGES]
_BACKGROUND = (40, 40, 40)  # BGR, when there is no video to draw on


def confidence_color(conf: float) -> tuple[int, int, int]:
    """BGR colour for a confidence in [0, 1]: red at 0, yellow at 0.5, green at 1."""
    c = float(np.clip(conf, 0.0, 1.0))
    return (0, int(255 * min(1.0, 2 * c)), int(255 * min(1.0, 2 * (1 - c))))


def draw_landmarks(image: np.ndarray, keypoints: np.ndarray, scale: float = 1.0) -> None:
    """Draw (33, 3) px+conf keypoints, scaled by `scale`, onto a BGR image in place."""
    pts = np.round(keypoints[:, :2] * scale).astype(int)
    conf = keypoints[:, 2]
    thick = max(1, round(max(image.shape[:2]) / 400))
    for a, b in _EDGES:
        if conf[a] > 0 and conf[b] > 0:
            cv2.line(image, tuple(pts[a]), tuple(pts[b]), confidence_color(min(conf[a], conf[b])),
                     thick, cv2.LINE_AA)
    for p, c in zip(pts, conf):
        if c > 0:
            cv2.circle(image, tuple(p), thick + 2, confidence_color(c), -1, cv2.LINE_AA)


def _label(image: np.ndarray, text: str, color: tuple[int, int, int]) -> None:
    scale = max(image.shape[:2]) / 1000
    org = (10, int(30 * scale) + 5)
    cv2.putText(image, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0),
                max(2, round(4 * scale)), cv2.LINE_AA)
    cv2.putText(image, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, color,
                max(1, round(2 * scale)), cv2.LINE_AA)


def write_overlay(obs: Observations, out_path: str | Path, video: str | Path | None = None, *,
                  progress: bool = True) -> Path:
    """Write an mp4 (mp4v) at obs.fps of the landmarks drawn on the analysed frames.

    video: the source video (frames obs.frame_indices are read from it), or None for a plain
    background. The file appears atomically under `out_path` when complete.
    """
    out_path = Path(out_path)
    width, height = obs.image_size
    scale = min(1.0, MAX_SIDE / max(width, height))
    size = (max(2, round(width * scale) // 2 * 2), max(2, round(height * scale) // 2 * 2))
    frames = _source_frames(obs, video)
    with atomic_path(out_path) as tmp:
        _write(obs, frames, str(tmp), size, progress)
    return out_path


def _write(obs: Observations, frames, tmp: str, size: tuple[int, int], progress: bool) -> None:
    width = obs.image_size[0]
    writer = cv2.VideoWriter(tmp, cv2.VideoWriter_fourcc(*"mp4v"), float(obs.fps), size)
    try:
        if not writer.isOpened():
            raise PhysposeError("OpenCV cannot write an mp4v video here", path=tmp,
                                remedy="pass --no-overlay, or check the folder is writable")
        shown = obs.frame_keypoints()   # each frame's own pixels (a turning camera)
        for t in tqdm(range(obs.num_frames), desc="overlay", unit="frame", disable=not progress,
                      leave=False):
            image = next(frames)
            image = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
            draw_landmarks(image, shown[t], scale=size[0] / width)
            stamp = f"t={obs.timestamps[t]:.2f}s"
            if obs.detected[t]:
                _label(image, stamp, (255, 255, 255))
            elif obs.interpolated[t]:
                _label(image, f"{stamp} interpolated", (0, 165, 255))
            else:
                _label(image, f"{stamp} NO DETECTION", (0, 0, 255))
            writer.write(image)
    finally:
        writer.release()


def _source_frames(obs: Observations, video: str | Path | None):
    """Iterator over BGR frames (H, W, 3) matching obs's frames."""
    width, height = obs.image_size
    if video is None:
        blank = np.empty((height, width, 3), np.uint8)
        blank[:] = _BACKGROUND
        return (blank.copy() for _ in range(obs.num_frames))
    info = videolib.probe(video)
    if info.image_size != tuple(obs.image_size):
        raise PhysposeError(f"video size {info.image_size} differs from the observations' "
                            f"{tuple(obs.image_size)}", path=video,
                            remedy="draw on the video the observations were made from")
    indices = obs.frame_indices
    if indices is None:
        indices = np.floor(obs.timestamps * info.fps + 0.5).astype(np.int64)
    frames = (image for _, image in videolib.read_frames(info, indices))
    return _exactly(frames, obs.num_frames, video)


def _exactly(frames, n: int, video):
    for i in range(n):
        image = next(frames, None)
        if image is None:
            raise PhysposeError(f"the video ended after {i} of the {n} observed frames",
                                path=video, frame=i, remedy="draw on the video the observations "
                                "were made from, or pass --no-overlay")
        yield image
