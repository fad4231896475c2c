"""BVH export: the file read back by physpose.mocap's BVH reader gives the body back."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from physpose.errors import PhysposeError
from physpose.export import export
from physpose.export.bvh import R_WORLD2BVH, write_bvh
from physpose.mocap.bvh import bvh_forward_kinematics, parse_bvh
from physpose.render.bodymotion import body_motion, reconstruction_motion
from synthetic_result import make_reconstruction, save_result, tiny_humanoid_mjcf, walking_qpos


def _positions_by_name(path, names):
    clip = parse_bvh(path)
    pos = bvh_forward_kinematics(clip)[0] @ R_WORLD2BVH  # back to world axes (z up)
    return pos[:, [_names(clip).index(n) for n in names]], clip


def _names(clip) -> list[str]:
    """Every node's name; the reader adds each End Site as a node named <parent>_end."""
    return [node.name for node in clip.nodes]


def _joints(clip) -> list:
    """The BVH joints proper (End Sites, which have no channels, left out)."""
    return [node for node in clip.nodes if node.channels]


def test_round_trip_matches_body_positions_within_a_millimetre(tmp_path):
    rec = make_reconstruction(num_frames=40)
    motion = reconstruction_motion(rec, "physics")
    path = write_bvh(motion, rec.fps, tmp_path / "m.bvh")
    pos, clip = _positions_by_name(path, motion.tree.names)
    assert np.abs(pos - motion.pos).max() < 1e-3
    assert clip.motion.shape == (40, 6 + 3 * (len(motion.tree.names) - 1))
    assert clip.frame_time == pytest.approx(1 / rec.fps)
    # The offsets are the subject's segment lengths: thigh -> shin is 0.42 m in the model.
    shin = clip.nodes[_names(clip).index("l_shin")]
    assert np.linalg.norm(shin.offset) == pytest.approx(0.42, abs=1e-6)
    ends = {clip.nodes[node.parent].name for node in clip.nodes if not node.channels}
    assert ends == {"head", "l_forearm", "r_forearm", "l_foot", "r_foot"}


def test_joint_sites_follow_from_the_bvh_bodies(tmp_path):
    """A joint fixed on a body (the knee site) is recovered from that body's BVH pose."""
    rec = make_reconstruction(num_frames=12)
    motion = reconstruction_motion(rec, "physics")
    path = write_bvh(motion, rec.fps, tmp_path / "m.bvh")
    # Knee site sits at the shin origin, wrist 0.26 m below the forearm origin.
    pos, clip = _positions_by_name(path, ("l_shin",))
    knee = rec.joint_names.index("l_knee")
    assert np.abs(pos[:, 0] - rec.joints_physics[:, knee]).max() < 1e-3
    assert clip.nodes[0].name == "pelvis"
    assert clip.nodes[0].channels[:3] == ("xposition", "yposition", "zposition")


def test_offset_hinge_gets_position_channels(tmp_path):
    """A hinge away from its body's origin moves the body: the BVH carries that translation."""
    spec = mujoco.MjSpec()
    root = spec.worldbody.add_body(name="root", pos=[0, 0, 1])
    root.add_freejoint(name="free")
    root.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.1, 0.1, 0.1])
    arm = root.add_body(name="arm", pos=[0.3, 0, 0])
    arm.add_joint(name="swing", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 1, 0], pos=[-0.2, 0, 0])
    arm.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[0, 0, 0, 0.3, 0, 0], size=[0.03, 0, 0])
    model = spec.compile()
    qpos = walking_qpos(model, 20)
    motion = body_motion(spec.to_xml(), qpos)
    path = write_bvh(motion, 25.0, tmp_path / "arm.bvh")
    pos, clip = _positions_by_name(path, ("root", "arm"))
    assert len(clip.nodes[_names(clip).index("arm")].channels) == 6
    assert np.abs(pos - motion.pos).max() < 1e-3


