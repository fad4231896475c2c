"""BodyShape: proportions from height, measured bones, silhouette widths, and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from physpose.errors import PhysposeError
from physpose.fk import fk
from physpose.shape import (BodyShape, bone_lengths_from_landmarks, mass_from_height,
                            stature_from_bones)
from physpose.skeleton import BONE_NAMES, DOF_LIMITS


@pytest.mark.parametrize("height", [0.5, 1.5, 1.75, 1.95, 2.5])
def test_from_height_stature_and_default_mass(height):
    s = BodyShape.from_height(height, mass=70.0 if height < 1 else None)
    assert stature_from_bones(s.bones()) == pytest.approx(height)
    if height >= 1:
        assert s.mass == pytest.approx(22.0 * height ** 2) and s.bmi == pytest.approx(22.0)


def test_build_changes_mass_and_radii_not_lengths():
    slim, heavy = (BodyShape.from_height(1.75, build=b) for b in ("slim", "heavy"))
    assert heavy.mass > slim.mass
    assert heavy.r_thigh > slim.r_thigh and heavy.r_chest > slim.r_chest
    assert np.array_equal(heavy.bones(), slim.bones())
    assert mass_from_height(1.75, "heavy") == pytest.approx(30 * 1.75 ** 2)


def test_from_bone_lengths_round_trip_and_fill():
    ref = BodyShape.from_height(1.68, mass=61.0)
    again = BodyShape.from_bone_lengths(ref.bones(), mass=61.0)
    assert again.height == pytest.approx(1.68)
    assert np.allclose(again.bones(), ref.bones())
    assert BodyShape.from_bone_lengths(dict(zip(BONE_NAMES, ref.bones()))) .height == \
        pytest.approx(1.68)
    longer = BodyShape.from_bone_lengths({"thigh": ref.thigh + 0.05, "shank": ref.shank})
    assert longer.thigh == pytest.approx(ref.thigh + 0.05)
    assert longer.height > 1.68  # the stature follows the measured thigh


def test_segment_widths_set_radii():
    s = BodyShape.from_height(1.75).with_segment_widths({"thigh": 0.16, "upper_arm": 0.09})
    assert s.r_thigh == pytest.approx(0.08) and s.radius("upper_arm") == pytest.approx(0.045)
    with pytest.raises(PhysposeError, match="unknown segment widths"):
        s.with_segment_widths({"tail": 0.1})
    with pytest.raises(PhysposeError, match="r_thigh"):
        s.with_segment_widths({"thigh": -0.1})


@pytest.mark.parametrize("call, match", [
    (lambda: BodyShape.from_height(3.0), "height 3.0 m is outside"),
    (lambda: BodyShape.from_height(1.7, mass=10.0), "mass 10.0 kg is outside"),
    (lambda: BodyShape.from_height(0.6), "give the body mass explicitly"),
    (lambda: BodyShape.from_height(1.7, build="round"), "unknown build"),
    (lambda: BodyShape.from_height(1.7, sex="x"), "unknown sex"),
    (lambda: BodyShape.from_bone_lengths({"tail": 1.0}), "unknown bone names"),
    (lambda: BodyShape.from_bone_lengths(np.ones(3)), "shape"),
    (lambda: BodyShape.from_bone_lengths({"thigh": -0.4}), "positive"),
])
def test_bad_input_is_a_physpose_error(call, match):
    with pytest.raises(PhysposeError, match=match):
        call()


def test_bone_lengths_measured_on_posed_landmarks():
    truth = BodyShape.from_height(1.83, mass=77.0)
    rng = np.random.default_rng(7)
    angles = rng.uniform(DOF_LIMITS[:, 0], DOF_LIMITS[:, 1], size=(6, 48))
    quat = rng.normal(size=(6, 4))
    _, landmarks = fk(truth.bones(), rng.normal(size=(6, 3)), quat, angles)
    landmarks = np.concatenate([landmarks, np.zeros((1, 33, 3))])  # an undetected frame
    measured = bone_lengths_from_landmarks(landmarks)
    # Trunk and neck lengths bend with the spine and neck joints: exact only when straight.
    for name in BONE_NAMES:
        if name not in ("trunk", "neck"):
            assert measured[name] == pytest.approx(getattr(truth, name), rel=1e-9), name
    rest = fk(truth.bones(), np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(48))[1]
    again = BodyShape.from_bone_lengths(bone_lengths_from_landmarks(rest), mass=77.0)
    assert np.allclose(again.bones(), truth.bones()) and again.height == pytest.approx(1.83)
    with pytest.raises(PhysposeError, match="no valid frame"):
        bone_lengths_from_landmarks(np.zeros((2, 33, 3)))
