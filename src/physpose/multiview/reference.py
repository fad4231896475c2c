"""A 3d reference from synchronised, calibrated views: observe every view, then triangulate.

Folder layout (that of the pose2sim demo): `videos/<name>.mp4` (any container physpose reads) and
`calibration/*.qca.txt` (Qualisys). Videos are matched to cameras by name (video stem = camera
serial), else in sorted order when the counts agree. The views must be synchronised: frame i of
every video shows the same instant.

The Qualisys lab frame is z up with the floor at z = 0 (see `qualisys.py`), so it is the
project's world frame as it is: floor normal (0, 0, 1), camera height = camera centre z.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from physpose.cache import Cache, stage_key
from physpose.errors import PhysposeError
from physpose.joints import LANDMARK_INDEX, joints_from_landmarks
from physpose.multiview.qualisys import CameraCalibration, load_qualisys
from physpose.multiview.triangulate import TriangulationConfig, triangulate
from physpose.observations import Observations
from physpose.observe import OBSERVE_VERSION, ObserveConfig, observe
from physpose.video import VIDEO_EXTENSIONS

REFERENCE_VERSION = 1  # bump when a change alters the reference for the same input
_FLOOR_NORMAL = np.array([0.0, 0.0, 1.0])  # world z up
_FOOT_LANDMARKS = [LANDMARK_INDEX[n] for n in ("left_heel", "right_heel", "left_foot_index",
                                               "right_foot_index")]
_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ReferenceConfig:
    """How the reference is built (all but use_cache are part of the cache key)."""

    observe: ObserveConfig = ObserveConfig()   # one setting for every view, so frames align
    triangulation: TriangulationConfig = TriangulationConfig()
    use_cache: bool = True


@dataclass(frozen=True, eq=False)
class MultiviewReference:
    """Triangulated landmarks of one person in the world frame (z up, floor z = 0, metres)."""

    folder: str
    fps: float                            # Hz, the observe rate
    timestamps: np.ndarray                # (T,) s since the start of the videos
    cameras: tuple[CameraCalibration, ...]  # (N,) adapted to the videos' sizes
    views: tuple[Observations, ...]       # (N,) detections of each view, frames aligned
    landmarks: np.ndarray                 # (T, 33, 3) world, gaps filled by interpolation
    landmarks_valid: np.ndarray           # (T, 33) bool, triangulated (not filled)
    view_errors: np.ndarray               # (T, 33, N) re-projection error per view, px
    used: np.ndarray                      # (T, 33, N) bool, views each point was built from

    @property
    def num_frames(self) -> int:
        return int(self.landmarks.shape[0])

    @property
    def joints(self) -> np.ndarray:
        """(T, J, 3) the project's joints (JOINT_NAMES) in the world frame."""
        return joints_from_landmarks(self.landmarks)

    @property
    def floor_normal(self) -> np.ndarray:
        """(3,) unit normal of the floor in the world frame."""
        return _FLOOR_NORMAL.copy()

    @property
    def camera_heights(self) -> np.ndarray:
        """(N,) height of each camera centre above the floor, m."""
        return np.array([cam.center @ _FLOOR_NORMAL for cam in self.cameras])

    def floor_normal_in_camera(self, view: int) -> np.ndarray:
        """(3,) floor normal in the OpenCV axes of camera `view`."""
        return self.cameras[view].R_world2cam @ _FLOOR_NORMAL

    def reprojection_summary(self) -> dict[str, float]:
        """Median/mean re-projection error (px) over the views each point was built from."""
        err = self.view_errors[self.used]
        return {"median_px": float(np.median(err)), "mean_px": float(np.mean(err)),
                "views_used_fraction": float(self.used.mean()),
                "points_triangulated_fraction": float(self.landmarks_valid.mean()),
                "foot_height_median_m": float(np.median(self.landmarks[:, _FOOT_LANDMARKS, 2]
                                                        .min(axis=1)))}


@dataclass(frozen=True)
class MultiviewFolder:
    """The files of a multi-view folder, videos in camera order."""

    calibration: Path
    videos: tuple[Path, ...]
    cameras: tuple[CameraCalibration, ...]


def find_multiview_files(folder: str | Path) -> MultiviewFolder:
    """Locate and pair the videos and the Qualisys calibration of a pose2sim-style folder."""
    folder = Path(folder)
    if not folder.is_dir():
        raise PhysposeError("multi-view folder not found", path=folder,
                            remedy="pass a folder with videos/ and calibration/*.qca.txt")
    calibs = sorted((folder / "calibration").glob("*.qca.txt"))
    if len(calibs) != 1:
        raise PhysposeError(f"expected one calibration/*.qca.txt, found {len(calibs)}",
                            path=folder, remedy="put exactly one Qualisys calibration in "
                                                "calibration/")
    videos = sorted(p for p in (folder / "videos").glob("*")
                    if p.suffix.lower() in VIDEO_EXTENSIONS)
    cameras = load_qualisys(calibs[0])
    by_stem = {v.stem: v for v in videos}
    if all(c.name in by_stem for c in cameras):
        paired = tuple(by_stem[c.name] for c in cameras)
    elif len(videos) == len(cameras):
        paired = tuple(videos)  # pose2sim's rule: sorted videos follow the calibration order
    else:
        raise PhysposeError(
            f"{len(videos)} videos in videos/ for {len(cameras)} calibrated cameras "
            f"({', '.join(c.name for c in cameras)})", path=folder,
            remedy="name each video after its camera serial or give one video per camera")
    if len(paired) < 2:
        raise PhysposeError("a multi-view reference needs at least two views", path=folder)
    return MultiviewFolder(calibration=calibs[0], videos=paired, cameras=cameras)


