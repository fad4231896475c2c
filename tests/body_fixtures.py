"""Shapes and scenes the body tests run over, and small simulation helpers."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from physpose.body import Body, build_body, standing_qpos
from physpose.scene import Box, SceneConfig, trampoline
from physpose.shape import BodyShape
from physpose.skeleton import DOF_NAMES

SHAPES: dict[str, BodyShape] = {
    "short": BodyShape.from_height(1.5),
    "tall": BodyShape.from_height(1.95),
    "light": BodyShape.from_height(1.75, mass=45.0),
    "heavy": BodyShape.from_height(1.75, mass=120.0),
}
# A chair seat behind the person and a step in front, clear of the standing body.
CHAIR = Box(center=(-0.55, 0.0, 0.225), size=(0.45, 0.45, 0.45))
STEP = Box(center=(0.6, 0.0, 0.09), size=(0.35, 0.9, 0.18), yaw=math.radians(10.0))
SCENES: dict[str, SceneConfig] = {
    "default": SceneConfig(),
    "trampoline": trampoline(),
    "chair": SceneConfig(obstacles=(CHAIR,)),
    "step": SceneConfig(obstacles=(STEP,)),
}


def dof(name: str) -> int:
    """qpos index of a hinge."""
    return 7 + DOF_NAMES.index(name)


def simulate(body: Body, qpos: np.ndarray, seconds: float, ctrl: np.ndarray | None = None
             ) -> tuple[np.ndarray, mujoco.MjData]:
    """Step from qpos at rest with constant servo targets (default: hold qpos): (T, 55) qpos."""
    data = mujoco.MjData(body.model)
    data.qpos[:] = qpos
    data.ctrl[:] = qpos[7:] if ctrl is None else ctrl
    out = np.empty((int(round(seconds / body.model.opt.timestep)), body.model.nq))
    for t in range(len(out)):
        mujoco.mj_step(body.model, data)
        out[t] = data.qpos
    return out, data


def standing(shape_name: str, scene_name: str = "default") -> tuple[Body, np.ndarray]:
    body = build_body(SHAPES[shape_name], SCENES[scene_name])
    return body, standing_qpos(body)
