"""The scene: ground friction and softness, the trampoline, obstacle boxes, sitting on a chair."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from body_fixtures import SHAPES, dof, simulate

from physpose.body import build_body, standing_qpos
from physpose.errors import PhysposeError
from physpose.scene import Box, SceneConfig, parse_obstacle, trampoline


def _geom(model, name):
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)


def test_parse_obstacle():
    box = parse_obstacle("box:-0.5, 0, 0.225, 0.45,0.45,0.45")
    assert box == Box(center=(-0.5, 0.0, 0.225), size=(0.45, 0.45, 0.45), yaw=0.0)
    assert parse_obstacle("BOX:1,2,0.1,1,1,0.2,90").yaw == pytest.approx(math.pi / 2)


@pytest.mark.parametrize("text, match", [
    ("sphere:0,0,0,1", "not a box"),
    ("0,0,0,1,1,1", "not a box"),
    ("box:1,2,3", "3 numbers"),
    ("box:1,2,3,a,1,1", "not a number"),
    ("box:0,0,0.1,1,-1,0.2", "sizes must be positive"),
    ("box:0,0,nan,1,1,1", "finite"),
])
def test_malformed_obstacles_are_rejected_with_the_format(text, match):
    with pytest.raises(PhysposeError, match=match) as err:
        parse_obstacle(text)
    assert "box:x,y,z,sx,sy,sz" in str(err.value)


@pytest.mark.parametrize("change, match", [
    (dict(gravity=-9.81), "gravity -9.81 must be a positive magnitude"),
    (dict(gravity=float("nan")), "gravity nan"),
    (dict(obstacle_friction=-0.1), "obstacle friction -0.1 must be >= 0"),
    (dict(obstacles=Box(center=(0, 0, 0.2), size=(1, 1, 0.4))), "must be a tuple of Box"),
    (dict(obstacles=("box:0,0,0.2,1,1,0.4",)), "parse_obstacle"),
])
def test_impossible_scenes_are_refused_when_configured(change, match):
    # (gravity=-9.81 had pointed gravity up; a bare Box or a string had failed only when the
    # body was built, after the kinematic fit)
    with pytest.raises(PhysposeError, match=match):
        SceneConfig(**change)


def test_obstacles_as_a_list_are_kept_as_a_tuple():
    box = Box(center=(0, 0, 0.2), size=(1, 1, 0.4))
    assert SceneConfig(obstacles=[box]).obstacles == (box,)
    assert SceneConfig(obstacles=[]).obstacles == ()


def test_a_box_yaw_in_degrees_is_refused():
    with pytest.raises(PhysposeError, match=r"Box takes radians.*math.radians\(90\)"):
        Box(center=(0, 0, 0.2), size=(1, 1, 0.4), yaw=90.0)
    assert Box(center=(0, 0, 0.2), size=(1, 1, 0.4), yaw=-math.pi).yaw == -math.pi
    turns = parse_obstacle("box:0,0,0.2,1,1,0.4,450")  # degrees, any number of turns
    assert turns.yaw == pytest.approx(math.pi / 2)


def test_scene_settings_reach_the_model():
    box = Box(center=(1.0, -0.5, 0.1), size=(0.4, 0.6, 0.2), yaw=math.radians(30))
    scene = SceneConfig(ground_friction=0.4, obstacles=(box,)).with_ground(stiffness=900.0)
    m = build_body(SHAPES["short"], scene).model
    floor, obstacle = _geom(m, "floor"), _geom(m, "obstacle_0")
    assert m.geom_friction[floor, 0] == pytest.approx(0.4)
    assert np.allclose(m.geom_solref[floor], [-900.0, -60.0])  # critical damping 2 sqrt(k)
    assert np.allclose(m.geom_pos[obstacle], box.center)
    assert np.allclose(m.geom_size[obstacle], [0.2, 0.3, 0.1])
    assert np.allclose(m.geom_quat[obstacle], [math.cos(math.radians(15)), 0, 0,
                                               math.sin(math.radians(15))])
    assert m.geom_priority[floor] > m.geom_priority[_geom(m, "l_foot")]


def test_ground_stiffness_damping_forms_agree():
    default = SceneConfig()
    k, d = default.ground_stiffness_damping()
    assert d == pytest.approx(2 * math.sqrt(k), rel=0.06)  # dampratio 1 (dmax close to 1)
    # --ground-stiffness's help names these: the default floor and the earlier, softer one
    assert k == pytest.approx(1e4)
    assert SceneConfig(ground_solref=(0.02, 1.0)).ground_stiffness_damping()[0] == \
        pytest.approx(2500)
    direct = default.with_ground(stiffness=k, damping=d)
    assert direct.ground_stiffness_damping() == pytest.approx((k, d))
    with pytest.raises(PhysposeError, match="stiffness"):
        default.with_ground(stiffness=-1.0)
    with pytest.raises(PhysposeError, match="solref"):
        SceneConfig(ground_solref=(0.02, -1.0))


def _apex_after_landing(scene: SceneConfig) -> float:
    """Drop the standing body from 1 m; highest pelvis rise above standing after first landing."""
    body = build_body(SHAPES["tall"], scene)
    q = standing_qpos(body)
    start = q.copy()
    start[2] += 1.0
    traj, _ = simulate(body, start, 2.0)
    landed = int(np.argmin(traj[: int(1.0 / body.model.opt.timestep), 2]))
    return float(traj[landed:, 2].max() - q[2])


def test_trampoline_bounces_higher_than_the_floor():
    floor, bed = _apex_after_landing(SceneConfig()), _apex_after_landing(trampoline())
    assert floor < 0.05  # the hard floor does not throw the body back up
    assert bed > 0.3 and bed > floor + 0.25


@pytest.mark.parametrize("shape_name", sorted(SHAPES))
def test_body_sits_on_a_chair(shape_name):
    shape = SHAPES[shape_name]
    probe = build_body(shape)
    r_thigh = probe.model.geom_size[_geom(probe.model, "l_thigh"), 0]
    seat = shape.ankle_height + shape.shank - r_thigh - 0.01  # thighs level on the seat
    chair = Box(center=(0.05, 0.0, 0.5 * seat), size=(0.5, 0.5, seat))
    body = build_body(shape, SceneConfig(obstacles=(chair,)))
    q = standing_qpos(body)
    for side in "lr":
        q[dof(f"{side}_hip_y")] = -math.pi / 2
        q[dof(f"{side}_knee_y")] = math.pi / 2
        q[dof(f"{side}_shoulder_y")] = -0.5
        q[dof(f"{side}_elbow_y")] = -1.2
    q[2] = seat + r_thigh + 0.03  # lowered from 3 cm above the seat
    traj, data = simulate(body, q, 2.0)
    assert np.all(np.isfinite(traj))
    settled = traj[-100:]  # last 0.5 s
    assert np.all(settled[:, 2] > seat) and np.all(settled[:, 2] < seat + r_thigh + 0.03)
    assert np.ptp(settled[:, 2]) < 0.005  # resting, not sliding down
    assert np.abs(traj[-1, :2] - q[:2]).max() < 0.1
    chair_id = _geom(body.model, "obstacle_0")
    on_chair = {(c.geom1, c.geom2) for c in data.contact[: data.ncon]
                if chair_id in (c.geom1, c.geom2)}
    assert len(on_chair) >= 2  # both thighs (and the pelvis) bear on the seat
    assert data.xmat[body.body_ids["thorax"]].reshape(3, 3)[2, 2] > 0.9  # sitting upright


def _contact_stiffness_damping(scene: SceneConfig) -> tuple[float, float]:
    """MuJoCo's own stiffness and damping (efc_KBIP) of a ball resting on the scene's floor."""
    xml = f"""<mujoco><worldbody>
      <geom type="plane" size="5 5 .1" solref="{' '.join(map(str, scene.ground_solref))}"
            solimp="{' '.join(map(str, scene.ground_solimp))}" priority="1"/>
      <body pos="0 0 0.099"><freejoint/><geom type="sphere" size="0.1"/></body>
    </worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    return float(d.efc_KBIP[0, 0]), float(d.efc_KBIP[0, 1])


def test_a_floor_given_in_direct_form_is_the_same_floor():
    """ground_stiffness_damping's direct form makes MuJoCo's contact of the (timeconst,
    dampratio) form, and a friction alone leaves the floor as it was: it had made it 11 %
    stiffer and 5 % more damped (reconstruct --ground-friction)."""
    default = SceneConfig()
    k, d = default.ground_stiffness_damping()
    direct = default.with_ground(stiffness=k, damping=d)
    assert direct.ground_solref[0] < 0
    assert _contact_stiffness_damping(direct) == pytest.approx(
        _contact_stiffness_damping(default), rel=1e-9)
    slippery = default.with_ground(friction=0.3)
    assert slippery.ground_solref == default.ground_solref and slippery.ground_friction == 0.3
