"""A picture of a body in its scene, for people to check the model: PNG via MuJoCo or matplotlib.

MuJoCo's offscreen renderer needs an OpenGL context: run with ``MUJOCO_GL=egl`` (headless GPU
or Mesa EGL) or ``MUJOCO_GL=osmesa``. When neither MUJOCO_GL nor a display is set, or no
context can be made, the "auto" backend draws a matplotlib 3d projection of the same geoms
instead and says so in its result.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from physpose.body import Body
from physpose.errors import PhysposeError

BACKENDS = ("auto", "mujoco", "matplotlib")


@dataclass(frozen=True)
class RenderConfig:
    """Camera and image. azimuth/elevation in degrees (MuJoCo's free camera convention);
    distance in metres (None: fit the body's height); landmarks: draw the 33 landmark sites."""

    width: int = 640
    height: int = 800
    azimuth: float = 150.0
    elevation: float = -12.0
    distance: float | None = None
    landmarks: bool = True
    backend: str = "auto"

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise PhysposeError(f"unknown render backend {self.backend!r}",
                                remedy=f"use one of {BACKENDS}")
        if not (16 <= self.width <= 4096 and 16 <= self.height <= 4096):
            raise PhysposeError(f"image size {self.width}x{self.height} is out of range",
                                remedy="use widths and heights between 16 and 4096 pixels")


def render_image(body: Body, qpos: np.ndarray, cfg: RenderConfig = RenderConfig()
                 ) -> tuple[np.ndarray, str]:
    """Draw the body at qpos (55,) in its scene: (image (H, W, 3) uint8, backend used)."""
    data = mujoco.MjData(body.model)
    data.qpos[:] = qpos
    mujoco.mj_forward(body.model, data)
    # Without MUJOCO_GL or a display MuJoCo would try GLFW, which cannot work headless.
    gl_possible = bool(os.environ.get("MUJOCO_GL") or os.environ.get("DISPLAY"))
    if cfg.backend == "mujoco" or (cfg.backend == "auto" and gl_possible):
        try:
            return _render_mujoco(body, data, cfg), "mujoco"
        except (mujoco.FatalError, RuntimeError, AttributeError, ImportError) as err:
            if cfg.backend == "mujoco":
                raise PhysposeError(f"MuJoCo could not open an OpenGL context ({err})",
                                    remedy="set MUJOCO_GL=egl (or osmesa), or use the "
                                           "matplotlib backend") from err
    return _render_matplotlib(body, data, cfg), "matplotlib"


def render_png(body: Body, qpos: np.ndarray, path: str | Path,
               cfg: RenderConfig = RenderConfig()) -> str:
    """Write the picture of ``render_image`` to a PNG file; returns the backend used."""
    import matplotlib.image

    image, backend = render_image(body, qpos, cfg)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    matplotlib.image.imsave(path, image)
    return backend


def _camera(body: Body, data: mujoco.MjData, cfg: RenderConfig) -> tuple[np.ndarray, float]:
    lookat = data.subtree_com[body.body_ids["pelvis"]].copy()
    lookat[2] = 0.5 * body.shape.height
    return lookat, cfg.distance if cfg.distance is not None else 1.9 * body.shape.height


def _render_mujoco(body: Body, data: mujoco.MjData, cfg: RenderConfig) -> np.ndarray:
    model = body.model
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, cfg.width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, cfg.height)
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:], cam.distance = _camera(body, data, cfg)
    cam.azimuth, cam.elevation = cfg.azimuth, cfg.elevation
    opt = mujoco.MjvOption()
    opt.sitegroup[:] = 0
    opt.sitegroup[3] = 1 if cfg.landmarks else 0
    with mujoco.Renderer(model, cfg.height, cfg.width) as renderer:
        renderer.update_scene(data, camera=cam, scene_option=opt)
        return renderer.render().copy()


def _render_matplotlib(body: Body, data: mujoco.MjData, cfg: RenderConfig) -> np.ndarray:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    model = body.model
    dpi = 100
    fig = plt.figure(figsize=(cfg.width / dpi, cfg.height / dpi), dpi=dpi)
    ax = fig.add_subplot(projection="3d")
    lookat, dist = _camera(body, data, cfg)
    half = 0.3 * dist
    for g in range(model.ngeom):
        kind, pos = model.geom_type[g], data.geom_xpos[g]
        rot = data.geom_xmat[g].reshape(3, 3)
        color = model.geom_rgba[g][:3]
        if kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
            r, h = model.geom_size[g][:2]
            ends = np.stack([pos - h * rot[:, 2], pos + h * rot[:, 2]])
            ax.plot(*ends.T, color=color, linewidth=max(1.0, 2.2 * r / half * cfg.width / 10),
                    solid_capstyle="round")
        elif kind == mujoco.mjtGeom.mjGEOM_BOX:
            _draw_box(ax, pos, rot, model.geom_size[g], color)
        elif kind == mujoco.mjtGeom.mjGEOM_PLANE:
            xs = np.linspace(lookat[0] - half, lookat[0] + half, 7)
            ys = np.linspace(lookat[1] - half, lookat[1] + half, 7)
            for x in xs:
                ax.plot([x, x], [ys[0], ys[-1]], [0, 0], color="0.7", linewidth=0.6)
            for y in ys:
                ax.plot([xs[0], xs[-1]], [y, y], [0, 0], color="0.7", linewidth=0.6)
    if cfg.landmarks:
        ax.scatter(*data.site_xpos[body.landmark_site_ids].T, color="red", s=6, depthshade=False)
    ax.set_xlim(lookat[0] - half, lookat[0] + half)
    ax.set_ylim(lookat[1] - half, lookat[1] + half)
    ax.set_zlim(lookat[2] - half, lookat[2] + half)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=-cfg.elevation, azim=cfg.azimuth + 180.0)  # MuJoCo looks along azimuth
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    fig.canvas.draw()
    image = np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    plt.close(fig)
    return image


def _draw_box(ax, pos: np.ndarray, rot: np.ndarray, half: np.ndarray, color) -> None:
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * half
    world = pos + corners @ rot.T
    for i in range(8):
        for j in range(i + 1, 8):
            if np.sum(np.abs(corners[i] - corners[j]) > 1e-12) == 1:  # differ in one axis
                ax.plot(*world[[i, j]].T, color=color, linewidth=1.2)
