"""Motion-capture readers: tiny synthetic files (parsers, FK, errors) and the real shared clips."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from physpose.errors import PhysposeError
from physpose.mocap import body_height, bone_lengths, load_mocap, stance_foot_heights
from physpose.mocap.asf_amc import (
    asf_forward_kinematics,
    find_asf,
    parse_amc,
    parse_asf,
)
from physpose.mocap.bvh import bvh_forward_kinematics, parse_bvh
from physpose.mocap.deepmimic import character_stature
from physpose.mocap.rotations import axis_rotation

# --- BVH ----------------------------------------------------------------------------------

def _bvh_leg(side: str, x: float) -> str:
    return f"""
  JOINT {side}UpLeg
  {{
    OFFSET {x} 0 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    JOINT {side}Leg
    {{
      OFFSET 0 -0.45 0
      CHANNELS 3 Zrotation Yrotation Xrotation
      JOINT {side}Foot
      {{
        OFFSET 0 -0.42 0
        CHANNELS 3 Zrotation Yrotation Xrotation
        JOINT {side}ToeBase
        {{
          OFFSET 0 -0.05 0.12
          CHANNELS 3 Zrotation Yrotation Xrotation
          End Site
          {{
            OFFSET 0 0 0.06
          }}
        }}
      }}
    }}
  }}"""


def _bvh_arm(side: str, x: float) -> str:
    return f"""
    JOINT {side}Arm
    {{
      OFFSET {x} 0.40 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      JOINT {side}ForeArm
      {{
        OFFSET 0 -0.28 0
        CHANNELS 3 Zrotation Xrotation Yrotation
        JOINT {side}Hand
        {{
          OFFSET 0 -0.25 0
          CHANNELS 3 Zrotation Xrotation Yrotation
          End Site
          {{
            OFFSET 0 -0.08 0
          }}
        }}
      }}
    }}"""


N_BVH_CHANNELS = 6 + 3 * 17  # root + 17 rotating joints


def write_bvh(path: Path, rows: list[list[float]], unit: float = 1.0) -> Path:
    """A 15-joint humanoid (metres x 1/unit, y up, facing +z) with the given motion rows."""
    text = f"""HIERARCHY