def build_multiview_reference(folder: str | Path, cfg: ReferenceConfig = ReferenceConfig(), *,
                              progress: bool = False) -> MultiviewReference:
    """Observe every view of `folder`, triangulate the 33 landmarks and return the reference."""
    files = find_multiview_files(folder)
    # Calibrated views are still by definition: their detections stay in their own pixels.
    still = dataclasses.replace(cfg.observe, stabilize=False)
    views = tuple(observe(v, still, progress=progress) for v in files.videos)
    cameras = tuple(cam.for_image_size(*obs.image_size, source=video)
                    for cam, obs, video in zip(files.cameras, views, files.videos))
    views = _align_frames(views, files.videos)
    key = stage_key("multiview_reference", version=REFERENCE_VERSION,
                    files=[files.calibration, *files.videos],
                    config=dataclasses.replace(cfg, use_cache=True),
                    extra={"observe_version": OBSERVE_VERSION})
    cache = Cache("multiview_reference")
    arrays = cache.get(key) if cfg.use_cache else None
    if arrays is None:
        arrays = triangulate_views(cameras, views, cfg.triangulation, Path(folder))
        if cfg.use_cache:
            cache.put(key, arrays)
    return MultiviewReference(folder=str(folder), fps=views[0].fps,
                              timestamps=views[0].timestamps, cameras=cameras, views=views,
                              landmarks=arrays["landmarks"],
                              landmarks_valid=arrays["landmarks_valid"].astype(bool),
                              view_errors=arrays["view_errors"], used=arrays["used"].astype(bool))


def triangulate_observations(cameras: tuple[CameraCalibration, ...],
                             views: tuple[Observations, ...],
                             cfg: TriangulationConfig = TriangulationConfig(),
                             exclude: int | None = None):
    """Triangulate the views' detections (undistorted first); `exclude` drops one view.

    Returns a `Triangulation` whose per-view arrays cover all N views (the excluded one unused).
    """
    keypoints = []
    for i, (cam, obs) in enumerate(zip(cameras, views)):
        kp = np.array(obs.keypoints2d, dtype=float)
        kp[..., :2] = cam.undistort(kp[..., :2])
        kp[~obs.valid, :, 2] = 0.0
        if i == exclude:
            kp[..., 2] = 0.0
        keypoints.append(kp)
    return triangulate(np.stack([c.projection for c in cameras]), np.stack(keypoints), cfg)


def triangulate_views(cameras, views, cfg: TriangulationConfig, folder: Path,
                      exclude: int | None = None) -> dict[str, np.ndarray]:
    """The reference's arrays from the views' detections (``exclude``: one view left out):
    landmarks with their gaps filled, which were triangulated, the views' errors and use.
    A landmark triangulated in no frame is an error naming the folder (and the view left
    out)."""
    tri = triangulate_observations(cameras, views, cfg, exclude=exclude)
    valid = tri.valid
    never = np.flatnonzero(~valid.any(axis=0))
    if never.size:
        without = "" if exclude is None else f"without view {cameras[exclude].name}, "
        raise PhysposeError(f"{without}landmarks {never.tolist()} could not be triangulated in "
                            "any frame", path=folder,
                            remedy="check that the person is visible in at least two views "
                                   "and the calibration matches" + (
                                       "" if exclude is None else "; or score against the "
                                       "reference from every view (--multiview-truth "
                                       "all-views)"))
    landmarks = fill_missing(tri.points, valid)
    return {"landmarks": landmarks, "landmarks_valid": valid, "view_errors": tri.view_errors,
            "used": tri.used}


def fill_missing(points: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Linearly interpolate invalid samples over time, holding the ends.

    points: (T, P, D); valid: (T, P) bool with at least one True per point -> (T, P, D).
    """
    out = np.array(points, dtype=float)
    frames = np.arange(points.shape[0])
    for p in range(points.shape[1]):
        ok = valid[:, p]
        if not ok.all():
            for d in range(points.shape[2]):
                out[:, p, d] = np.interp(frames, frames[ok], points[ok, p, d])
    return out


def _align_frames(views: tuple[Observations, ...], videos: tuple[Path, ...]
                  ) -> tuple[Observations, ...]:
    """Cut every view to the common frames; the views must share their frame plan."""
    n = min(v.num_frames for v in views)
    for obs, video in zip(views, videos):
        if not np.allclose(obs.timestamps[:n], views[0].timestamps[:n], atol=0.5 / obs.fps):
            raise PhysposeError("video frames are not at the same times as the first view's "
                                f"({obs.fps:g} vs {views[0].fps:g} fps)", path=video,
                                remedy="the views must be synchronised videos of equal rate")
        if obs.num_frames != n:
            _log.warning("%s: %d frames, using the %d common to all views", video,
                         obs.num_frames, n)
    return tuple(obs if obs.num_frames == n else obs.frames(0, n) for obs in views)
