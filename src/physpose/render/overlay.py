"""Overlay video: the input frames with the kinematic and physics body projected on them, beside
a 3d view of the body, the ground grid, the foot contacts and the simulated ground reaction
force under each foot (an arrow from its centre of pressure) from a second viewpoint.

The source frames are re-read at the analysis rate: meta['source'] names the video and
meta['frame_indices'] (T,) the frame used for each analysed frame (else the frame nearest
meta.get('start', 0) + t / fps). Without a video the body is drawn on a plain background of
meta['image_size'] (else twice the principal point).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from physpose import video as videolib
from physpose.cache import atomic_path
from physpose.errors import PhysposeError
from physpose.reconstruction import Reconstruction
from physpose.camera_motion import frame_cameras
from physpose.render.bodymotion import BodyMotion, body_weight, load_model, reconstruction_motion
from physpose.render.draw import (draw_grid, draw_ground_disc, draw_skeleton, draw_solids,
                                  geom_samples, look_at, project)
from physpose.render.result import available_motions, joints_of, load_result
from physpose.render.skeleton import edge_indices, foot_contacts, lowest_foot_points

DEFAULT_NAME = "overlay.mp4"
COLORS = {"kinematic": (36, 138, 240), "physics": (214, 111, 47)}  # BGR: orange, blue
CONTACT_COLOR = (94, 36, 224)  # BGR
_BACKGROUND = (48, 48, 48)     # BGR, when there is no video
_VIEW_BACKGROUND = (245, 241, 238)
_GRID_COLOR = (190, 184, 178)
RESTART_COLOR = (43, 57, 192)  # BGR, red: the physics motion jumped back to the estimate
RESTART_SHOWN_S = 0.4          # s the restart notice stays up (a jump is one frame)
FORCE_COLOR = (60, 160, 40)    # BGR, green: the simulated ground reaction force
FORCE_M_PER_BW = 0.5           # m of arrow per body weight of force


@dataclass(frozen=True)
class OverlayConfig:
    """Layout and the second viewpoint of the overlay video."""

    height: int = 540                # px, height of both panels
    solids: bool = True              # draw the capsule body (when stored), not only the skeleton
    view_azimuth_deg: float = -60.0  # second view, around z from the video camera's direction
    view_elevation_deg: float = 18.0
    view_distance: float = 3.3       # m from the pelvis
    grid_step: float = 0.5           # m
    grid_extent: float = 4.0         # m around the pelvis


@dataclass(frozen=True)
class OverlayVideo:
    path: Path
    background: str  # the video drawn on, or why there was none


@dataclass(frozen=True, eq=False)
class _Scene:
    rec: Reconstruction
    motions: tuple[str, ...]
    bodies: dict[str, BodyMotion | None]
    samples: dict[str, list[np.ndarray]]
    contacts: dict[str, np.ndarray]     # (T, 2) bool per motion
    feet_xy: dict[str, np.ndarray]      # (T, 2, 2) per motion
    edges: np.ndarray
    image_size: tuple[int, int]
    restarting: np.ndarray              # (T,) bool: within RESTART_SHOWN_S of a physics restart
    cameras: np.ndarray                 # (T, 4, 4) world -> each frame's camera (a turning one)
    force_arrows: np.ndarray | None     # (T, 2, 2, 3) per foot: centre of pressure, arrow tip


def _scene(rec: Reconstruction, image_size: tuple[int, int]) -> _Scene:
    motions = available_motions(rec)
    bodies = {m: reconstruction_motion(rec, m) for m in motions}
    feet = {m: lowest_foot_points(joints_of(rec, m), rec.joint_names) for m in motions}
    return _Scene(
        rec=rec, motions=motions, bodies=bodies,
        samples={m: [geom_samples(g) for g in b.tree.geoms] for m, b in bodies.items() if b},
        contacts={m: foot_contacts(f[..., 2]) for m, f in feet.items()},
        feet_xy={m: f[..., :2] for m, f in feet.items()},
        edges=edge_indices(rec.joint_names), image_size=image_size,
        restarting=_restarting(rec), cameras=_frame_cameras(rec),
        force_arrows=_force_arrows(rec))


def _force_arrows(rec: Reconstruction) -> np.ndarray | None:
    """(T, 2, 2, 3) per foot, its centre of pressure and the tip of an arrow along the simulated
    ground reaction force, FORCE_M_PER_BW long per body weight (NaN where the foot carries
    nothing); None without recorded forces or a stored body model (for its weight)."""
    if rec.grf_physics is None or rec.cop_physics is None or rec.body_mjcf is None:
        return None
    weight = body_weight(load_model(rec.body_mjcf))
    start = np.asarray(rec.cop_physics, dtype=float)
    tip = start + np.asarray(rec.grf_physics, dtype=float)[:, :2] * (FORCE_M_PER_BW / weight)
    return np.stack([start, tip], axis=2)


def _frame_cameras(rec: Reconstruction) -> np.ndarray:
    """(T, 4, 4) the camera of each frame: camera_T_world2cam, turned where the camera turned
    while filming (meta camera_homographies, camera_motion.py)."""
    turned = rec.meta.get("camera_homographies")
    if turned is None:
        return np.repeat(rec.camera_T_world2cam[None], rec.num_frames, axis=0)
    return frame_cameras(np.asarray(turned, dtype=float), rec.camera_K, rec.camera_T_world2cam)


def _restarting(rec: Reconstruction) -> np.ndarray:
    """(T,) bool: frames from each physics restart (a jump back to the estimate) on, for
    RESTART_SHOWN_S."""
    shown = np.zeros(rec.num_frames, dtype=bool)
    if rec.has_physics:
        span = max(1, round(RESTART_SHOWN_S * rec.fps))
        for f in rec.restarts:
            shown[max(f, 0):f + span] = True
    return shown


def _filming(rec: Reconstruction, motion: str, t_w2c: np.ndarray, t: int) -> np.ndarray:
    """The camera (4, 4) that films ``motion`` at frame t: moved along with the person by the
    camera's travel for the physics where the camera travelled (Reconstruction.camera_travel)."""
    travel = rec.camera_travel(motion)
    if travel is None:
        return t_w2c
    moved = t_w2c.copy()
    moved[:3, 3] -= moved[:3, :3] @ travel[t]  # sees x where t_w2c sees x - travel
    return moved