ROOT Hips
{{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\
{_bvh_leg("Left", 0.1)}{_bvh_leg("Right", -0.1)}
  JOINT Spine
  {{
    OFFSET 0 0.1 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    JOINT Neck
    {{
      OFFSET 0 0.45 0
      CHANNELS 3 Zrotation Yrotation Xrotation
      JOINT Head
      {{
        OFFSET 0 0.1 0
        CHANNELS 3 Zrotation Yrotation Xrotation
        End Site
        {{
          OFFSET 0 0.15 0
        }}
      }}
    }}{_bvh_arm("Left", 0.18)}{_bvh_arm("Right", -0.18)}
  }}
}}
MOTION
Frames: {len(rows)}
Frame Time: 0.1
"""
    if unit != 1.0:   # scale every OFFSET and the root position channels
        lines = []
        for line in text.splitlines():
            if line.strip().startswith("OFFSET"):
                vals = [float(v) / unit for v in line.split()[1:]]
                line = line[:line.index("OFFSET")] + "OFFSET " + " ".join(f"{v:.12g}" for v in vals)
            lines.append(line)
        text = "\n".join(lines) + "\n"
        rows = [[v / unit if k < 3 else v for k, v in enumerate(r)] for r in rows]
    text += "\n".join(" ".join(f"{v:.12g}" for v in r) for r in rows) + "\n"
    path.write_text(text)
    return path


def bvh_rows(n: int = 8) -> list[list[float]]:
    rows = [[0.0] * N_BVH_CHANNELS for _ in range(n)]
    for r in rows:
        r[:3] = [0.0, 0.95, 0.0]
    if n >= 3:
        rows[1][6 + 3 + 2] = 90.0   # LeftLeg Xrotation (channels: Z Y X): knee flexed 90 deg
        rows[2][4] = 90.0           # root Yrotation
    if n >= 4:
        rows[3][4] = rows[3][5] = 90.0   # root Yrotation and Xrotation: R = Ry(90) Rx(90)
    return rows


def test_bvh_forward_kinematics_by_hand(tmp_path):
    bvh = parse_bvh(write_bvh(tmp_path / "a.bvh", bvh_rows()))
    names = [n.name for n in bvh.nodes]
    assert names[:6] == ["Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase",
                         "LeftToeBase_end"]
    pos, _ = bvh_forward_kinematics(bvh)
    knee, ankle = names.index("LeftLeg"), names.index("LeftFoot")
    assert pos[0, knee] == pytest.approx([0.1, 0.5, 0.0])
    assert pos[0, ankle] == pytest.approx([0.1, 0.08, 0.0])
    assert pos[1, ankle] == pytest.approx([0.1, 0.5, -0.42])      # shin swings backwards
    assert pos[2, names.index("LeftUpLeg")] == pytest.approx([0.0, 0.95, -0.1])  # Ry(90) x
    assert pos[3, names.index("Spine")] == pytest.approx([0.1, 0.95, 0.0])  # Ry(90) Rx(90) y


def test_bvh_clip_is_z_up_on_the_floor_at_the_target_rate(tmp_path):
    clip = load_mocap(write_bvh(tmp_path / "a.bvh", bvh_rows(8)), target_fps=20.0)
    assert clip.fps == 20.0 and clip.source_fps == pytest.approx(10.0)
    assert clip.num_frames == 15                         # 0.7 s at 20 Hz, both ends included
    standing = clip.joints[-1]
    from physpose.joints import JOINT_INDEX as J
    assert standing[J["head"], 2] > standing[J["pelvis"], 2] > standing[J["l_knee"], 2]
    # Static frames 3..7 set the floor: heel and toe sole points at z = 0.
    assert clip.joint("l_heel")[-1, 2] == pytest.approx(0.0, abs=1e-9)
    assert clip.joint("r_toe")[-1, 2] == pytest.approx(0.0, abs=1e-9)
    # Facing +z in the file -> facing -y after the y-up to z-up turn; left hip at +x.
    assert clip.joint("l_toe")[-1, 1] < clip.joint("l_heel")[-1, 1]
    assert clip.joint("l_hip")[-1, 0] > clip.joint("r_hip")[-1, 0]
    # Head top at 0.95 + 0.8 m above the hips' origin, the sole 4.5 cm under the ball (y=0.03).
    assert body_height(clip) == pytest.approx(1.75 - (0.03 - 0.045), abs=1e-6)
    assert clip.head_rot[-1, :, 0] == pytest.approx([0.0, -1.0, 0.0], abs=1e-9)  # face forward
    native = load_mocap(tmp_path / "a.bvh", target_fps=None)
    for lengths in bone_lengths(native).values():
        assert np.ptp(lengths) < 1e-9


@pytest.mark.parametrize("unit", [0.01, 0.001, 0.0254, 0.0254 / 0.45])
def test_bvh_length_unit_is_guessed(tmp_path, unit):
    """Centimetres, millimetres, inches and CMU's units (1/0.45 inch, the cgspeed BVH
    conversion's) all read as the same person in metres."""
    metres = load_mocap(write_bvh(tmp_path / "m.bvh", bvh_rows()))
    other = load_mocap(write_bvh(tmp_path / "other.bvh", bvh_rows(), unit=unit))
    assert other.joints == pytest.approx(metres.joints, abs=1e-9)


def _smooth_rows(n: int, root_step: float = 0.01) -> list[list[float]]:
    """Walking-speed motion: the root moving along z, the left knee bending slowly."""
    rows = []
    for i in range(n):
        r = [0.0] * N_BVH_CHANNELS
        r[:3] = [1.0, 0.95, root_step * i]
        r[6 + 3 + 2] = 20.0 * np.sin(i / 5.0)   # LeftLeg Xrotation
        rows.append(r)
    return rows


@pytest.mark.parametrize("held", [1, 3])
def test_a_leading_rest_pose_is_dropped(tmp_path, held):
    """A rest pose (arms out, at the origin) put before the capture, as many exports do, is
    cut off: the clip is the capture alone."""
    capture = _smooth_rows(30)
    t_pose = [0.0] * N_BVH_CHANNELS
    t_pose[1] = 0.95
    t_pose[39], t_pose[48] = 90.0, -90.0   # LeftArm and RightArm Zrotation: arms out
    plain = load_mocap(write_bvh(tmp_path / "plain.bvh", capture))
    with_rest = load_mocap(write_bvh(tmp_path / "rest.bvh", [t_pose] * held + capture))
    assert with_rest.meta["leading_frames_dropped"] == held
    assert plain.meta["leading_frames_dropped"] == 0
    assert with_rest.joints == pytest.approx(plain.joints, abs=1e-9)