def test_export_uses_kinematic_qpos_when_there_is_no_physics(tmp_path):
    folder = save_result(tmp_path, physics=False)
    path = export(folder, "bvh")
    assert path == folder / "motion.bvh"
    rec = make_reconstruction(physics=False)
    expected = body_motion(tiny_humanoid_mjcf(), rec.qpos_kinematic).pos
    pos, _ = _positions_by_name(path, ("pelvis", "l_foot"))
    assert np.abs(pos - expected[:, [0, 9]]).max() < 1e-3


def test_export_without_a_body_model_is_a_clear_error(tmp_path):
    folder = save_result(tmp_path, physics=False, qpos_kinematic=False)
    with pytest.raises(PhysposeError, match="no body model"):
        export(folder, "bvh")
    with pytest.raises(PhysposeError, match="no physics motion"):
        export(save_result(tmp_path / "b", physics=False), "bvh", motion="physics")


def test_malformed_bvh_is_reported(tmp_path):
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 3 Xrotation Yrotation Zrotation\n"
                   "}\nMOTION\nFrames: 2\nFrame Time: 0.04\n1 2 3\n")
    with pytest.raises(PhysposeError, match="header says 2 frames but 1 motion rows"):
        parse_bvh(bad)


def test_real_body_round_trips_through_bvh_and_glb(tmp_path):
    """physpose.body's 48-hinge model: BVH and glTF both give its body positions back."""
    from physpose.body import build_body, standing_qpos
    from physpose.export.gltf import read_glb, write_glb
    from physpose.shape import BodyShape
    from test_export_gltf import animated_world_positions, structural_problems

    body = build_body(BodyShape.from_height(1.7))
    t = np.arange(15) / 25.0
    qpos = np.tile(standing_qpos(body), (len(t), 1))
    qpos[:, 0] += 1.1 * t
    qpos[:, body.qpos_adr] += 0.3 * np.sin(3 * t[:, None] + np.arange(len(body.qpos_adr)))
    motion = body_motion(body.xml, qpos)
    assert len(motion.tree.names) == 17 and {"l_foot", "r_foot"} <= {
        g.name for g in motion.tree.geoms if g.kind == "box"}
    pos, clip = _positions_by_name(write_bvh(motion, 25.0, tmp_path / "b.bvh"), motion.tree.names)
    assert np.abs(pos - motion.pos).max() < 1e-3
    assert sum(len(node.channels) for node in clip.nodes) == 6 + 3 * (len(_joints(clip)) - 1)
    glb = write_glb(motion, 25.0, tmp_path / "b.glb")
    assert structural_problems(glb) == []
    doc, blob = read_glb(glb)
    nodes, index = animated_world_positions(doc, blob)
    y_up_to_z_up = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    back = nodes[:, [index[n] for n in motion.tree.names]] @ y_up_to_z_up.T
    assert np.abs(back - motion.pos).max() < 1e-3


def test_euler_channels_do_not_flip_through_gimbal_lock():
    """An arm raised through the horizontal (the ZXY middle angle passing 90 degrees) while it
    twists: principal Euler values jump by about 180 degrees between neighbouring frames there,
    which sends an interpolating tool's limb round the flip. The written channels step by at
    most a few degrees and still give every frame's rotation."""
    from scipy.spatial.transform import Rotation

    from physpose.export.bvh import continuous_euler
    t = np.linspace(0.0, 1.0, 60)
    truth = Rotation.from_euler("ZXY", np.stack([40 * t - 10, 60 + 60 * t, 30 * np.sin(6 * t)],
                                                axis=1), degrees=True)
    principal = truth.as_euler("ZXY", degrees=True)
    assert np.abs(np.diff(principal, axis=0)).max() > 150        # the flip is there to mend
    channels = continuous_euler(principal)
    assert np.abs(np.diff(channels, axis=0)).max() < 10
    back = Rotation.from_euler("ZXY", channels, degrees=True)
    assert np.degrees((back * truth.inv()).magnitude()).max() < 1e-6
    # Whole turns are taken out as before (a root yawing round and round).
    spin = np.stack([np.linspace(0, 1080, 50), np.zeros(50), np.zeros(50)], axis=1)
    wrapped = Rotation.from_euler("ZXY", spin, degrees=True).as_euler("ZXY", degrees=True)
    assert np.allclose(continuous_euler(wrapped), spin, atol=1e-6)