def _draw_motions(scene: _Scene, image: np.ndarray, k: np.ndarray, t_w2c: np.ndarray, t: int,
                  solids: bool, filmed: bool = False) -> None:
    """Both motions through the camera (k, t_w2c); ``filmed``: t_w2c is the video's camera,
    which follows a travelling person (`_filming`)."""
    for m in sorted(scene.motions, key=lambda m: m != scene.motions[-1]):
        t_w2c_m = _filming(scene.rec, m, t_w2c, t) if filmed else t_w2c
        body = scene.bodies[m]
        if solids and body is not None and body.tree.geoms:
            centers, quats = body.geom_poses()
            # The best motion (the last) is filled; the other one is outlined over it.
            alpha = 0.55 if m == scene.motions[-1] else 0.0
            draw_solids(image, k, t_w2c_m, scene.samples[m], centers[t], quats[t], COLORS[m],
                        alpha=alpha)
        draw_skeleton(image, k, t_w2c_m, joints_of(scene.rec, m)[t], scene.edges, COLORS[m])


def _video_panel(scene: _Scene, frame: np.ndarray | None, t: int, cfg: OverlayConfig):
    w, h = scene.image_size
    scale = cfg.height / h
    if frame is None:
        image = np.empty((cfg.height, round(w * scale), 3), np.uint8)
        image[:] = _BACKGROUND
    else:
        image = cv2.resize(frame, (round(w * scale), cfg.height), interpolation=cv2.INTER_AREA)
    k = np.diag([scale, scale, 1.0]) @ scene.rec.camera_K
    _draw_motions(scene, image, k, scene.cameras[t], t, cfg.solids, filmed=True)
    return image


def _view_camera(scene: _Scene, t: int, cfg: OverlayConfig) -> tuple[np.ndarray, np.ndarray]:
    """The orbit camera (K, T_world2cam) looking at the shown pelvis from the side."""
    best = scene.motions[-1]
    target = joints_of(scene.rec, best)[t, 0].copy()
    target[2] = 0.8
    r_cam2world = scene.rec.camera_T_world2cam[:3, :3].T
    look = r_cam2world[:, 2].copy()
    look[2] = 0.0
    if np.linalg.norm(look) < 1e-6:
        look = np.array([0.0, 1.0, 0.0])
    base = np.arctan2(look[1], look[0]) + np.pi  # azimuth from the target back to the camera
    az, el = base + np.radians(cfg.view_azimuth_deg), np.radians(cfg.view_elevation_deg)
    eye = target + cfg.view_distance * np.array([np.cos(el) * np.cos(az),
                                                 np.cos(el) * np.sin(az), np.sin(el)])
    f = 1.1 * cfg.height
    k = np.array([[f, 0, 0.5 * cfg.height * 4 / 3], [0, f, 0.5 * cfg.height], [0, 0, 1.0]])
    return k, look_at(eye, target)