def test_a_fast_start_is_kept(tmp_path):
    """A motion as fast from its first frame as later (a sprint: 15 cm per frame) is no jump."""
    clip = load_mocap(write_bvh(tmp_path / "fast.bvh", _smooth_rows(30, root_step=0.15)))
    assert clip.meta["leading_frames_dropped"] == 0


# Other exporters' joint names for the test skeleton's joints (3ds Max Biped, MotionBuilder
# HumanIK with its character prefix).
_BIPED = {"Hips": "Bip01 Pelvis", "Spine": "Bip01 Spine", "Neck": "Bip01 Neck",
          "Head": "Bip01 Head"} | {
    f"{side}{part}": f"Bip01 {side[0]} {biped}" for side in ("Left", "Right")
    for part, biped in (("UpLeg", "Thigh"), ("Leg", "Calf"), ("Foot", "Foot"),
                        ("ToeBase", "Toe0"), ("Arm", "UpperArm"), ("ForeArm", "Forearm"),
                        ("Hand", "Hand"))}
_ROLL_BONE = """JOINT {name}
{{
  OFFSET 0 -0.2 0
  CHANNELS 0
  End Site
  {{
    OFFSET 0 -0.01 0
  }}
}}"""


def _renamed_bvh(path: Path, rename, roll_bones: bool = False) -> Path:
    """The test skeleton with every joint renamed; optionally a twist bone (no channels) as the
    first child of each knee and elbow, part-way down the shin or forearm."""
    parent_of = {"Foot": "Leg", "Hand": "ForeArm"}
    lines = []
    for line in write_bvh(path, bvh_rows()).read_text().splitlines():
        words = line.split()
        if words[:1] in (["ROOT"], ["JOINT"]):
            old = words[1]
            part = old.removeprefix("Left").removeprefix("Right")
            if roll_bones and part in parent_of:  # a sibling before the ankle or wrist
                limb = rename(old.removesuffix(part) + parent_of[part])
                lines.extend(_ROLL_BONE.format(name=limb + "Roll").splitlines())
            line = line.replace(old, rename(old))
        lines.append(line)
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("rename", [lambda n: _BIPED[n], lambda n: "Character1_" + n,
                                    lambda n: "mixamorig:" + n], ids=["biped", "humanik",
                                                                      "mixamo"])
@pytest.mark.parametrize("roll_bones", [False, True], ids=["plain", "roll-bones"])
def test_bvh_joint_names_of_other_exporters(tmp_path, rename, roll_bones):
    """Knees and elbows are found by name after an exporter's prefix, and a limb's next joint
    is the farthest child, not a twist bone: the same motion as the plain file."""
    plain = load_mocap(write_bvh(tmp_path / "plain.bvh", bvh_rows()))
    other = load_mocap(_renamed_bvh(tmp_path / "other.bvh", rename, roll_bones))
    assert other.joints == pytest.approx(plain.joints, abs=1e-9)


def test_a_prefix_does_not_make_a_thigh_a_knee(tmp_path):
    """'UpperLeg_L' ends like 'leg' + 'l'; where the knee has no known name either, the deeper
    of such joints is taken, which is the shin below the thigh."""
    names = {"LeftUpLeg": "UpperLeg_L", "LeftLeg": "LowLeg_L", "RightUpLeg": "UpperLeg_R",
             "RightLeg": "LowLeg_R"}
    plain = load_mocap(write_bvh(tmp_path / "plain.bvh", bvh_rows()))
    other = load_mocap(_renamed_bvh(tmp_path / "o.bvh", lambda n: names.get(n, n)))
    assert other.joints == pytest.approx(plain.joints, abs=1e-9)


def test_bvh_of_no_plausible_size_is_refused(tmp_path):
    with pytest.raises(PhysposeError, match="cannot tell the length unit.*rescale the file"):
        load_mocap(write_bvh(tmp_path / "tiny.bvh", bvh_rows(), unit=1000.0))


