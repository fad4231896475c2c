"""Read a Qualisys calibration (`*.qca.txt`, XML) into per-camera pinhole models.

Conventions, checked on the pose2sim demo (triangulated MediaPipe landmarks re-project with a
median error of 16 px and the feet touch the floor):

- `<transform>`: the rows r11..r33 form a matrix M and (x, y, z) is the camera centre in the lab
  frame in millimetres. The lab-to-camera rotation in OpenCV axes (x right, y down, z forward)
  is `diag(1, -1, -1) @ M`, i.e. M after a 180-degree turn about the camera x axis.
- `<intrinsic>`: focal lengths and the principal point are in 1/64 pixel of the sensor;
  `<fov_video>` is the video window on the sensor (pixels, inclusive bounds), so the image size
  is (right - left + 1, bottom - top + 1) and the principal point is relative to its corner.
  Distortion is OpenCV's (k1, k2, p1, p2, k3).
- The lab frame is z up with the floor at z = 0 (camera centres sit 1.7-2.1 m above it; the
  feet of the walking subject reach z = 0.01-0.05 m), metres after conversion. It is therefore
  already the project's world frame.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from physpose.errors import PhysposeError

_SUBPIXEL = 64.0            # Qualisys stores focal lengths and centres in 1/64 pixel
_MM = 1e-3                  # m per mm
_FLIP_X180 = np.diag([1.0, -1.0, -1.0])  # 180-degree turn about the camera x axis
_CROP_TOLERANCE = 0.01      # relative size difference treated as a crop at the right/bottom


@dataclass(frozen=True, eq=False)
class CameraCalibration:
    """One calibrated camera: pinhole intrinsics with OpenCV distortion, lab-to-camera pose."""

    name: str
    K: np.ndarray              # (3, 3) intrinsics, pixels
    dist: np.ndarray           # (5,) OpenCV distortion k1, k2, p1, p2, k3
    image_size: tuple[int, int]  # (width, height) pixels
    T_world2cam: np.ndarray    # (4, 4) world (lab, metres, z up) -> OpenCV camera

    @property
    def R_world2cam(self) -> np.ndarray:
        return self.T_world2cam[:3, :3]

    @property
    def center(self) -> np.ndarray:
        """(3,) camera centre in the world frame, metres."""
        return -self.R_world2cam.T @ self.T_world2cam[:3, 3]

    @property
    def projection(self) -> np.ndarray:
        """(3, 4) pinhole projection K [R | t] for undistorted pixel coordinates."""
        return self.K @ self.T_world2cam[:3]

    def project(self, points: np.ndarray) -> np.ndarray:
        """World points (..., 3) -> distorted pixel coordinates (..., 2)."""
        pts = np.asarray(points, dtype=float)
        flat = pts.reshape(-1, 3)
        rvec = cv2.Rodrigues(self.R_world2cam)[0]
        uv, _ = cv2.projectPoints(flat, rvec, self.T_world2cam[:3, 3], self.K, self.dist)
        return uv.reshape(pts.shape[:-1] + (2,))

    def undistort(self, pixels: np.ndarray) -> np.ndarray:
        """Distorted pixel coordinates (..., 2) -> ideal pinhole pixel coordinates (..., 2)."""
        px = np.asarray(pixels, dtype=float)
        flat = px.reshape(-1, 1, 2)
        und = cv2.undistortPoints(flat, self.K, self.dist, P=self.K)
        return und.reshape(px.shape)

    def for_image_size(self, width: int, height: int, source: str | Path | None = None
                       ) -> "CameraCalibration":
        """The calibration adapted to a video of the given size.

        Equal sizes return self; a difference within 1 % is a crop at the right/bottom (intrinsics
        unchanged, e.g. 1080-wide videos of a 1088-wide calibration); a uniform scale (binning,
        resizing) scales the intrinsics, by the larger of the two sides' factors where they
        differ within 1 % (a crop as well: the pixels stay square, 540x960 from 1088x1920 is
        half of the 1080-wide crop); anything else (e.g. a rotated video) is an error.
        """
        cw, ch = self.image_size
        if (width, height) == (cw, ch):
            return self
        if abs(width - cw) <= _CROP_TOLERANCE * cw and abs(height - ch) <= _CROP_TOLERANCE * ch:
            return replace(self, image_size=(width, height))
        sx, sy = width / cw, height / ch
        if abs(sx - sy) <= _CROP_TOLERANCE * sx:
            K = self.K.copy()
            K[:2] *= max(sx, sy)
            return replace(self, K=K, image_size=(width, height))
        raise PhysposeError(
            f"video is {width}x{height} but camera {self.name} is calibrated for {cw}x{ch}",
            path=source, remedy="use the videos the calibration was made for, unrotated")


def load_qualisys(path: str | Path) -> tuple[CameraCalibration, ...]:
    """Parse every active camera of a Qualisys `.qca.txt` calibration, in file order."""
    path = Path(path)
    if not path.is_file():
        raise PhysposeError("calibration file not found", path=path,
                            remedy="pass a Qualisys .qca.txt file")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise PhysposeError(f"not a readable XML calibration ({exc})", path=path,
                            remedy="export the calibration from QTM as .qca.txt") from None
    cameras = [_parse_camera(node, index, path)
               for index, node in enumerate(root.iter("camera"))
               if node.get("active", "1") != "0"]
    if not cameras:
        raise PhysposeError("no active <camera> element", path=path,
                            remedy="check that this is a Qualisys calibration export")
    names = [c.name for c in cameras]
    if len(set(names)) != len(names):
        raise PhysposeError(f"duplicate camera serials {names}", path=path)
    return tuple(cameras)


def _parse_camera(node: ET.Element, index: int, path: Path) -> CameraCalibration:
    name = node.get("serial") or f"camera{index + 1}"
    transform = _child(node, "transform", name, path)
    intrinsic = _child(node, "intrinsic", name, path)
    fov = node.find("fov_video")
    if fov is None:
        fov = node.find("fov_marker")
    if fov is None:
        raise PhysposeError(f"camera {name} has no <fov_video> element", path=path,
                            remedy="the video window is needed for the image size")

    def num(elem: ET.Element, key: str, default: float | None = None) -> float:
        raw = elem.get(key)
        if raw is None and default is not None:
            return default
        try:
            value = float(raw)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            raise PhysposeError(f"camera {name}: <{elem.tag}> attribute {key}={raw!r} is not a "
                                "number", path=path, remedy="repair or re-export the calibration"
                                ) from None
        if not np.isfinite(value):
            raise PhysposeError(f"camera {name}: <{elem.tag}> {key} is not finite", path=path)
        return value

    M = np.array([[num(transform, f"r{i}{j}") for j in "123"] for i in "123"])
    if abs(np.linalg.det(M) - 1.0) > 1e-3 or not np.allclose(M @ M.T, np.eye(3), atol=1e-3):
        raise PhysposeError(f"camera {name}: transform r11..r33 is not a rotation matrix",
                            path=path, remedy="repair or re-export the calibration")
    center = np.array([num(transform, k) for k in "xyz"]) * _MM
    R_world2cam = _FLIP_X180 @ M
    T = np.eye(4)
    T[:3, :3] = R_world2cam
    T[:3, 3] = -R_world2cam @ center

    left, top = num(fov, "left"), num(fov, "top")
    width = int(round(num(fov, "right") - left + 1))
    height = int(round(num(fov, "bottom") - top + 1))
    if width <= 0 or height <= 0:
        raise PhysposeError(f"camera {name}: empty video window {width}x{height}", path=path)
    fu, fv = num(intrinsic, "focalLengthU") / _SUBPIXEL, num(intrinsic, "focalLengthV") / _SUBPIXEL
    if fu <= 0 or fv <= 0:
        raise PhysposeError(f"camera {name}: focal lengths must be positive", path=path)
    cu = num(intrinsic, "centerPointU") / _SUBPIXEL - left
    cv = num(intrinsic, "centerPointV") / _SUBPIXEL - top
    skew = num(intrinsic, "skew", 0.0)
    K = np.array([[fu, skew, cu], [0.0, fv, cv], [0.0, 0.0, 1.0]])
    dist = np.array([num(intrinsic, "radialDistortion1", 0.0),
                     num(intrinsic, "radialDistortion2", 0.0),
                     num(intrinsic, "tangentalDistortion1", 0.0),
                     num(intrinsic, "tangentalDistortion2", 0.0),
                     num(intrinsic, "radialDistortion3", 0.0)])
    return CameraCalibration(name=name, K=K, dist=dist, image_size=(width, height), T_world2cam=T)


def _child(node: ET.Element, tag: str, name: str, path: Path) -> ET.Element:
    child = node.find(tag)
    if child is None:
        raise PhysposeError(f"camera {name} has no <{tag}> element", path=path,
                            remedy="repair or re-export the calibration")
    return child
