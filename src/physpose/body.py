"""The simulation-ready body: capsules and boxes sized from a BodyShape, servos, in a scene.

Built with ``mujoco.MjSpec`` from the skeleton (physpose.skeleton): one MuJoCo body per
segment, a free root joint named "root" and three hinges per joint named ``<joint>_<axis>``
(DOF_NAMES), a position servo per hinge named like it, a site per MediaPipe landmark (named as
in LANDMARK_NAMES) and per project joint (named as in JOINT_NAMES).

Mass. Each body's geoms get a volume; the total mass is split over the anatomical segments of
de Leva (1996), "Adjustments to Zatsiorsky-Seluyanov's segment inertia parameters", J Biomech
29:1223, table 4 (male and female columns; "neutral" is their mean), and a segment's mass is
shared among its bodies and geoms in proportion to their volume. Inertia follows from each
geom's shape at that mass (uniform density within a geom).

Actuation. Position servos (force = kp (target - q), clipped to +-torque limit, and a damping
-kv qdot applied outside the clip, as the actuator's own unclamped damping) with kp = limit /
saturation angle, so every joint saturates at the same error, and kv chosen by MuJoCo for the
requested damping ratio from the joint's reflected inertia in the rest pose (1 / the diagonal
of the inverse mass matrix, the rest of the body free: a hip swinging its leg from a pelvis
held still moves more inertia and is damped less than that ratio says; docs/body_model.md).
The simulation does not clip targets (the force limit
bounds their effect); the dynamics' initial targets are kept within the joint ranges
(dynamics.init.initial_coefficients). The root has no actuator.
Integrator implicitfast at 200 Hz (explicit Euler blew up at 200 Hz; DESIGN.md).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from physpose.errors import PhysposeError, expect_type
from physpose.joints import JOINT_NAMES, LANDMARK_NAMES
from physpose.scene import SceneConfig, add_scene
from physpose.shape import HEAD_TOP_PER_EAR_WIDTH, BodyShape
from physpose.skeleton import (AXES, AXIS_VECTORS, DOF_LIMITS, DOF_NAMES, DOF_TORQUE,
                               JOINT_POINTS, LANDMARK_SITES, NQ, NUM_DOF, NV, REFERENCE_HEIGHT,
                               REFERENCE_MASS, SEGMENT_NAMES, SEGMENTS, joint_offsets, landmark_offsets,
                               segment_offsets)

# Segment mass fractions (% of body mass, one side for limbs), de Leva 1996 table 4.
# upper_trunk = upper + middle trunk; lower_trunk = lower trunk (omphalion to hip joints).
SEGMENT_MASS_PERCENT: dict[str, dict[str, float]] = {
    "male": {"head": 6.94, "upper_trunk": 15.96 + 16.33, "lower_trunk": 11.17,
             "upper_arm": 2.71, "forearm": 1.62, "hand": 0.61, "thigh": 14.16, "shank": 4.33,
             "foot": 1.37},
    "female": {"head": 6.68, "upper_trunk": 15.45 + 14.65, "lower_trunk": 12.47,
               "upper_arm": 2.55, "forearm": 1.38, "hand": 0.56, "thigh": 14.78,
               "shank": 4.81, "foot": 1.29},
}
SEGMENT_MASS_PERCENT["neutral"] = {k: 0.5 * (SEGMENT_MASS_PERCENT["male"][k]
                                             + SEGMENT_MASS_PERCENT["female"][k])
                                   for k in SEGMENT_MASS_PERCENT["male"]}
# Body pairs that always touch in the rest pose although they are not parent and child: the
# upper arms and neck sit on the chest through the small shoulder-girdle body, and the trunk
# capsules overlap along the spine.
EXCLUDED_PAIRS: tuple[tuple[str, str], ...] = (
    ("spine", "l_shoulder"), ("spine", "r_shoulder"), ("spine", "neck"), ("pelvis", "thorax"))
# Thighs are kept from overlapping each other in the rest pose (their radius is capped at this
# fraction of half the hip width; the mass table, not the volume, sets their mass).
_MAX_THIGH_RADIUS_PER_HALF_HIP = 0.9

_CAPSULE = mujoco.mjtGeom.mjGEOM_CAPSULE
_BOX = mujoco.mjtGeom.mjGEOM_BOX
_SKIN = [0.85, 0.68, 0.55, 1.0]
_SKIN_LEFT = [0.62, 0.74, 0.88, 1.0]  # left side tinted so handedness shows in renders


@dataclass(frozen=True)
class BodyConfig:
    """Actuation and integration settings of the simulated body.

    saturation_angle: servo error (rad) at which a joint reaches its torque limit (kp = limit /
        this). dampratio: servo damping ratio (kv from the rest-pose reflected inertia).
    armature: rotor inertia added to every hinge, kg m^2 (numerical stiffening for light
        segments). timestep: s. self_collision: contacts between non-adjacent segments.
    """

    saturation_angle: float = 0.25
    dampratio: float = 1.0
    armature: float = 0.01
    timestep: float = 0.005
    self_collision: bool = True
    body_friction: float = 0.9

    def __post_init__(self) -> None:
        for name in ("saturation_angle", "dampratio", "timestep"):
            if not getattr(self, name) > 0:
                raise PhysposeError(f"body config {name} must be positive",
                                    remedy="use the defaults of BodyConfig")
        if self.armature < 0:
            raise PhysposeError("body config armature must be >= 0",
                                remedy="use the defaults of BodyConfig")


@dataclass(frozen=True, eq=False)
class Body:
    """A compiled body + scene and the index maps the other stages need.

    dof_names (48,): hinge names; actuator k drives dof k; qpos_adr/qvel_adr/actuator_ids
        (48,) int: where each dof lives in qpos, qvel and ctrl (qpos_adr = 7 + k).
    body_ids: segment name -> MuJoCo body id. landmark_site_ids (33,): LANDMARK_NAMES order.
    joint_site_ids (21,): JOINT_NAMES order. foot_geom_ids: {"l": id, "r": id}.
    kp, kv, torque_limit (48,): servo gains (N·m/rad, N·m·s/rad) and force limits (N·m).
    segment_masses: body name -> kg. total_mass: kg.
    """

    shape: BodyShape
    scene: SceneConfig
    config: BodyConfig
    spec: mujoco.MjSpec
    model: mujoco.MjModel
    xml: str
    dof_names: tuple[str, ...]
    qpos_adr: np.ndarray
    qvel_adr: np.ndarray
    actuator_ids: np.ndarray
    body_ids: dict[str, int]
    landmark_site_ids: np.ndarray
    joint_site_ids: np.ndarray
    foot_geom_ids: dict[str, int]
    kp: np.ndarray
    kv: np.ndarray
    torque_limit: np.ndarray
    segment_masses: dict[str, float] = field(default_factory=dict)
    total_mass: float = 0.0


@dataclass(frozen=True)
class _GeomPlan:
    name: str
    type: int
    size: tuple[float, ...]
    pos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    fromto: tuple[float, ...] | None = None

    def volume(self) -> float:
        if self.type == _BOX:
            return 8.0 * self.size[0] * self.size[1] * self.size[2]
        r = self.size[0]
        a, b = np.asarray(self.fromto[:3]), np.asarray(self.fromto[3:])
        return math.pi * r * r * float(np.linalg.norm(b - a)) + 4.0 / 3.0 * math.pi * r ** 3


def _capsule(name: str, r: float, a, b) -> _GeomPlan:
    return _GeomPlan(name, _CAPSULE, (r,), fromto=tuple(float(v) for v in (*a, *b)))


def _box(name: str, center, half) -> _GeomPlan:
    return _GeomPlan(name, _BOX, tuple(float(v) for v in half),
                     pos=tuple(float(v) for v in center))


def _geometry(shape: BodyShape) -> dict[str, list[_GeomPlan]]:
    """Geoms of each segment in its own frame (rest pose), from the shape."""
    s = shape
    t, hw, sw = s.trunk, s.hip_width, s.shoulder_width
    head_top = HEAD_TOP_PER_EAR_WIDTH * s.ear_width
    head_lo, head_hi = -0.1 * s.ear_width, max(head_top - s.r_head, 0.0)
    geoms: dict[str, list[_GeomPlan]] = {
        "pelvis": [_capsule("pelvis", s.r_pelvis, (0, -0.3 * hw, 0.1 * t), (0, 0.3 * hw, 0.1 * t)),
                   _capsule("abdomen", s.r_abdomen, (0, 0, 0.3 * t), (0, 0, 0.5 * t))],
        "spine": [_capsule("chest", s.r_chest, (0, 0, 0.05 * t), (0, 0, 0.3 * t))],
        "thorax": [_capsule("upper_chest", s.r_upper_chest,
                            (0, -max(0.5 * sw - s.r_upper_chest, 0.01), -0.6 * s.r_upper_chest),
                            (0, max(0.5 * sw - s.r_upper_chest, 0.01), -0.6 * s.r_upper_chest))],
        "neck": [_capsule("neck", s.r_neck, (0, 0, -0.5 * s.neck), (0, 0, 0.5 * s.neck))],
        "head": [_capsule("head", s.r_head, (0.1 * s.ear_width, 0, min(head_lo, head_hi - 1e-3)),
                          (0.1 * s.ear_width, 0, head_hi))],
    }
    for side in ("l", "r"):
        geoms[f"{side}_shoulder"] = [_capsule(f"{side}_upper_arm", s.r_upper_arm,
                                              (0, 0, 0), (0, 0, -s.upper_arm))]
        geoms[f"{side}_elbow"] = [_capsule(f"{side}_forearm", s.r_forearm,
                                           (0, 0, 0), (0, 0, -s.forearm))]
        geoms[f"{side}_wrist"] = [_box(f"{side}_hand", (0, 0, -0.5 * s.hand_length),
                                       (0.5 * s.hand_width, 0.5 * s.hand_thickness,
                                        0.5 * s.hand_length))]
        r_thigh = min(s.r_thigh, _MAX_THIGH_RADIUS_PER_HALF_HIP * 0.5 * hw)
        geoms[f"{side}_hip"] = [_capsule(f"{side}_thigh", r_thigh, (0, 0, 0), (0, 0, -s.thigh))]
        geoms[f"{side}_knee"] = [_capsule(f"{side}_shank", s.r_shank, (0, 0, 0),
                                          (0, 0, -max(s.shank - s.r_shank, 0.5 * s.shank)))]
        geoms[f"{side}_ankle"] = [_box(f"{side}_foot",
                                       (0.5 * s.foot_length - s.heel_back, 0,
                                        -s.ankle_height + 0.5 * s.foot_height),
                                       (0.5 * s.foot_length, 0.5 * s.foot_width,
                                        0.5 * s.foot_height))]
    return geoms


def segment_masses(shape: BodyShape) -> dict[str, float]:
    """Mass of each segment body (kg): de Leva fractions, shared by volume within a group."""
    geoms = _geometry(shape)
    percent = SEGMENT_MASS_PERCENT[shape.sex]
    volume = {seg.name: sum(g.volume() for g in geoms[seg.name]) for seg in SEGMENTS}
    # A limb group is per side; trunk and head groups span several bodies.
    group_of = {seg.name: seg.mass_group + (seg.name[:2] if seg.name[:2] in ("l_", "r_") else "")
                for seg in SEGMENTS}
    group_volume: dict[str, float] = {}
    for name, g in group_of.items():
        group_volume[g] = group_volume.get(g, 0.0) + volume[name]
    group_percent = {g: percent[seg.mass_group] for seg in SEGMENTS
                     for g in (group_of[seg.name],)}
    scale = shape.mass / sum(group_percent.values())  # the table's rows sum to ~100 %
    return {seg.name: scale * percent[seg.mass_group] * volume[seg.name]
            / group_volume[group_of[seg.name]] for seg in SEGMENTS}


def torque_limits(shape: BodyShape) -> np.ndarray:
    """Per-dof force limits (48,) N·m: the skeleton's table scaled by mass x height."""
    return DOF_TORQUE * (shape.mass * shape.height) / (REFERENCE_MASS * REFERENCE_HEIGHT)


