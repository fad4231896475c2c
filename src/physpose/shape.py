"""The person's body shape: bone lengths, limb radii, box sizes, height and mass.

Proportions of an average adult as fractions of stature, after Drillis & Contini (1966) as
tabulated in Winter, "Biomechanics and Motor Control of Human Movement" (4th ed., 2009,
fig. 4.1): hip joint at 0.530 H, knee 0.285 H, ankle 0.039 H, shoulder 0.818 H (acromion),
elbow 0.630 H, wrist 0.485 H, eye 0.936 H, foot length 0.152 H, foot breadth 0.055 H, hand
0.108 H. Joint-centre distances (hips, shoulders) are narrower than the bony widths
(bitrochanteric 0.191 H, biacromial 0.259 H). Radii are those of a 1.75 m adult of BMI 22,
scaled by H / 1.75 and sqrt(BMI / 22), BMI clipped to 15-40 for the geometry.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from physpose.errors import PhysposeError
from physpose.joints import LANDMARK_NAMES
from physpose.skeleton import BONE_NAMES, FOOT_LANDMARK_Z

HEIGHT_RANGE = (0.5, 2.5)  # m, accepted statures
MASS_RANGE = (20.0, 300.0)  # kg, accepted masses
BUILD_BMI: dict[str, float] = {"slim": 19.0, "average": 22.0, "athletic": 25.0, "heavy": 30.0}
SEXES = ("neutral", "male", "female")

# Bone lengths as fractions of stature (see module docstring).
_BONE_FRACTION: dict[str, float] = {
    "hip_width": 0.100, "trunk": 0.265, "shoulder_width": 0.200, "neck": 0.130,
    "ear_width": 0.085, "upper_arm": 0.172, "forearm": 0.146, "hand": 0.052,
    "thigh": 0.245, "shank": 0.246, "ankle_height": 0.039, "foot_length": 0.145,
    "heel_back": 0.035,
}
# Vertex of the head above the ear canals (0.075 H, so the standing chain sums to H), per ear
# width.
HEAD_TOP_PER_EAR_WIDTH = (1.0 - sum(_BONE_FRACTION[n] for n in (
    "ankle_height", "shank", "thigh", "trunk", "neck"))) / _BONE_FRACTION["ear_width"]

RADIUS_NAMES: tuple[str, ...] = (
    "pelvis", "abdomen", "chest", "upper_chest", "neck", "head",
    "upper_arm", "forearm", "thigh", "shank",
)
# Capsule radii (m) of the reference body (1.75 m, BMI 22).
_REFERENCE_RADIUS: dict[str, float] = {
    "pelvis": 0.085, "abdomen": 0.100, "chest": 0.110, "upper_chest": 0.080, "neck": 0.050,
    "head": 0.085, "upper_arm": 0.045, "forearm": 0.037, "thigh": 0.070, "shank": 0.050,
}
_REFERENCE_HEIGHT = 1.75  # m
_REFERENCE_BMI = 22.0  # kg/m^2
_GEOMETRY_BMI_RANGE = (15.0, 40.0)  # kg/m^2, BMI range over which radii follow the mass
# Box sizes relative to the bones: hand length per wrist-to-index distance; widths per stature.
_HAND_LENGTH_PER_HAND = 2.1
_HAND_WIDTH = 0.048     # x H (palm breadth ~ 0.085 m at 1.75 m)
_HAND_THICKNESS = 0.017  # x H
_FOOT_WIDTH = 0.055     # x H (Drillis & Contini foot breadth)
_FOOT_HEIGHT_PER_ANKLE = 0.8  # box height per ankle height


@dataclass(frozen=True)
class BodyShape:
    """Everything that sizes the body, SI units. Bone names follow skeleton.BONE_NAMES.

    Capsule radii are named after RADIUS_NAMES with an ``r_`` prefix; boxes are the hands
    (length along the forearm, width fore-aft, thickness medio-lateral) and the feet (length
    = foot_length heel to toe, width, height). ``sex`` picks the segment-mass table column.
    """

    height: float
    mass: float
    hip_width: float
    trunk: float
    shoulder_width: float
    neck: float
    ear_width: float
    upper_arm: float
    forearm: float
    hand: float
    thigh: float
    shank: float
    ankle_height: float
    foot_length: float
    heel_back: float
    r_pelvis: float
    r_abdomen: float
    r_chest: float
    r_upper_chest: float
    r_neck: float
    r_head: float
    r_upper_arm: float
    r_forearm: float
    r_thigh: float
    r_shank: float
    hand_length: float
    hand_width: float
    hand_thickness: float
    foot_width: float
    foot_height: float
    sex: str = "neutral"

    def __post_init__(self) -> None:
        _check_height(self.height)
        _check_mass(self.mass)
        if self.sex not in SEXES:
            raise PhysposeError(f"unknown sex {self.sex!r}", remedy=f"use one of {SEXES}")
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.name != "sex" and not (np.isfinite(v) and v > 0):
                raise PhysposeError(f"body shape {f.name} = {v} must be a positive length",
                                    remedy="check the measured bone lengths and widths")

    def bones(self) -> np.ndarray:
        """Bone lengths in skeleton.BONE_NAMES order: (13,) metres."""
        return np.array([getattr(self, n) for n in BONE_NAMES], dtype=float)

    def radius(self, name: str) -> float:
        """Capsule radius of a RADIUS_NAMES part, metres."""
        return float(getattr(self, f"r_{name}"))

    @property
    def bmi(self) -> float:
        return self.mass / self.height ** 2

    def with_segment_widths(self, widths: Mapping[str, float]) -> BodyShape:
        """Radii from silhouette widths (metres, e.g. a mask's width across a limb): r = w / 2.

        widths: {RADIUS_NAMES part: width}; parts not given keep their radius.
        """
        unknown = sorted(set(widths) - set(RADIUS_NAMES))
        if unknown:
            raise PhysposeError(f"unknown segment widths {unknown}",
                                remedy=f"name widths after {RADIUS_NAMES}")
        return dataclasses.replace(self, **{f"r_{k}": 0.5 * float(w) for k, w in widths.items()})

    @classmethod
    def from_height(cls, height: float, mass: float | None = None, build: str = "average",
                    sex: str = "neutral") -> BodyShape:
        """Average adult proportions for a stature (m); mass (kg) from the build's BMI if None."""
        _check_height(height)
        bones = {n: f * height for n, f in _BONE_FRACTION.items()}
        return _assemble(height, mass, build, sex, bones)

    @classmethod
    def from_bone_lengths(cls, lengths: Mapping[str, float] | np.ndarray,
                          height: float | None = None, mass: float | None = None,
                          build: str = "average", sex: str = "neutral") -> BodyShape:
        """Shape from measured bone lengths (metres), e.g. distances between fitted landmarks.

        lengths: {BONE_NAMES name: length} (missing bones come from the stature's proportions)
            or a (13,) array in BONE_NAMES order. height: stature (m); when None it is the
            standing chain ankle height + shank + thigh + trunk + neck + head top.
        """
        if isinstance(lengths, np.ndarray) or not isinstance(lengths, Mapping):
            arr = np.asarray(lengths, dtype=float)
            if arr.shape != (len(BONE_NAMES),):
                raise PhysposeError(f"bone lengths have shape {arr.shape}",
                                    remedy=f"pass ({len(BONE_NAMES)},) lengths in {BONE_NAMES}")
            given = dict(zip(BONE_NAMES, arr.tolist()))
        else:
            unknown = sorted(set(lengths) - set(BONE_NAMES))
            if unknown:
                raise PhysposeError(f"unknown bone names {unknown}",
                                    remedy=f"name bones after {BONE_NAMES}")
            given = {k: float(v) for k, v in lengths.items()}
        if height is None:
            fill = {n: given.get(n, f * _REFERENCE_HEIGHT) for n, f in _BONE_FRACTION.items()}
            if not all(np.isfinite(v) and v > 0 for v in fill.values()):
                raise PhysposeError("bone lengths must be positive and finite",
                                    remedy="check the measured landmark distances")
            height = stature_from_bones(np.array([fill[n] for n in BONE_NAMES]))
        _check_height(height)
        bones = {n: given.get(n, f * height) for n, f in _BONE_FRACTION.items()}
        return _assemble(height, mass, build, sex, bones)


def bone_lengths_from_landmarks(landmarks: np.ndarray, valid: np.ndarray | None = None
                                ) -> dict[str, float]:
    """Bone lengths (m) measured on 3d landmarks, median over frames, left and right averaged.

    landmarks: (T, 33, 3) or (33, 3) metric positions in MediaPipe order (e.g. the world
    landmarks). valid: (T,) bool frames to use (default: frames that are not all zero). The
    ankle height and heel offset follow from the ankle-heel, ankle-toe and heel-toe distances
    under the skeleton's foot geometry. Returns {BONE_NAMES name: length}, ready for
    ``BodyShape.from_bone_lengths``.
    """
    lm = np.asarray(landmarks, dtype=float)
    lm = lm[None] if lm.ndim == 2 else lm
    if lm.ndim != 3 or lm.shape[1:] != (len(LANDMARK_NAMES), 3):
        raise PhysposeError(f"landmarks have shape {lm.shape}",
                            remedy="pass (T, 33, 3) metric landmarks in MediaPipe order")
    keep = np.any(lm != 0, axis=(1, 2)) if valid is None else np.asarray(valid, dtype=bool)
    if keep.shape != (len(lm),) or not keep.any():
        raise PhysposeError("no valid frame to measure bone lengths on",
                            remedy="pass frames where the person was detected")
    lm = lm[keep]

    def at(name: str) -> np.ndarray:
        return lm[:, LANDMARK_NAMES.index(name)]

    def dist(a: np.ndarray, b: np.ndarray) -> float:
        return float(np.median(np.linalg.norm(a - b, axis=-1)))

    def sides(a: str, b: str) -> float:
        return 0.5 * (dist(at(f"left_{a}"), at(f"left_{b}")) + dist(at(f"right_{a}"),
                                                                      at(f"right_{b}")))

    def mid(name: str) -> np.ndarray:
        return 0.5 * (at(f"left_{name}") + at(f"right_{name}"))

    foot, heel, toe = sides("heel", "foot_index"), sides("ankle", "heel"), sides("ankle",
                                                                                "foot_index")
    # heel = ankle + (-b, 0, z), toe = ankle + (foot - b, 0, z), z = FOOT_LANDMARK_Z x ankle
    # height: two distances from the ankle give b and z.
    back = float(np.clip((foot ** 2 - toe ** 2 + heel ** 2) / (2 * foot), 1e-3, heel - 1e-3))
    ankle_height = float(np.sqrt(heel ** 2 - back ** 2) / abs(FOOT_LANDMARK_Z))
    return {
        "hip_width": dist(at("left_hip"), at("right_hip")),
        "trunk": dist(mid("shoulder"), mid("hip")),
        "shoulder_width": dist(at("left_shoulder"), at("right_shoulder")),
        "neck": dist(mid("ear"), mid("shoulder")),
        "ear_width": dist(at("left_ear"), at("right_ear")),
        "upper_arm": sides("shoulder", "elbow"), "forearm": sides("elbow", "wrist"),
        "hand": sides("wrist", "index"), "thigh": sides("hip", "knee"),
        "shank": sides("knee", "ankle"), "ankle_height": ankle_height, "foot_length": foot,
        "heel_back": back,
    }


def stature_from_bones(bones: np.ndarray) -> float:
    """Standing height implied by bone lengths (13,) in BONE_NAMES order, metres."""
    b = dict(zip(BONE_NAMES, np.asarray(bones, dtype=float)))
    return float(b["ankle_height"] + b["shank"] + b["thigh"] + b["trunk"] + b["neck"]
                 + HEAD_TOP_PER_EAR_WIDTH * b["ear_width"])


def mass_from_height(height: float, build: str = "average") -> float:
    """Body mass (kg) for a stature (m) at the build's BMI (BUILD_BMI)."""
    if build not in BUILD_BMI:
        raise PhysposeError(f"unknown build {build!r}", remedy=f"use one of {tuple(BUILD_BMI)}")
    return BUILD_BMI[build] * height ** 2


def _assemble(height: float, mass: float | None, build: str, sex: str,
              bones: dict[str, float]) -> BodyShape:
    if mass is None:
        mass = mass_from_height(height, build)
        if not MASS_RANGE[0] <= mass <= MASS_RANGE[1]:
            raise PhysposeError(
                f"the mass estimated for a height of {height:g} m at BMI {BUILD_BMI[build]:g} "
                f"is {mass:.1f} kg, outside {MASS_RANGE[0]:g}-{MASS_RANGE[1]:g} kg",
                remedy="give the body mass explicitly")
    _check_mass(mass)
    # Radii scale with the height (geometric similarity, so limbs clear the trunk at any
    # stature) and with sqrt(BMI) (cross-section ~ mass per height^2). Beyond a plausible BMI
    # the segments get denser instead of wider.
    bmi = float(np.clip(mass / height ** 2, *_GEOMETRY_BMI_RANGE))
    k = float(height / _REFERENCE_HEIGHT * np.sqrt(bmi / _REFERENCE_BMI))
    radii = {f"r_{n}": r * k for n, r in _REFERENCE_RADIUS.items()}
    return BodyShape(
        height=float(height), mass=float(mass), sex=sex, **bones, **radii,
        hand_length=_HAND_LENGTH_PER_HAND * bones["hand"],
        hand_width=_HAND_WIDTH * height,
        hand_thickness=_HAND_THICKNESS * height * np.sqrt(bmi / _REFERENCE_BMI),
        foot_width=_FOOT_WIDTH * height,
        foot_height=_FOOT_HEIGHT_PER_ANKLE * bones["ankle_height"],
    )


def _check_height(height: float) -> None:
    if not (np.isfinite(height) and HEIGHT_RANGE[0] <= height <= HEIGHT_RANGE[1]):
        raise PhysposeError(f"height {height} m is outside {HEIGHT_RANGE[0]}-{HEIGHT_RANGE[1]} m",
                            remedy="give the person's standing height in metres (e.g. 1.75)")


def _check_mass(mass: float) -> None:
    if not (np.isfinite(mass) and MASS_RANGE[0] <= mass <= MASS_RANGE[1]):
        raise PhysposeError(f"mass {mass} kg is outside {MASS_RANGE[0]:g}-{MASS_RANGE[1]:g} kg",
                            remedy="give the body mass in kilograms (e.g. 70), or omit it to "
                                   "estimate it from the height")
