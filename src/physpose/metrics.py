"""The paper's evaluation metrics (supplementary, "Additional Metrics"), plus penetration and jitter.

Position metrics compare an estimate with ground truth given in one common frame (world, or
camera: see `evaluate`'s transforms). Plausibility metrics (foot skate, float, penetration,
jitter) read one motion in its own world frame: z up, ground plane z = 0. Arrays are
(T, J, 3) metres under `physpose.joints.JOINT_NAMES` unless a `joint_names` says otherwise.
Definitions and choices: docs/metrics.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from physpose.errors import PhysposeError
from physpose.joints import JOINT_NAMES

SKATE_DISTANCE = 0.02  # m, a foot in contact moving further than this between frames skates ...
SKATE_RATE = 25.0  # Hz, ... at the paper's frame rate; at f Hz the distance is 0.02 x 25 / f m
FLOAT_DISTANCE = 0.02  # m, a foot out of contact but lower than this floats
FALL_RATIO = 0.5  # a head lower than this fraction of the reference's head height has fallen ...
FALL_MARGIN = 0.2  # m, ... if it is also at least this much (about a head's height) lower
SIDES = ("l", "r")


@dataclass(frozen=True)
class ContactConfig:
    """Foot-ground contact: at least `min_points` of a foot's sole points lie below `threshold`.

    The sole is a grid of `grid` = (along, across) points on the rectangle from the heel to the
    toe joint, `width_ratio` x its length wide, in the plane that contains the heel-toe line
    and is perpendicular to the ankle's offset from that line (world z if the ankle lies on it).
    """

    threshold: float = 0.005        # m, d in the paper
    min_points: int = 10            # N in the paper
    grid: tuple[int, int] = (12, 6)  # sole points along heel->toe, across the foot
    width_ratio: float = 0.35       # foot breadth / foot length (anthropometric, ~0.35-0.40)


# The paper's thresholds: d = 5 mm for kinematic output; -15 mm for the simulated body, whose
# box feet differ from the mesh the metric was defined on.
KINEMATIC_CONTACT = ContactConfig(threshold=0.005)
DYNAMIC_CONTACT = ContactConfig(threshold=-0.015)
CONTACT_PRESETS = {"kinematics": KINEMATIC_CONTACT, "dynamics": DYNAMIC_CONTACT}


def _check(*arrays: np.ndarray) -> None:
    shape = arrays[0].shape
    for a in arrays:
        if a.shape != shape or a.ndim != 3 or a.shape[-1] != 3:
            raise ValueError(f"expected matching (T, J, 3) arrays, got {[x.shape for x in arrays]}")
        if not np.isfinite(a).all():
            raise ValueError("joint arrays must be finite")


def _index(joint_names, name: str) -> int:
    return list(joint_names).index(name)


def transform_points(T_a2b: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a (4, 4) rigid transform to points (..., 3)."""
    return points @ T_a2b[:3, :3].T + T_a2b[:3, 3]


def camera_height(T_world2cam: np.ndarray) -> float:
    """Height (m) of the camera centre above the floor z = 0 of a world -> camera transform."""
    T = np.asarray(T_world2cam, dtype=float)
    return float(-(T[:3, :3].T @ T[:3, 3])[2])


def camera_tilt(T_world2cam: np.ndarray) -> float:
    """Degrees between the floor's up direction and the image's up axis (-y) of a world ->
    camera transform: 0 for a level camera, its pitch and roll together otherwise."""
    up = np.asarray(T_world2cam, dtype=float)[:3, :3] @ np.array([0.0, 0.0, 1.0])
    return float(np.degrees(np.arccos(np.clip(-up[1] / np.linalg.norm(up), -1.0, 1.0))))


def project(points: np.ndarray, K: np.ndarray, T_world2cam: np.ndarray) -> np.ndarray:
    """Pinhole projection of world points (..., 3) to pixels (..., 2)."""
    cam = transform_points(T_world2cam, points)
    uvw = cam @ K.T
    return uvw[..., :2] / uvw[..., 2:3]


def align_first_frame(est: np.ndarray, gt: np.ndarray, root: int = 0) -> np.ndarray:
    """Translate the whole estimate so its root joint matches the ground truth's in frame 0."""
    return est + (gt[0, root] - est[0, root])


