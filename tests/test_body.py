"""The simulated body over shapes and scenes: naming, mass, actuation, standing, dropping."""

from __future__ import annotations

import itertools

import mujoco
import numpy as np
import pytest
from body_fixtures import SCENES, SHAPES, dof, simulate, standing

from physpose.body import (EXCLUDED_PAIRS, SEGMENT_MASS_PERCENT, BodyConfig, self_contacts,
                           build_body, segment_masses, standing_qpos)
from physpose.errors import PhysposeError
from physpose.skeleton import DOF_NAMES, SEGMENT_NAMES, SEGMENTS

CASES = list(itertools.product(sorted(SHAPES), sorted(SCENES)))
_OBJ = mujoco.mjtObj
_OBJECTS = {"body": (_OBJ.mjOBJ_BODY, "nbody"), "joint": (_OBJ.mjOBJ_JOINT, "njnt"),
            "geom": (_OBJ.mjOBJ_GEOM, "ngeom"), "site": (_OBJ.mjOBJ_SITE, "nsite"),
            "actuator": (_OBJ.mjOBJ_ACTUATOR, "nu")}


def _upright(body, data) -> float:
    """z component of the thorax's up axis (1 = upright)."""
    return float(data.xmat[body.body_ids["thorax"]].reshape(3, 3)[2, 2])


@pytest.mark.parametrize("shape_name, scene_name", CASES)
def test_compiles_with_every_element_named(shape_name, scene_name):
    body = build_body(SHAPES[shape_name], SCENES[scene_name])
    m = body.model
    for kind, (obj, count) in _OBJECTS.items():
        start = 1 if kind == "body" else 0  # body 0 is MuJoCo's world
        names = [mujoco.mj_id2name(m, obj, i) for i in range(start, getattr(m, count))]
        assert all(names), f"unnamed {kind}"
        assert len(set(names)) == len(names), f"duplicate {kind} names"
    assert m.nq == 55 and m.nv == 54 and m.nu == 48
    assert m.opt.timestep == 0.005 and m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert m.ngeom == 1 + len(SCENES[scene_name].obstacles) + 18  # floor + boxes + body geoms


@pytest.mark.parametrize("shape_name", sorted(SHAPES))
def test_masses_positive_and_sum_to_the_total(shape_name):
    shape = SHAPES[shape_name]
    body = build_body(shape)
    masses = body.model.body_mass[1:]
    assert np.all(masses > 0) and len(masses) == len(SEGMENT_NAMES)
    assert masses.sum() == pytest.approx(shape.mass, rel=1e-9)
    assert body.total_mass == pytest.approx(shape.mass, rel=1e-9)
    assert np.all(body.model.body_inertia[1:] > 0)
    # Each anatomical group gets its share of the table (de Leva 1996).
    table = SEGMENT_MASS_PERCENT[shape.sex]
    by_group: dict[str, float] = {}
    for seg in SEGMENTS:
        key = seg.mass_group + ("_l" if seg.name.startswith("l_") else "")
        by_group[key] = by_group.get(key, 0.0) + body.segment_masses[seg.name]
    scale = shape.mass / 100.0
    assert by_group["thigh_l"] == pytest.approx(table["thigh"] * scale, rel=1e-2)
    assert by_group["head"] == pytest.approx(table["head"] * scale, rel=1e-2)
    assert segment_masses(shape) == body.segment_masses


def test_root_is_unactuated_and_each_servo_drives_its_hinge():
    body = build_body(SHAPES["tall"])
    m = body.model
    root = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "root")
    assert m.jnt_type[root] == mujoco.mjtJoint.mjJNT_FREE
    assert root not in m.actuator_trnid[:, 0]
    for k, name in enumerate(DOF_NAMES):
        j = m.actuator_trnid[k, 0]
        assert mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) == name
        assert m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE and m.jnt_limited[j]
    assert np.all(body.kp > 0) and np.all(body.kv > 0)
    assert np.allclose(m.actuator_forcerange[:, 1], body.torque_limit)
    assert body.torque_limit[DOF_NAMES.index("l_hip_y")] > \
        body.torque_limit[DOF_NAMES.index("l_knee_y")] > \
        body.torque_limit[DOF_NAMES.index("l_elbow_y")] > \
        body.torque_limit[DOF_NAMES.index("l_wrist_y")]
    assert np.array_equal(body.qpos_adr, np.arange(7, 55))
    assert np.array_equal(body.qvel_adr, np.arange(6, 54))