def build_body(shape: BodyShape, scene: SceneConfig = SceneConfig(),
               config: BodyConfig = BodyConfig()) -> Body:
    """Compile the body of ``shape`` standing in ``scene`` (rest pose, pelvis at the origin)."""
    for value, kind, what, example in ((shape, BodyShape, "shape", "BodyShape.from_height(1.75)"),
                                       (scene, SceneConfig, "scene", "SceneConfig()"),
                                       (config, BodyConfig, "config", "BodyConfig()")):
        expect_type(value, kind, f"build_body's {what}", f"pass e.g. {example}")
    spec = mujoco.MjSpec()
    spec.modelname = "physpose_body"
    spec.compiler.degree = False
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_TRUE
    spec.option.timestep = config.timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    add_scene(spec, scene)

    bones = shape.bones()
    offsets = segment_offsets(bones)
    lm_offsets = landmark_offsets(bones)
    geoms = _geometry(shape)
    masses = segment_masses(shape)
    limits = torque_limits(shape)
    mj_bodies: dict[str, mujoco.MjsBody] = {}
    for i, seg in enumerate(SEGMENTS):
        parent = spec.worldbody if seg.parent is None else mj_bodies[seg.parent]
        b = parent.add_body(name=seg.name, pos=offsets[i].tolist())
        mj_bodies[seg.name] = b
        if seg.parent is None:
            b.add_freejoint(name="root")
        else:
            for k, axis in enumerate(AXES):
                lo, hi = DOF_LIMITS[3 * (i - 1) + k]
                b.add_joint(name=f"{seg.name}_{axis}", type=mujoco.mjtJoint.mjJNT_HINGE,
                            axis=list(AXIS_VECTORS[axis]), range=[lo, hi], limited=True,
                            armature=config.armature)
        vol = sum(g.volume() for g in geoms[seg.name])
        for g in geoms[seg.name]:
            left = seg.name.startswith("l_")
            mg = b.add_geom(name=g.name, type=g.type, size=list(g.size) + [0.0] * (3 - len(g.size)),
                            pos=list(g.pos), mass=masses[seg.name] * g.volume() / vol,
                            rgba=_SKIN_LEFT if left else _SKIN,
                            contype=1, conaffinity=1 if config.self_collision else 0, condim=3)
            if g.fromto is not None:
                mg.fromto = list(g.fromto)
            mg.friction = [config.body_friction, 0.005, 0.0001]
    for name, (parent, _) in LANDMARK_SITES.items():
        mj_bodies[parent].add_site(name=name, pos=lm_offsets[LANDMARK_NAMES.index(name)].tolist(),
                                   size=[0.012, 0, 0], rgba=[0.9, 0.1, 0.1, 1.0], group=3)
    j_offsets = joint_offsets(shape.bones())
    for i, name in enumerate(JOINT_NAMES):
        parent, _ = JOINT_POINTS[name]
        mj_bodies[parent].add_site(name=name, pos=j_offsets[i].tolist(), size=[0.015, 0, 0],
                                   rgba=[0.1, 0.3, 0.9, 1.0], group=4)
    for a, b in EXCLUDED_PAIRS:
        spec.add_exclude(name=f"exclude_{a}_{b}", bodyname1=a, bodyname2=b)
    actuators = []
    for k, dof in enumerate(DOF_NAMES):
        act = spec.add_actuator(name=dof, target=dof, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=float(limits[k] / config.saturation_angle),
                            dampratio=config.dampratio)
        act.forcelimited = True
        act.forcerange = [-float(limits[k]), float(limits[k])]
        actuators.append(act)
    model = _compile(spec)
    # Move the servo damping (kv, from the damping ratio) out of the force-limited term into
    # the actuator's own unclamped damping: a clamped kv vanishes exactly when velocities are
    # high while implicitfast still integrates it, and violent targets then blew up.
    kv = -model.actuator_biasprm[:NUM_DOF, 2]
    for act, d in zip(actuators, kv):
        act.biasprm[2] = 0.0
        act.damping = [float(d), 0.0, 0.0]
    stand = _standing(model)
    spec.add_key(name="standing", qpos=stand.tolist(), ctrl=stand[7:].tolist())
    return _index(shape, scene, config, spec, _compile(spec), masses, limits)