def _view_panel(scene: _Scene, t: int, cfg: OverlayConfig) -> np.ndarray:
    image = np.empty((cfg.height, round(cfg.height * 4 / 3), 3), np.uint8)
    image[:] = _VIEW_BACKGROUND
    k, t_w2c = _view_camera(scene, t, cfg)
    center = joints_of(scene.rec, scene.motions[-1])[t, 0, :2]
    draw_grid(image, k, t_w2c, center, cfg.grid_extent, cfg.grid_step, _GRID_COLOR)
    tree = next((b.tree for b in scene.bodies.values() if b is not None), None)
    if tree is not None and tree.scene:
        draw_solids(image, k, t_w2c, [geom_samples(g) for g in tree.scene],
                    np.array([g.pos for g in tree.scene]), np.array([g.quat for g in tree.scene]),
                    (125, 143, 154), alpha=0.8)
    for m in scene.motions:
        for foot in range(2):
            if scene.contacts[m][t, foot]:
                draw_ground_disc(image, k, t_w2c, scene.feet_xy[m][t, foot], 0.08, CONTACT_COLOR)
    _draw_motions(scene, image, k, t_w2c, t, cfg.solids)
    if scene.force_arrows is not None:
        for start, tip in scene.force_arrows[t]:
            if not (np.isfinite(start).all() and np.isfinite(tip).all()):
                continue
            px, front = project(k, t_w2c, np.stack([start, tip]))
            if front.all():
                a, b = (tuple(int(round(v)) for v in p) for p in px)
                cv2.arrowedLine(image, a, b, FORCE_COLOR, 2, cv2.LINE_AA, tipLength=0.15)
    return image


def _legend(image: np.ndarray, scene: _Scene, t: int) -> None:
    rows = [(m, COLORS[m]) for m in scene.motions] + [("foot contact", CONTACT_COLOR)]
    if scene.force_arrows is not None:
        rows.append((f"ground force, {FORCE_M_PER_BW:g} m/BW", FORCE_COLOR))
    cv2.rectangle(image, (6, 6), (226, 30 + 20 * len(rows)), (255, 255, 255), -1)
    clock = " real" if scene.rec.slow_motion != 1.0 else ""  # not the footage's time
    cv2.putText(image, f"t = {t / scene.rec.fps:5.2f} s{clock}  frame {t + 1}", (12, 24),
                cv2.FONT_HERSHEY_SIMPLEX, 0.45, (30, 30, 30), 1, cv2.LINE_AA)
    for i, (name, color) in enumerate(rows):
        y = 44 + 20 * i
        cv2.rectangle(image, (12, y - 10), (26, y + 2), color, -1)
        cv2.putText(image, name, (32, y), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (30, 30, 30), 1,
                    cv2.LINE_AA)
    if scene.restarting[t]:  # say why the physics body jumped
        y = 36 + 20 * len(rows)
        cv2.rectangle(image, (6, y), (300, y + 24), RESTART_COLOR, -1)
        cv2.putText(image, "physics restarted from the estimate", (12, y + 16),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)