def test_bvh_errors_name_file_and_line(tmp_path):
    good = write_bvh(tmp_path / "a.bvh", bvh_rows(2)).read_text().splitlines()
    k = good.index("    OFFSET 0.1 0 0")   # LeftUpLeg's
    (tmp_path / "b.bvh").write_text("\n".join(good[:k] + good[k + 1:]))
    with pytest.raises(PhysposeError, match=r"b\.bvh: line \d+: joint 'LeftUpLeg' has no OFFSET"):
        load_mocap(tmp_path / "b.bvh")
    short_row = good[:-1] + [" ".join(good[-1].split()[:-1])]
    (tmp_path / "c.bvh").write_text("\n".join(short_row))
    with pytest.raises(PhysposeError, match=rf"line {len(good)}: expected {N_BVH_CHANNELS} numbers"):
        load_mocap(tmp_path / "c.bvh")
    (tmp_path / "d.bvh").write_text("\n".join(good[:-1]))
    with pytest.raises(PhysposeError, match="header says 2 frames but 1 motion rows"):
        load_mocap(tmp_path / "d.bvh")



@pytest.mark.parametrize("header, message", [
    ("Frames: nan", "must be a whole number"),
    ("Frames: 3.5", "must be a whole number"),
    ("Frame Time: inf", "a positive number of seconds"),
    ("Frame Time: 1000000", "frame rate 1e-06 Hz is outside"),
])
def test_bvh_header_of_no_usable_rate_is_refused(tmp_path, header, message):
    """A frame count or rate that cannot be right stops with the file named, before it could
    resample a million frames into memory."""
    text = write_bvh(tmp_path / "a.bvh", bvh_rows(4)).read_text()
    key = header.split(":")[0]
    old = next(line for line in text.splitlines() if line.startswith(key + ":"))
    (tmp_path / "b.bvh").write_text(text.replace(old, header))
    with pytest.raises(PhysposeError, match=message) as caught:
        load_mocap(tmp_path / "b.bvh")
    assert caught.value.path == str(tmp_path / "b.bvh")


def test_a_clip_under_two_frames_long_is_refused(tmp_path):
    rows = bvh_rows(2)
    path = write_bvh(tmp_path / "short.bvh", rows)
    path.write_text(path.read_text().replace("Frame Time: 0.1", "Frame Time: 0.008333"))
    with pytest.raises(PhysposeError, match="under two frames at 25 Hz"):
        load_mocap(path)


# --- ASF/AMC ------------------------------------------------------------------------------

def _asf_bone(i, name, direction, length, axis="0 0 0", dof="rx ry rz"):
    dof_line = f"    dof {dof}\n" if dof else ""
    return (f"  begin\n    id {i}\n    name {name}\n    direction {direction}\n"
            f"    length {length}\n    axis {axis} XYZ\n{dof_line}  end\n")


ASF_BONES = [
    ("lhipjoint", "1 -0.5 0", 2.0), ("lfemur", "0 -1 0", 8.0), ("ltibia", "0 -1 0", 7.5),
    ("lfoot", "0 -0.3 1", 2.0), ("ltoes", "0 0 1", 1.0),
    ("rhipjoint", "-1 -0.5 0", 2.0), ("rfemur", "0 -1 0", 8.0), ("rtibia", "0 -1 0", 7.5),
    ("rfoot", "0 -0.3 1", 2.0), ("rtoes", "0 0 1", 1.0),
    ("lowerback", "0 1 0", 8.0), ("head", "0 1 0", 2.5),
    ("lclavicle", "1 0.3 0", 3.0), ("lhumerus", "1 0 0", 5.0), ("lradius", "1 0 0", 4.5),
    ("lwrist", "1 0 0", 1.5), ("rclavicle", "-1 0.3 0", 3.0), ("rhumerus", "-1 0 0", 5.0),
    ("rradius", "-1 0 0", 4.5), ("rwrist", "-1 0 0", 1.5),
]
ASF_HIERARCHY = """  begin
    root lhipjoint rhipjoint lowerback
    lhipjoint lfemur
    lfemur ltibia
    ltibia lfoot
    lfoot ltoes
    rhipjoint rfemur
    rfemur rtibia
    rtibia rfoot
    rfoot rtoes
    lowerback head lclavicle rclavicle
    lclavicle lhumerus
    lhumerus lradius
    lradius lwrist
    rclavicle rhumerus
    rhumerus rradius
    rradius rwrist
  end
"""