def mpjpe_g(est: np.ndarray, gt: np.ndarray, root: int = 0) -> float:
    """Global MPJPE (mm): mean joint distance over all frames after first-frame root alignment."""
    _check(est, gt)
    return float(np.linalg.norm(align_first_frame(est, gt, root) - gt, axis=-1).mean() * 1000)


def mpjpe(est: np.ndarray, gt: np.ndarray, root: int = 0) -> float:
    """MPJPE (mm) with the root joint aligned in every frame."""
    _check(est, gt)
    diff = (est - est[:, root:root + 1]) - (gt - gt[:, root:root + 1])
    return float(np.linalg.norm(diff, axis=-1).mean() * 1000)


def procrustes_align(est: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Per-frame similarity transform (rotation, translation, scale) of est onto gt. -> (T, J, 3)"""
    mu_e, mu_g = est.mean(axis=1, keepdims=True), gt.mean(axis=1, keepdims=True)
    x, y = est - mu_e, gt - mu_g
    u, s, vt = np.linalg.svd(np.einsum("tji,tjk->tik", x, y))  # H = X^T Y
    d = np.sign(np.linalg.det(np.einsum("tij,tjk->tik", u, vt)))
    s = s.copy()
    s[:, -1] *= d
    vt = vt.copy()
    vt[:, -1] *= d[:, None]
    rot = np.einsum("tij,tjk->tik", u, vt)  # x @ rot best matches y
    scale = s.sum(axis=1) / np.maximum((x ** 2).sum(axis=(1, 2)), 1e-12)
    return scale[:, None, None] * np.einsum("tji,tik->tjk", x, rot) + mu_g


def mpjpe_pa(est: np.ndarray, gt: np.ndarray) -> float:
    """MPJPE (mm) after per-frame Procrustes alignment with scale."""
    _check(est, gt)
    return float(np.linalg.norm(procrustes_align(est, gt) - gt, axis=-1).mean() * 1000)


def mpjpe_2d(est_px: np.ndarray, target_px: np.ndarray,
             confidence: np.ndarray | None = None) -> float:
    """Mean 2d distance (px). est_px, target_px: (T, J, 2); confidence: (T, J) weights or None.

    NaN when no joint carries weight (a video whose detections are all unsure): there is
    nothing to compare, and the benchmark's means skip NaN.
    """
    if est_px.shape != target_px.shape or est_px.shape[-1] != 2:
        raise ValueError(f"expected matching (T, J, 2) arrays, got {est_px.shape}, {target_px.shape}")
    err = np.linalg.norm(est_px - target_px, axis=-1)
    w = np.ones_like(err) if confidence is None else np.asarray(confidence, dtype=float)
    if w.shape != err.shape or (w < 0).any():
        raise ValueError(f"confidence must be (T, J) non-negative weights, got shape {w.shape}")
    if w.sum() == 0:
        return float("nan")
    return float((w * err).sum() / w.sum())


def _mean(values: np.ndarray) -> float:
    """The mean, NaN (without numpy's warning) where a motion is too short to have values."""
    return float(values.mean()) if values.size else float("nan")


def velocity_error(est: np.ndarray, gt: np.ndarray, fps: float, root: int = 0) -> float:
    """Mean |speed_gt - speed_est| (m/s) over frames and joints (paper eq. of e_v); NaN for a
    single frame.

    Speeds are magnitudes of finite-difference velocities of the first-frame-aligned joints.
    """
    _check(est, gt)
    est = align_first_frame(est, gt, root)
    speed = lambda x: np.linalg.norm(np.diff(x, axis=0), axis=-1) * fps
    return _mean(np.abs(speed(gt) - speed(est)))


def jitter(joints: np.ndarray, fps: float) -> float:
    """Mean joint acceleration magnitude (m/s^2), second finite differences; NaN for fewer
    than three frames."""
    _check(joints)
    acc = (joints[2:] - 2 * joints[1:-1] + joints[:-2]) * fps ** 2
    return _mean(np.linalg.norm(acc, axis=-1))


def foot_points(joints: np.ndarray, cfg: ContactConfig = KINEMATIC_CONTACT,
                joint_names=JOINT_NAMES) -> np.ndarray:
    """Sole points of both feet (see ContactConfig). -> (T, 2, P, 3), P = grid[0] * grid[1]."""
    out = []
    for s in SIDES:
        heel = joints[:, _index(joint_names, f"{s}_heel")]
        toe = joints[:, _index(joint_names, f"{s}_toe")]
        ankle = joints[:, _index(joint_names, f"{s}_ankle")]
        axis = toe - heel
        length = np.linalg.norm(axis, axis=-1, keepdims=True)
        fwd = axis / np.maximum(length, 1e-9)
        up = ankle - heel
        up = up - np.sum(up * fwd, axis=-1, keepdims=True) * fwd
        degenerate = np.linalg.norm(up, axis=-1) < 1e-6
        up[degenerate] = (0.0, 0.0, 1.0)
        side = np.cross(up, fwd)
        norm = np.linalg.norm(side, axis=-1, keepdims=True)
        side = np.where(norm > 1e-9, side / np.maximum(norm, 1e-12), 0.0)
        u = np.linspace(0.0, 1.0, cfg.grid[0])
        v = np.linspace(-0.5, 0.5, cfg.grid[1]) * cfg.width_ratio
        uu, vv = (g.ravel() for g in np.meshgrid(u, v, indexing="ij"))
        out.append(heel[:, None] + uu[None, :, None] * axis[:, None]
                   + vv[None, :, None] * length[:, None] * side[:, None])
    return np.stack(out, axis=1)


def foot_contacts(joints: np.ndarray, cfg: ContactConfig = KINEMATIC_CONTACT,
                  joint_names=JOINT_NAMES) -> np.ndarray:
    """(T, 2) bool [left, right]: at least `min_points` sole points below `threshold`."""
    _check(joints)
    low = foot_points(joints, cfg, joint_names)[..., 2] < cfg.threshold
    return low.sum(axis=-1) >= cfg.min_points


def foot_skate(joints: np.ndarray, cfg: ContactConfig = KINEMATIC_CONTACT,
               joint_names=JOINT_NAMES, *, fps: float) -> float:
    """% of frame pairs in which a foot in contact (both frames) slides; NaN for a single frame
    (no pair).

    A foot slides when both its heel and its toe move horizontally further than
    SKATE_DISTANCE per frame at SKATE_RATE (0.5 m/s, the paper's 2 cm at its 25 fps; scaled
    with the rate, so that a motion skates as often at any frame rate); a foot rolling over its
    heel or toe keeps one of them planted.
    """
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"frame rate {fps} must be positive")
    limit = SKATE_DISTANCE * (SKATE_RATE / fps)  # exactly SKATE_DISTANCE at SKATE_RATE
    contact = foot_contacts(joints, cfg, joint_names)
    both = contact[1:] & contact[:-1]
    moved = []
    for s in SIDES:
        step = [np.linalg.norm(np.diff(joints[:, _index(joint_names, f"{s}_{p}"), :2], axis=0),
                               axis=-1) for p in ("heel", "toe")]
        moved.append(np.minimum(*step) > limit)
    skating = (both & np.stack(moved, axis=1)).any(axis=1)
    return 100.0 * _mean(skating)


def foot_float(joints: np.ndarray, cfg: ContactConfig = KINEMATIC_CONTACT,
               joint_names=JOINT_NAMES) -> float:
    """% of frames where a foot is out of contact yet its lowest sole point is < FLOAT_DISTANCE."""
    contact = foot_contacts(joints, cfg, joint_names)
    lowest = foot_points(joints, cfg, joint_names)[..., 2].min(axis=-1)  # (T, 2)
    return float(100.0 * ((~contact) & (lowest < FLOAT_DISTANCE)).any(axis=1).mean())


def ground_penetration(joints: np.ndarray, cfg: ContactConfig = KINEMATIC_CONTACT,
                       joint_names=JOINT_NAMES) -> tuple[float, float]:
    """(mean, max) depth (mm) of the deepest sole point below z = 0 per frame (0 when above)."""
    _check(joints)
    depth = np.maximum(0.0, -foot_points(joints, cfg, joint_names)[..., 2].min(axis=(1, 2)))
    return float(depth.mean() * 1000), float(depth.max() * 1000)


def fallen(joints: np.ndarray, reference: np.ndarray, joint_names=JOINT_NAMES) -> float:
    """% of frames in which the head is lower than FALL_RATIO x the reference's head height and
    at least FALL_MARGIN lower than it.

    Both motions stand on their own ground z = 0, so no alignment is needed: a cartwheel in
    the reference lowers the threshold with it, a body lying on the floor where the reference
    stands counts. The margin keeps a reference that is itself down on the floor from counting
    its own pose as a fall: a rolling body's head 15 cm above the floor halves to 7.5 cm, less
    than a head's radius, so a second body rolling beside it would count by the ratio alone.
    """
    _check(joints, reference)
    head = _index(joint_names, "head")
    est, ref = joints[:, head, 2], reference[:, head, 2]
    return float(100.0 * ((est < FALL_RATIO * ref) & (est < ref - FALL_MARGIN)).mean())


def evaluate(est: np.ndarray, gt: np.ndarray | None = None, *, fps: float,
             contact: ContactConfig = KINEMATIC_CONTACT, joint_names=JOINT_NAMES,
             root: str = "pelvis", T_est2common: np.ndarray | None = None,
             T_gt2common: np.ndarray | None = None, est_2d: np.ndarray | None = None,
             target_2d: np.ndarray | None = None,
             confidence_2d: np.ndarray | None = None,
             fall_reference: np.ndarray | None = None) -> dict[str, float]:
    """All metrics that the inputs allow, keyed with their units.

    est: (T, J, 3) in its own world frame (z up, ground z = 0) for the plausibility metrics.
    gt: (T, J, 3) ground truth. Position metrics compare T_est2common(est) with
    T_gt2common(gt) ((4, 4) rigid transforms, identity when None): pass each motion's
    world-to-camera transform to compare in camera coordinates.
    est_2d, target_2d: (T, J, 2) px with optional confidence_2d (T, J) for MPJPE-2d.
    fall_reference: (T, J, 3) motion (own world frame) that `fallen_pct` compares head heights
    with; defaults to gt (both in their own world frames).
    """
    est = np.asarray(est, dtype=float)
    gt = None if gt is None else np.asarray(gt, dtype=float)
    _check(est)
    if est.shape[1] != len(joint_names):
        raise PhysposeError(f"{est.shape[1]} joints given for {len(joint_names)} joint names",
                            remedy="pass joints in joint_names' order (JOINT_NAMES: "
                                   "Reconstruction.joints(), not landmarks)")
    if not (np.isfinite(fps) and fps > 0):
        raise PhysposeError(f"frame rate {fps} must be positive", remedy="pass the motion's fps")
    if (est_2d is None) != (target_2d is None):
        raise PhysposeError("MPJPE-2d needs both est_2d and target_2d",
                            remedy="pass both, or neither")
    out: dict[str, float] = {}
    if gt is not None:
        a = est if T_est2common is None else transform_points(T_est2common, est)
        b = gt if T_gt2common is None else transform_points(T_gt2common, gt)
        r = _index(joint_names, root)
        out.update(mpjpe_g_mm=mpjpe_g(a, b, r), mpjpe_mm=mpjpe(a, b, r),
                   mpjpe_pa_mm=mpjpe_pa(a, b), velocity_error_mps=velocity_error(a, b, fps, r))
    if est_2d is not None and target_2d is not None:
        out["mpjpe_2d_px"] = mpjpe_2d(est_2d, target_2d, confidence_2d)
    pen_mean, pen_max = ground_penetration(est, contact, joint_names)
    out.update(foot_skate_pct=foot_skate(est, contact, joint_names, fps=fps),
               float_pct=foot_float(est, contact, joint_names),
               penetration_mean_mm=pen_mean, penetration_max_mm=pen_max,
               jitter_mps2=jitter(est, fps))
    reference = gt if fall_reference is None else fall_reference
    if reference is not None:
        out["fallen_pct"] = fallen(est, reference, joint_names)
    return out