def _compile(spec: mujoco.MjSpec) -> mujoco.MjModel:
    try:
        return spec.compile()
    except ValueError as err:  # MuJoCo reports compile problems as ValueError
        raise PhysposeError(f"the body model did not compile: {err}",
                            remedy="check the body shape (lengths and radii) for odd values") \
            from err


def _index(shape, scene, config, spec, model, masses, limits) -> Body:
    def ids(kind, names):
        return np.array([mujoco.mj_name2id(model, kind, n) for n in names], dtype=int)

    jnt = ids(mujoco.mjtObj.mjOBJ_JOINT, DOF_NAMES)
    body_ids = {n: int(i) for n, i in zip(SEGMENT_NAMES, ids(mujoco.mjtObj.mjOBJ_BODY,
                                                             SEGMENT_NAMES))}
    qpos_adr = model.jnt_qposadr[jnt].astype(int)
    # The skeleton's depth-first segment order must be MuJoCo's body and qpos order.
    assert list(body_ids.values()) == list(range(1, len(SEGMENT_NAMES) + 1)), body_ids
    assert np.array_equal(qpos_adr, np.arange(7, NQ)) and model.nq == NQ and model.nv == NV
    act = ids(mujoco.mjtObj.mjOBJ_ACTUATOR, DOF_NAMES)
    assert np.array_equal(act, np.arange(NUM_DOF))
    return Body(
        shape=shape, scene=scene, config=config, spec=spec, model=model, xml=spec.to_xml(),
        dof_names=DOF_NAMES, qpos_adr=qpos_adr, qvel_adr=model.jnt_dofadr[jnt].astype(int),
        actuator_ids=act, body_ids=body_ids,
        landmark_site_ids=ids(mujoco.mjtObj.mjOBJ_SITE, LANDMARK_NAMES),
        joint_site_ids=ids(mujoco.mjtObj.mjOBJ_SITE, JOINT_NAMES),
        foot_geom_ids={s: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{s}_foot")
                       for s in ("l", "r")},
        kp=model.actuator_gainprm[:NUM_DOF, 0].copy(),
        kv=model.actuator_damping[:NUM_DOF].copy(),
        torque_limit=np.asarray(limits, dtype=float).copy(),
        segment_masses=dict(masses), total_mass=float(model.body_subtreemass[1]),
    )