def write_asf(path: Path) -> Path:
    bones = "".join(_asf_bone(i + 1, n, d, ln, axis="0 0 20" if n == "lfemur" else "0 0 0")
                    for i, (n, d, ln) in enumerate(ASF_BONES))
    path.write_text(":version 1.10\n:name test\n:units\n  mass 1.0\n  length 0.45\n  angle deg\n"
                    ":documentation\n  tiny test skeleton\n:root\n   order TX TY TZ RX RY RZ\n"
                    "   axis XYZ\n   position 0 0 0\n   orientation 0 0 0\n:bonedata\n"
                    f"{bones}:hierarchy\n{ASF_HIERARCHY}")
    return path


def write_amc(path: Path, n: int = 6, femur_rx: float = 0.0, tibia_rx: float = 0.0) -> Path:
    lines = ["#!OML:ASF test", ":FULLY-SPECIFIED", ":DEGREES"]
    for k in range(n):
        lines.append(str(k + 1))
        lines.append("root 0 17 0 0 0 0")
        for name, _, _ in ASF_BONES:
            if name == "lfemur":
                lines.append(f"lfemur {femur_rx} 0 0")
            elif name == "ltibia":
                lines.append(f"ltibia {tibia_rx} 0 0")
            else:
                lines.append(f"{name} 0 0 0")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_asf_forward_kinematics_by_hand(tmp_path):
    asf = parse_asf(write_asf(tmp_path / "s.asf"))
    unit = 0.0254 / 0.45
    assert asf.bones["lfemur"].length == pytest.approx(8.0 * unit)
    motion = parse_amc(write_amc(tmp_path / "s.amc", n=2, femur_rx=30.0, tibia_rx=90.0), asf)
    names, parents, pos, _ = asf_forward_kinematics(asf, motion)
    hip, knee, ankle = (names.index(n) for n in ("lfemur", "ltibia", "lfoot"))
    assert names[parents[knee]] == "lfemur"
    assert pos[0, 0] == pytest.approx([0.0, 17 * unit, 0.0])
    # femur: axis (0, 0, 20 deg) -> R = Rz(20) Rx(30) Rz(-20)
    r_femur = axis_rotation("z", np.deg2rad(20)) @ axis_rotation("x", np.deg2rad(30)) @ \
        axis_rotation("z", np.deg2rad(-20))
    expected_knee = pos[0, hip] + r_femur @ np.array([0.0, -8.0 * unit, 0.0])
    assert pos[0, knee] == pytest.approx(expected_knee)
    r_tibia = r_femur @ axis_rotation("x", np.deg2rad(90))
    assert pos[0, ankle] == pytest.approx(pos[0, knee] + r_tibia @ [0.0, -7.5 * unit, 0.0])
    assert np.linalg.norm(pos[0, ankle] - pos[0, knee]) == pytest.approx(7.5 * unit)


def test_amc_clip(tmp_path):
    write_asf(tmp_path / "walk.asf")
    clip = load_mocap(write_amc(tmp_path / "walk.amc", n=13), target_fps=25.0)
    assert clip.source_fps == pytest.approx(120.0)
    assert clip.num_frames == 3                          # 12 / 120 s = 0.1 s -> 0, 0.04, 0.08
    assert clip.joint("l_heel")[:, 2] == pytest.approx(0.0, abs=1e-9)
    unit = 0.0254 / 0.45
    leg = np.linalg.norm(clip.joint("l_hip") - clip.joint("l_knee"), axis=1)
    assert leg == pytest.approx(8.0 * unit)


def test_find_asf_rules(tmp_path):
    write_asf(tmp_path / "charleston.asf")
    amc = write_amc(tmp_path / "charleston1.amc", n=2)
    assert find_asf(amc) == tmp_path / "charleston.asf"          # take number stripped
    write_asf(tmp_path / "charleston1.asf")
    assert find_asf(amc) == tmp_path / "charleston1.asf"         # same stem first
    other = write_amc(tmp_path / "zombie.amc", n=2)
    with pytest.raises(PhysposeError, match="cannot tell which ASF.*name the .asf as the .amc"):
        find_asf(other)                                          # two candidates, none matches
    assert find_asf(other, tmp_path / "charleston.asf") == tmp_path / "charleston.asf"
    alone = tmp_path / "alone"
    alone.mkdir()
    write_asf(alone / "skel.asf")
    assert find_asf(write_amc(alone / "x.amc", n=2)) == alone / "skel.asf"