@pytest.mark.parametrize("shape_name", sorted(SHAPES))
def test_standing_pose_has_feet_on_the_ground_and_no_self_contact(shape_name):
    body, q = standing(shape_name)
    data = mujoco.MjData(body.model)
    data.qpos[:] = q
    mujoco.mj_forward(body.model, data)
    assert self_contacts(body.model, data) == []
    feet = [body.foot_geom_ids["l"], body.foot_geom_ids["r"]]
    lowest = [float(np.min(data.geom_xpos[g][2] - np.abs(
        data.geom_xmat[g].reshape(3, 3)[2]) @ body.model.geom_size[g])) for g in feet]
    assert lowest == pytest.approx([0.0, 0.0], abs=1e-9)
    key = body.model.key("standing")
    assert np.allclose(key.qpos, q) and np.allclose(key.ctrl, q[7:])


# A rigid statue cannot balance on the springy trampoline bed (it rocks and tips, as a person
# would without balance control), so standing is checked on the firm scenes.
@pytest.mark.parametrize("shape_name, scene_name",
                         [c for c in CASES if c[1] != "trampoline"])
def test_servos_hold_the_standing_pose_for_5_seconds(shape_name, scene_name):
    body, q = standing(shape_name, scene_name)
    traj, data = simulate(body, q, 5.0)
    assert np.all(np.isfinite(traj))
    assert traj[:, 2].min() > q[2] - 0.01  # the pelvis does not sink
    assert np.abs(traj[:, :2] - q[:2]).max() < 0.1  # nor wander
    assert _upright(body, data) > 0.97
    assert np.abs(traj[-1, 7:] - q[7:]).max() < 0.15  # joints near their targets


@pytest.mark.parametrize("shape_name, scene_name", CASES)
def test_dropped_from_1_m_gives_finite_states(shape_name, scene_name):
    body, q = standing(shape_name, scene_name)
    q = q.copy()
    q[2] += 1.0
    traj, data = simulate(body, q, 2.0)
    assert np.all(np.isfinite(traj)) and np.all(np.isfinite(data.qvel))
    assert traj[:, 2].min() > 0.0  # the pelvis never goes through the floor


def test_same_inputs_give_bit_identical_trajectories():
    runs = []
    for _ in range(2):
        body, q = standing("light", "chair")
        data = mujoco.MjData(body.model)
        data.qpos[:] = q
        data.qpos[2] += 0.3
        out = []
        for t in range(300):
            if t % 20 == 0:
                data.ctrl[:] = q[7:] + 0.3 * np.random.default_rng(t).standard_normal(48)
            mujoco.mj_step(body.model, data)
            out.append(data.qpos.copy())
        runs.append(np.array(out))
    assert np.array_equal(runs[0], runs[1])
    assert np.abs(runs[0][-1] - runs[0][0]).max() > 0.05  # it did move


def test_xml_round_trip():
    body = build_body(SHAPES["heavy"], SCENES["step"])
    again = mujoco.MjModel.from_xml_string(body.xml)
    assert (again.nq, again.nu, again.ngeom, again.nsite, again.nkey) == \
        (body.model.nq, body.model.nu, body.model.ngeom, body.model.nsite, 1)
    assert np.allclose(again.body_mass, body.model.body_mass, rtol=1e-5)
    assert np.allclose(again.actuator_biasprm, body.model.actuator_biasprm, rtol=1e-5)


def test_self_collision_between_non_adjacent_segments():
    body = build_body(SHAPES["tall"])
    m = body.model
    data = mujoco.MjData(m)
    q = standing_qpos(body)
    q[dof("l_hip_x")] = -0.5  # left leg adducted across the right one
    data.qpos[:] = q
    mujoco.mj_forward(m, data)
    assert ("l_thigh", "r_thigh") in self_contacts(m, data) or \
        ("r_thigh", "l_thigh") in self_contacts(m, data)
    off = build_body(SHAPES["tall"], config=BodyConfig(self_collision=False))
    data2 = mujoco.MjData(off.model)
    data2.qpos[:] = q
    mujoco.mj_forward(off.model, data2)
    assert self_contacts(off.model, data2) == []
    assert len(EXCLUDED_PAIRS) == m.nexclude


def test_bad_body_config_is_a_physpose_error():
    with pytest.raises(PhysposeError, match="timestep"):
        BodyConfig(timestep=0.0)


@pytest.mark.parametrize("shape_name", sorted(SHAPES))
def test_violent_servo_targets_stay_stable(shape_name):
    """Random targets 0.8 rad off, switched every 50 ms, while falling 1 m (CMA-ES samples):
    MuJoCo reports no instability and hinge rates stay bounded."""
    body, q = standing(shape_name)
    data = mujoco.MjData(body.model)
    data.qpos[:] = q
    data.qpos[2] += 1.0
    rng = np.random.default_rng(1)
    fastest = 0.0
    for t in range(600):
        if t % 10 == 0:
            data.ctrl[:] = q[7:] + rng.normal(0.0, 0.8, 48)
        mujoco.mj_step(body.model, data)
        fastest = max(fastest, float(np.abs(data.qvel[6:]).max()))
    assert data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number == 0
    assert fastest < 100.0  # rad/s