def rest_qpos() -> np.ndarray:
    """qpos of the rest pose with the pelvis at the origin, identity orientation: (55,)."""
    q = np.zeros(NQ)
    q[3] = 1.0
    return q


def standing_qpos(body: Body, xy: tuple[float, float] = (0.0, 0.0), yaw: float = 0.0,
                  arm_abduction: float | None = None) -> np.ndarray:
    """A relaxed standing pose with the soles on z = 0: (55,) qpos (also keyframe "standing").

    Knees and hips straight, arms hanging slightly away from the body: the shoulder abduction
    (rad) is the smallest multiple of 2 degrees from 4 degrees on at which no body geom touches
    another, unless ``arm_abduction`` is given. Facing +x rotated by ``yaw`` (rad) about z.
    """
    return _standing(body.model, xy, yaw, arm_abduction)


def _standing(model: mujoco.MjModel, xy: tuple[float, float] = (0.0, 0.0), yaw: float = 0.0,
              arm_abduction: float | None = None) -> np.ndarray:
    data = mujoco.MjData(model)
    q = rest_qpos()
    q[3:7] = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
    angles = np.arange(4.0, 40.0, 2.0) if arm_abduction is None else [math.degrees(arm_abduction)]
    for deg in angles:
        for side, sign in (("l", 1.0), ("r", -1.0)):
            q[7 + DOF_NAMES.index(f"{side}_shoulder_x")] = sign * math.radians(deg)
        _place_on_ground(model, data, q, xy)
        if arm_abduction is not None or not self_contacts(model, data):
            break
    return q