def test_asf_amc_errors_name_file_and_line(tmp_path):
    asf = write_asf(tmp_path / "s.asf")
    text = asf.read_text().replace("direction 0 -1 0\n    length 7.5",
                                   "direction 0 -1 0\n    length x")
    (tmp_path / "bad.asf").write_text(text)
    with pytest.raises(PhysposeError, match=r"bad\.asf: line \d+: 'x' is not a number"):
        parse_asf(tmp_path / "bad.asf")
    amc = write_amc(tmp_path / "s.amc", n=2)
    lines = amc.read_text().splitlines()
    lines[6] = lines[6] + " 5"
    (tmp_path / "s2.amc").write_text("\n".join(lines))
    with pytest.raises(PhysposeError, match=r"s2\.amc: line 7: bone '\w+' has 4 values"):
        load_mocap(tmp_path / "s2.amc", asf=asf)
    lines = amc.read_text().splitlines()
    lines[6] = lines[6].rsplit(" ", 1)[0] + " nan"
    (tmp_path / "s3.amc").write_text("\n".join(lines))
    with pytest.raises(PhysposeError, match=r"s3\.amc: line 7: bone '\w+' has a NaN or infinite"):
        load_mocap(tmp_path / "s3.amc", asf=asf)
    (tmp_path / "nameless.asf").write_text(asf.read_text().replace("name lfemur", "name"))
    with pytest.raises(PhysposeError, match=r"nameless\.asf: line \d+: name needs 1 value, got 0"):
        parse_asf(tmp_path / "nameless.asf")


# --- DeepMimic ----------------------------------------------------------------------------

DM_JOINTS = [  # name, type, parent, attach (x, y, z)
    ("root", "none", -1, (0, 0, 0)), ("chest", "spherical", 0, (0, 0.24, 0)),
    ("neck", "spherical", 1, (0, 0.22, 0)),
    ("right_hip", "spherical", 0, (0, 0, 0.085)), ("right_knee", "revolute", 3, (0, -0.42, 0)),
    ("right_ankle", "spherical", 4, (0, -0.41, 0)),
    ("right_shoulder", "spherical", 1, (0, 0.24, 0.18)),
    ("right_elbow", "revolute", 6, (0, -0.27, 0)), ("right_wrist", "fixed", 7, (0, -0.26, 0)),
    ("left_hip", "spherical", 0, (0, 0, -0.085)), ("left_knee", "revolute", 9, (0, -0.42, 0)),
    ("left_ankle", "spherical", 10, (0, -0.41, 0)),
    ("left_shoulder", "spherical", 1, (0, 0.24, -0.18)),
    ("left_elbow", "revolute", 12, (0, -0.27, 0)), ("left_wrist", "fixed", 13, (0, -0.26, 0)),
]


def write_deepmimic(folder: Path, frames: list[list[float]], name="humanoid3d_test.txt") -> Path:
    joints = [{"ID": k, "Name": n, "Type": t, "Parent": p, "AttachX": a[0], "AttachY": a[1],
               "AttachZ": a[2]} for k, (n, t, p, a) in enumerate(DM_JOINTS)]
    box = {"Shape": "box", "AttachX": 0.045, "AttachY": -0.0225, "AttachZ": 0,
           "Param0": 0.18, "Param1": 0.055, "Param2": 0.09}
    bodies = [{"ID": 2, "Shape": "sphere", "AttachX": 0, "AttachY": 0.175, "AttachZ": 0,
               "Param0": 0.2}, dict(box, ID=5), dict(box, ID=11)]
    (folder / "character_humanoid3d.txt").write_text(
        json.dumps({"Skeleton": {"Joints": joints}, "BodyDefs": bodies}))
    path = folder / name
    path.write_text(json.dumps({"Loop": "none", "Frames": frames}))
    return path


def dm_frame(dt=0.05, root_y=0.88, right_knee=0.0, root_quat=(1.0, 0, 0, 0)) -> list[float]:
    row = [dt, 0.0, root_y, 0.0, *root_quat]
    for _, t, _, _ in DM_JOINTS[1:]:
        row += {"spherical": [1.0, 0.0, 0.0, 0.0], "revolute": [0.0], "fixed": []}[t]
    row[8 + 4 + 4 + 4] = right_knee    # chest (4), neck (4), right hip (4), right knee
    return row


