"""The world around the body: a ground plane at z = 0 and optional boxes (a chair seat, a step).

Ground softness uses MuJoCo's contact ``solref``: either (timeconst s, dampratio) — the default
(0.01, 1) is a hard, non-bouncing floor — or "direct" (-stiffness, -damping), where stiffness
(1/s^2) and damping (1/s) act per unit of effective mass: the penetration accelerates back at
stiffness x depth. The ``trampoline`` setting is such a soft, lightly damped floor that throws
a dropped body back up (the paper's figure 2). The ground and obstacles have contact priority
over the body, so their friction and softness decide every body-scene contact.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import mujoco
import numpy as np

from physpose.errors import PhysposeError

DEFAULT_FRICTION = 0.9  # sliding friction coefficient of the paper's simulation
GRAVITY = 9.81  # m/s^2
# A trampoline bed: ~2 Hz bounce (k = (2 pi 2)^2 ~ 160 1/s^2) with little loss, allowed to
# sink deep (impedance already high at small depth, so the spring, not the solver, decides).
TRAMPOLINE_STIFFNESS = 150.0  # 1/s^2
TRAMPOLINE_DAMPING = 1.5  # 1/s
_TRAMPOLINE_SOLIMP = (0.95, 0.99, 0.001, 0.5, 2.0)
_HARD_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)  # MuJoCo's default impedance
_SCENE_PRIORITY = 1  # body geoms have priority 0


@dataclass(frozen=True)
class Box:
    """An axis-aligned (up to yaw) box resting in the world: a chair seat, a step, a table.

    center: (x, y, z) metres, world frame. size: full side lengths (sx, sy, sz) metres along
    the box's own x, y, z. yaw: rotation about world z, radians.
    """

    center: tuple[float, float, float]
    size: tuple[float, float, float]
    yaw: float = 0.0

    def __post_init__(self) -> None:
        if len(self.center) != 3 or len(self.size) != 3:
            raise PhysposeError(f"box needs 3 centre and 3 size values, got {self}",
                                remedy="write box:x,y,z,sx,sy,sz[,yaw_deg]")
        values = (*self.center, *self.size, self.yaw)
        if not all(math.isfinite(v) for v in values):
            raise PhysposeError(f"box values must be finite numbers, got {values}",
                                remedy="write box:x,y,z,sx,sy,sz[,yaw_deg] with numbers")
        if min(self.size) <= 0:
            raise PhysposeError(f"box sizes must be positive, got {self.size}",
                                remedy="give full side lengths in metres: "
                                       "box:x,y,z,sx,sy,sz[,yaw_deg]")
        if abs(self.yaw) > 2 * math.pi:
            raise PhysposeError(f"box yaw {self.yaw:g} is more than a full turn: Box takes "
                                "radians", remedy=f"use yaw=math.radians({self.yaw:g}) (the "
                                "command line's box:...,yaw_deg takes degrees)")

    def spec(self) -> str:
        """The box as `parse_obstacle` (and --obstacle) reads it, centimetre precision."""
        values = (*self.center, *self.size)
        text = "box:" + ",".join(f"{v:.2f}" for v in values)
        return text + (f",{math.degrees(self.yaw):.0f}" if self.yaw else "")


@dataclass(frozen=True)
class SceneConfig:
    """Ground (plane z = 0) and obstacles.

    ground_solref: MuJoCo solref of ground contacts, (timeconst, dampratio) when positive or
        (-stiffness, -damping) for direct values (see module docstring).
    ground_solimp: MuJoCo solimp (dmin, dmax, width, midpoint, power) of ground contacts.
    """

    ground_friction: float = DEFAULT_FRICTION
    # 0.01 s: two of the body's 5 ms steps, the hardest floor MuJoCo keeps stable (it clamps a
    # shorter time constant to that). Stop 96: on 0.02 s the feet sank 2-6 mm on average and
    # up to 3 cm on landings and slid there; at 0.01 s they slid less on the real clips that
    # skated most and motion capture's image error fell 2 px (docs/dynamics.md, Measured).
    ground_solref: tuple[float, float] = (0.01, 1.0)
    ground_solimp: tuple[float, float, float, float, float] = _HARD_SOLIMP
    obstacles: tuple[Box, ...] = ()
    obstacle_friction: float = DEFAULT_FRICTION
    gravity: float = GRAVITY

    def __post_init__(self) -> None:
        for name in ("ground_friction", "obstacle_friction"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise PhysposeError(f"{name.replace('_', ' ')} {value} must be >= 0",
                                    remedy="give a friction coefficient such as 0.9")
        if not (math.isfinite(self.gravity) and self.gravity > 0):
            raise PhysposeError(f"gravity {self.gravity} must be a positive magnitude (m/s^2; "
                                "it points down, -z)", remedy=f"use e.g. {GRAVITY}")
        if isinstance(self.obstacles, list):  # as good as a tuple, and kept as one
            object.__setattr__(self, "obstacles", tuple(self.obstacles))
        if not isinstance(self.obstacles, tuple) or \
                not all(isinstance(box, Box) for box in self.obstacles):
            raise PhysposeError(f"obstacles must be a tuple of Box, not {self.obstacles!r}",
                                remedy="e.g. obstacles=(Box(center=(x, y, z), size=(sx, sy, sz)),)"
                                       " or parse_obstacle('box:x,y,z,sx,sy,sz')")
        a, b = self.ground_solref
        if not (math.isfinite(a) and math.isfinite(b)) or (a > 0) != (b > 0) or a == 0:
            raise PhysposeError(f"ground solref {self.ground_solref} mixes signs or is zero",
                                remedy="use (timeconst, dampratio) > 0 or "
                                       "(-stiffness, -damping) < 0")

    def with_ground(self, stiffness: float | None = None, damping: float | None = None,
                    friction: float | None = None) -> SceneConfig:
        """A copy with direct ground stiffness (1/s^2) and/or damping (1/s), or friction.

        Giving only one of stiffness/damping keeps the other at the value that matches the
        current floor (critically damped for the default floor); giving neither keeps the
        floor's contact as it is.
        """
        for name, v in (("stiffness", stiffness), ("damping", damping)):
            if v is not None and not (math.isfinite(v) and v > 0):
                raise PhysposeError(f"ground {name} {v} must be positive",
                                    remedy=f"give --ground-{name} as a positive number")
        if stiffness is None and damping is None:
            return self if friction is None else dataclasses.replace(
                self, ground_friction=float(friction))
        k, d = self.ground_stiffness_damping()
        k = k if stiffness is None else float(stiffness)
        d = (2.0 * math.sqrt(k) if stiffness is not None else d) if damping is None \
            else float(damping)
        return dataclasses.replace(
            self, ground_solref=(-k, -d),
            ground_friction=self.ground_friction if friction is None else float(friction))

    def ground_stiffness_damping(self) -> tuple[float, float]:
        """The ground's (stiffness 1/s^2, damping 1/s) in MuJoCo's direct form: the solref
        (-stiffness, -damping) that makes the same contact. MuJoCo divides both forms by the
        impedance dmax alike (stiffness by dmax^2, damping by dmax), so (timeconst,
        dampratio) is (1 / (timeconst dampratio)^2, 2 / timeconst); with dmax folded in as
        well, a floor given only a friction had come out 1/dmax^2 stiffer."""
        a, b = self.ground_solref
        if a < 0:
            return -a, -b
        return 1.0 / (a * a * b * b), 2.0 / a


def trampoline(base: SceneConfig = SceneConfig()) -> SceneConfig:
    """The named trampoline floor (soft and springy) on top of a scene's other settings."""
    return dataclasses.replace(base, ground_solref=(-TRAMPOLINE_STIFFNESS, -TRAMPOLINE_DAMPING),
                               ground_solimp=_TRAMPOLINE_SOLIMP)


