"""Tiny videos made by the tests themselves (cv2.VideoWriter), for the observe-stage tests."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np


def frame_value(i: int) -> int:
    """Grey level that encodes frame i, so a test can tell which frame it got back."""
    return (40 + 7 * i) % 256


def make_video(path: Path, n_frames: int, fps: float = 30.0, size: tuple[int, int] = (64, 48),
               fourcc: str | None = None) -> Path:
    """Write n_frames flat grey frames (frame i has grey level frame_value(i)); size = (w, h).

    The codec is mp4v for .mp4/.mov and MJPG for .avi unless `fourcc` is given.
    """
    fourcc = fourcc or ("MJPG" if path.suffix == ".avi" else "mp4v")
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, size)
    assert writer.isOpened(), f"OpenCV cannot write {path}"
    for i in range(n_frames):
        writer.write(np.full((size[1], size[0], 3), frame_value(i), np.uint8))
    writer.release()
    return path


def make_noise_video(path: Path, n_frames: int, fps: float = 10.0,
                     size: tuple[int, int] = (160, 120), seed: int = 0) -> Path:
    """Smoothed random texture that drifts: a scene with no person in it."""
    rng = np.random.default_rng(seed)
    base = cv2.GaussianBlur(rng.integers(0, 256, (size[1] * 2, size[0] * 2, 3), np.uint8),
                            (9, 9), 0)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, size)
    for i in range(n_frames):
        writer.write(np.ascontiguousarray(base[i:i + size[1], i:i + size[0]]))
    writer.release()
    return path


def truncate(path: Path, out: Path, fraction: float) -> Path:
    """Copy the first `fraction` of a file's bytes, as an interrupted download would."""
    data = path.read_bytes()
    out.write_bytes(data[: int(len(data) * fraction)])
    return out


def tag_rotation(path: Path, degrees: int) -> Path:
    """Set an mp4's display rotation in place, as phones store portrait video (landscape
    pixels and a tag that players apply): the track header's matrix, no re-encoding."""
    data = bytearray(path.read_bytes())
    at = data.find(b"tkhd")
    assert at > 0, f"no track header in {path}"
    version = data[at + 4]
    matrix = at + 4 + (52 if version == 1 else 40)
    a, b = {90: (0, 1), 180: (-1, 0), 270: (0, -1)}[degrees]
    fixed = [a, b, 0, -b, a, 0, 0, 0, 1]   # 16.16 fixed point, the last column 2.30
    for k, value in enumerate(fixed):
        scale = 1 << 30 if k in (2, 5, 8) else 1 << 16
        data[matrix + 4 * k:matrix + 4 * k + 4] = int(value * scale).to_bytes(4, "big",
                                                                               signed=True)
    path.write_bytes(bytes(data))
    return path