def test_deepmimic_clip_by_hand(tmp_path):
    turn = (np.cos(np.pi / 4), 0.0, np.sin(np.pi / 4), 0.0)   # w, x, y, z: 90 deg about +y
    frames = [dm_frame(), dm_frame(right_knee=-np.pi / 2), dm_frame(root_quat=turn),
              dm_frame(dt=0.0)]
    clip = load_mocap(write_deepmimic(tmp_path, frames), target_fps=None)
    assert clip.fps == pytest.approx(20.0) and clip.num_frames == 4
    # Zero pose: sole 0.05 under the ankle, root 0.88 above it -> head top 0.88+0.24+0.22+0.175+0.1
    stature = 0.05 + 0.41 + 0.42 + 0.24 + 0.22 + 0.175 + 0.1
    assert character_stature(tmp_path / "character_humanoid3d.txt") == pytest.approx(stature)
    assert clip.head_top[0, 2] == pytest.approx(stature)
    assert clip.joint("l_heel")[0] == pytest.approx([0.045 - 0.09, 0.085, 0.0])   # z-up: -z -> +y
    assert clip.joint("l_toe")[0] == pytest.approx([0.045 + 0.09, 0.085, 0.0])
    # Knee angle -90 deg (about +z, the character's right): the shin points backwards (-x).
    knee, ankle = clip.joint("r_knee")[1], clip.joint("r_ankle")[1]
    assert ankle - knee == pytest.approx([-0.41, 0.0, 0.0])
    assert clip.head_rot[0] == pytest.approx(np.eye(3))   # facing +x, left +y, up +z
    # Root turned 90 deg about the file's up axis: the left hip (file -z) goes to -x.
    assert clip.joint("l_hip")[2] - clip.joint("pelvis")[2] == pytest.approx([-0.085, 0, 0])


def test_deepmimic_errors(tmp_path):
    bad = write_deepmimic(tmp_path, [dm_frame(), dm_frame()[:-1]])
    with pytest.raises(PhysposeError, match=r"frame 1: Frames\[1\] has 43 values, the character"):
        load_mocap(bad)
    (tmp_path / "humanoid3d_broken.txt").write_text('{"Frames": [1, 2,\n')
    with pytest.raises(PhysposeError, match=r"humanoid3d_broken\.txt: line 2: not valid JSON"):
        load_mocap(tmp_path / "humanoid3d_broken.txt")
    (tmp_path / "humanoid3d_words.txt").write_text(json.dumps(
        {"Frames": [dm_frame(), ["fast"] + dm_frame()[1:]]}))
    with pytest.raises(PhysposeError, match=r"frame 1: Frames\[1\] holds something other"):
        load_mocap(tmp_path / "humanoid3d_words.txt")
    zero_turn = write_deepmimic(tmp_path, [dm_frame(), dm_frame(root_quat=(0, 0, 0, 0))],
                                name="humanoid3d_zero.txt")
    with pytest.raises(PhysposeError, match="not finite .*zero-length quaternion") as caught:
        load_mocap(zero_turn)
    assert caught.value.frame == 1
    (tmp_path / "humanoid3d_latin1.txt").write_bytes(b'{"Frames": [], "Loop": "\xe9"}')
    with pytest.raises(PhysposeError, match="not a UTF-8 JSON file"):
        load_mocap(tmp_path / "humanoid3d_latin1.txt")
    character = tmp_path / "character_humanoid3d.txt"
    doc = json.loads(character.read_text())
    del doc["Skeleton"]["Joints"][4]["Type"]
    character.write_text(json.dumps(doc))
    with pytest.raises(PhysposeError, match=r"Skeleton/Joints\[4\] needs the numbers"):
        load_mocap(zero_turn)


def test_unknown_extension(tmp_path):
    (tmp_path / "x.c3d").write_bytes(b"\0")
    with pytest.raises(PhysposeError, match="unknown motion-capture format"):
        load_mocap(tmp_path / "x.c3d")


# --- The real clips in ../shared/data/mocap -----------------------------------------------