def parse_obstacle(text: str) -> Box:
    """Parse ``box:x,y,z,sx,sy,sz[,yaw_deg]`` (centre and full sizes in metres, yaw in degrees).

    Example, a 45 cm chair seat behind a person at the origin:
    ``box:-0.35,0,0.225,0.45,0.45,0.45``.
    """
    remedy = "write box:x,y,z,sx,sy,sz[,yaw_deg] (centre and full sizes in metres)"
    kind, sep, rest = text.partition(":")
    if not sep or kind.strip().lower() != "box":
        raise PhysposeError(f"obstacle {text!r} is not a box specification", remedy=remedy)
    parts = [p.strip() for p in rest.split(",")]
    if len(parts) not in (6, 7):
        raise PhysposeError(f"obstacle {text!r} has {len(parts)} numbers, expected 6 or 7",
                            remedy=remedy)
    try:
        v = [float(p) for p in parts]
    except ValueError:
        raise PhysposeError(f"obstacle {text!r} contains a value that is not a number",
                            remedy=remedy) from None
    yaw_deg = v[6] if len(v) == 7 else 0.0
    if math.isfinite(yaw_deg):
        yaw_deg = math.remainder(yaw_deg, 360.0)  # any number of turns
    return Box(center=(v[0], v[1], v[2]), size=(v[3], v[4], v[5]), yaw=math.radians(yaw_deg))


def add_scene(spec: mujoco.MjSpec, scene: SceneConfig) -> None:
    """Add the ground plane ("floor"), obstacles ("obstacle_<i>"), light and gravity to a spec."""
    spec.option.gravity = [0.0, 0.0, -scene.gravity]
    spec.add_texture(name="sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
                     builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT, width=256, height=256,
                     rgb1=[0.75, 0.85, 0.95], rgb2=[0.35, 0.45, 0.6])
    tex = spec.add_texture(name="grid", type=mujoco.mjtTexture.mjTEXTURE_2D,
                           builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, width=256, height=256,
                           rgb1=[0.82, 0.84, 0.86], rgb2=[0.62, 0.65, 0.68])
    mat = spec.add_material(name="floor", texrepeat=[1.0, 1.0], reflectance=0.05)
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = tex.name
    spec.worldbody.add_light(name="sun", pos=[0.0, -2.0, 4.0], dir=[0.0, 0.4, -1.0],
                             diffuse=[0.8, 0.8, 0.8], castshadow=True)
    floor = spec.worldbody.add_geom(
        name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0.0, 0.0, 0.05],
        material="floor", priority=_SCENE_PRIORITY, condim=3)
    floor.friction = [scene.ground_friction, 0.005, 0.0001]
    floor.solref = list(scene.ground_solref)
    floor.solimp = list(scene.ground_solimp)
    for i, box in enumerate(scene.obstacles):
        half = 0.5 * np.asarray(box.size, dtype=float)
        g = spec.worldbody.add_geom(
            name=f"obstacle_{i}", type=mujoco.mjtGeom.mjGEOM_BOX, size=half.tolist(),
            pos=list(box.center), quat=[math.cos(box.yaw / 2), 0.0, 0.0, math.sin(box.yaw / 2)],
            rgba=[0.55, 0.42, 0.3, 1.0], priority=_SCENE_PRIORITY, condim=3)
        g.friction = [scene.obstacle_friction, 0.005, 0.0001]