def compose_frame(scene: _Scene, frame: np.ndarray | None, t: int,
                  cfg: OverlayConfig) -> np.ndarray:
    """One overlay frame (H, W, 3) BGR: video panel beside the 3d view, even width and height."""
    out = np.concatenate([_video_panel(scene, frame, t, cfg), _view_panel(scene, t, cfg)], axis=1)
    _legend(out, scene, t)
    return out[: out.shape[0] // 2 * 2, : out.shape[1] // 2 * 2]


def _frames(rec: Reconstruction, video: str | Path | None) -> tuple[Iterator, tuple[int, int],
                                                                    str]:
    """(iterator of BGR frames or None per analysed frame, image size (w, h), description)."""
    given = video is not None
    path = Path(video) if given else Path(rec.meta.get("source") or "")
    recorded = rec.meta.get("image_size")
    if recorded is not None and not (
            isinstance(recorded, (list, tuple)) and len(recorded) == 2
            and all(isinstance(v, (int, float)) and 0 < v < 1e5 for v in recorded)):
        raise PhysposeError(f"its image_size {recorded!r} is not a width and a height in "
                            "pixels", remedy="re-run the reconstruction")
    size = recorded or (2 * rec.camera_K[0, 2], 2 * rec.camera_K[1, 2])
    size = (int(round(size[0])), int(round(size[1])))
    if not given and not (str(path) and path.is_file()
                          and path.suffix.lower() in videolib.VIDEO_EXTENSIONS):
        return iter([None] * rec.num_frames), size, "plain background (no source video found)"
    info = videolib.probe(path)
    if recorded is not None and tuple(map(int, recorded)) != (info.width, info.height):
        if not given:  # the recorded video has changed since: draw without it
            return iter([None] * rec.num_frames), size, \
                f"plain background ({path} is now {info.width}x{info.height} pixels)"
        raise PhysposeError(f"the video is {info.width}x{info.height} pixels, the result was "
                            f"made from {int(recorded[0])}x{int(recorded[1])}", path=path,
                            remedy="pass the video this result was made from (--video)")
    indices = rec.meta.get("frame_indices")
    if indices is None or len(indices) != rec.num_frames:
        # Seconds into the footage (the result's own clock is the real one).
        times = rec.meta.get("start", 0.0) + np.arange(rec.num_frames) * rec.slow_motion / rec.fps
        indices = np.floor(times * info.fps + 0.5)
    indices = np.asarray(indices, dtype=np.int64)
    if indices.min() < 0 or indices.max() >= info.frame_count:
        raise PhysposeError(f"the result uses frames up to {indices.max()}, the video has "
                            f"{info.frame_count}", path=path,
                            remedy="pass the video this result was made from (--video)")
    return _repeat(videolib.read_frames(info, np.unique(indices)), indices, path), \
        (info.width, info.height), str(path)


def _repeat(decoded, indices: np.ndarray, path: Path) -> Iterator[np.ndarray]:
    """Yield the decoded frame of each index in the non-decreasing `indices`."""
    current, image = -1, None
    for t, idx in enumerate(indices):
        while current < idx:
            nxt = next(decoded, None)
            if nxt is None:
                raise PhysposeError("the video ended early", path=path, frame=t,
                                    remedy="pass the video this result was made from")
            current, image = nxt
        yield image


def render_overlay(result_dir: str | Path, out: str | Path | None = None,
                   video: str | Path | None = None, cfg: OverlayConfig = OverlayConfig(),
                   progress: bool = False) -> OverlayVideo:
    """Write the overlay mp4 (mp4v codec, the analysis frame rate)."""
    rec, folder = load_result(result_dir)
    out = Path(out) if out is not None else folder / DEFAULT_NAME
    frames, size, background = _frames(rec, video)
    scene = _scene(rec, size)
    with atomic_path(out) as tmp:
        writer = None
        try:
            for t in tqdm(range(rec.num_frames), desc="overlay", unit="frame",
                          disable=not progress):
                image = compose_frame(scene, next(frames), t, cfg)
                if writer is None:
                    # Slow-motion footage: the overlay plays at the footage's pace.
                    writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"),
                                             rec.fps / rec.slow_motion,
                                             (image.shape[1], image.shape[0]))
                    if not writer.isOpened():
                        raise PhysposeError("OpenCV cannot write an mp4 video here", path=out,
                                            remedy="check that the folder is writable")
                writer.write(image)
        finally:
            if writer is not None:
                writer.release()
    return OverlayVideo(path=out, background=background)


def save_overlay_png(result_dir: str | Path, frame: int, out: str | Path,
                     video: str | Path | None = None, cfg: OverlayConfig = OverlayConfig()) -> Path:
    """Write overlay frame `frame` (0-based) as a PNG; returns its path."""
    rec, _ = load_result(result_dir)
    if not 0 <= frame < rec.num_frames:
        raise PhysposeError(f"frame {frame} is outside the result's 0-{rec.num_frames - 1}",
                            remedy="pick a frame inside the result")
    frames, size, _ = _frames(rec, video)
    for _ in range(frame):
        next(frames)
    image = compose_frame(_scene(rec, size), next(frames), frame, cfg)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(out), image):
        raise PhysposeError("cannot write the PNG", path=out, remedy="check the folder")
    return out