REAL_CLIPS = {  # file -> (frames at the source rate, source rate, height range m)
    # CMU 131 via the cgspeed BVH conversion: its trunk lacks CMU's thorax bone (lowerneck has
    # a zero offset from Chest2), so the head top sits ~12 cm low: 1.44-1.46 m measured.
    "cmu_bvh/scaled_131_01.bvh": (995, 120.0, (1.40, 1.55)),
    "cmu_bvh/scaled_131_02.bvh": (1248, 120.0, (1.40, 1.55)),
    "cmu_bvh/scaled_131_03.bvh": (1248, 120.0, (1.40, 1.55)),
    "cmu_amc/charleston1.amc": (506, 120.0, (1.5, 2.0)),
    "cmu_amc/charleston2.amc": (546, 120.0, (1.5, 2.0)),
    "cmu_amc/zombie.amc": (1558, 120.0, (1.5, 2.0)),
    # DeepMimic humanoid3d: the character is 1.62 m tall (zero pose); crouched or airborne
    # motions measure 1.50-1.65 m.
    **{f"deepmimic/humanoid3d_{n}.txt": (f, r, (1.45, 1.70)) for n, f, r in (
        ("walk", 39, 30.0), ("run", 25, 30.0), ("jog", 26, 30.0), ("jump", 107, 60.0),
        ("cartwheel", 164, 60.0), ("dance_a", 98, 60.0), ("kick", 47, 30.0),
        ("punch", 65, 30.0), ("roll", 121, 60.0))},
}


def test_real_cmu_bvh_in_cmu_units(shared_data, tmp_path):
    """The cgspeed conversion of the CMU database writes BVH in CMU's units (1/0.45 inch);
    scaled_131_01.bvh is that file in metres. Written back in CMU units it reads the same."""
    unit = 0.0254 / 0.45
    text = (shared_data / "mocap" / "cmu_bvh" / "scaled_131_01.bvh").read_text().splitlines()
    start = text.index("MOTION") + 3
    out = []
    for k, line in enumerate(text):
        words = line.split()
        if words[:1] == ["OFFSET"]:
            line = "OFFSET " + " ".join(f"{float(v) / unit:.9g}" for v in words[1:])
        elif k >= start and words:
            line = " ".join([f"{float(v) / unit:.9g}" for v in words[:3]] + words[3:])
        out.append(line)
    (tmp_path / "131_01.bvh").write_text("\n".join(out) + "\n")
    metres = load_mocap(shared_data / "mocap" / "cmu_bvh" / "scaled_131_01.bvh")
    cmu = load_mocap(tmp_path / "131_01.bvh")
    assert cmu.joints == pytest.approx(metres.joints, abs=1e-5)


@pytest.mark.parametrize("rel", sorted(REAL_CLIPS))
def test_real_clip(shared_data, rel):
    frames, rate, (lo, hi) = REAL_CLIPS[rel]
    native = load_mocap(shared_data / "mocap" / rel, target_fps=None)
    assert native.meta["source_frames"] == frames
    assert native.fps == pytest.approx(rate, rel=1e-3)
    # Rigid segments keep their length; roll has one double-length frame, so even its native
    # rate is resampled from there on (interpolation shortens chords).
    tolerance = 0.01 if "roll" in rel else 1e-6
    for name, lengths in bone_lengths(native).items():
        assert np.ptp(lengths) < tolerance, name
    clip = load_mocap(shared_data / "mocap" / rel)
    duration = native.meta["source_duration"]
    assert clip.fps == 25.0 and clip.num_frames == int(np.floor(duration * 25 + 1e-6)) + 1
    assert lo <= body_height(clip) <= hi
    for name, lengths in bone_lengths(clip).items():    # linear resampling shortens chords a bit
        assert lengths.std() < 0.01 * lengths.mean(), name
    stance = stance_foot_heights(native)
    if len(stance) >= 10:   # feet on the floor while they stand still
        assert abs(np.median(stance)) < 0.01
        assert np.percentile(np.abs(stance), 90) < 0.05
    assert clip.joint("head")[:, 2].mean() > clip.joint("pelvis")[:, 2].mean()


def test_deepmimic_character_scale(shared_data):
    stature = character_stature(shared_data / "mocap" / "deepmimic" / "character_humanoid3d.txt")
    assert stature == pytest.approx(1.619, abs=0.002)