def _place_on_ground(model: mujoco.MjModel, data: mujoco.MjData, q: np.ndarray,
                     xy: tuple[float, float]) -> None:
    """Shift the root so the lowest point of the feet is at z = 0 (in place)."""
    q[0:3] = [xy[0], xy[1], 0.0]
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    lowest = min(_box_lowest_z(model, data, mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM,
                                                              f"{s}_foot")) for s in ("l", "r"))
    q[2] = -lowest
    data.qpos[:] = q
    mujoco.mj_forward(model, data)


def _box_lowest_z(model: mujoco.MjModel, data: mujoco.MjData, geom: int) -> float:
    half = model.geom_size[geom]
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
    world = data.geom_xpos[geom] + corners @ data.geom_xmat[geom].reshape(3, 3).T
    return float(world[:, 2].min())


def self_contacts(model: mujoco.MjModel, data: mujoco.MjData) -> list[tuple[str, str]]:
    """Names of body geoms touching each other (scene geoms left out), after mj_forward."""
    pairs = []
    for c in data.contact[: data.ncon]:
        if model.geom_bodyid[c.geom1] > 0 and model.geom_bodyid[c.geom2] > 0:
            pairs.append((mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, c.geom1),
                          mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, c.geom2)))
    return pairs


def with_config(body: Body, **changes) -> Body:
    """Rebuild a body with changed BodyConfig fields (e.g. timestep=0.01)."""
    return build_body(body.shape, body.scene, dataclasses.replace(body.config, **changes))
