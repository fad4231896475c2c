"""The ground plane T_g (+G): the paper's L_gp over the fitted body, and the level-camera guess.

L_gp(T_g) = sum_t ||min(delta, L_k(D_left^t))|| + ||min(delta, L_k(D_right^t))||
            + 2 ||min(delta, L_k(D_body^t))||,
D the signed distances of surface points to the plane and L_k the k smallest. It places the
body in contact with the ground without preferring particular contact points and ignores
frames in the air. Where the contacts alone leave the plane's tilt open (a person standing on
one spot), two priors decide: balance (averaged over the clip, the body's centre of mass lies
above its support, the centroid of the lowest surface points; a frame counts as far as its
centre of mass rises above the lowest point, not at all under _BALANCE_MIN_RISE and fully from
_BALANCE_FULL_RISE: lying or sitting on the floor, the direction says nothing about which way
is up, and crouching or bending frames count less too) and a weak one that the camera's roll
about its optical axis is small. The balance term is averaged over all frames, so a clip with
many low frames has a weaker prior. The rise is measured along the candidate normal, so the
weights change as the search moves. The plane is searched from several starts (the level
camera's up, the mean balance direction, the normal of the lowest foot points or, where these
lie along a line at least a metre or so long, the plane through that line nearest the balance
direction), each also with the level camera's up reversed, and the best minimum wins. Along
the line of sight of a low camera a tilt towards it and the depth gain (below) nearly trade
off, and the loss has minima several degrees off that the other starts can lead into. The
reversed starts find the floor under a camera held upside down (rolled by about a half turn,
with no rotation tag in the video), which sees the person head-down: from the level camera's
up alone, the floor of three simulated clips came out upside down at rolls of 150 and 180
degrees, the head 1.2-1.4 m below the ankles. Where the camera is upright, the reversed floor
(the person standing on a ceiling, the feet off it) is far worse in the contact terms and
costs the roll prior a half turn too.

Monocular depth errors are correlated with the distance: on the pose2sim views the estimated
depth varies 0.65-1.4 x as much as the true one. Feet at the wrong depth along their rays
tilt the plane towards or away from the camera (4 degrees there, which moved the camera height
by 15 %). So the plane fit also estimates that gain: frame t's body is scaled about the camera
centre (moved along its rays, so its image stays the same) by exp(g u_t), u_t its relative
distance from the clip's mean distance, with a Gaussian prior on g (`depth_gain_sigma`).

The plane is fitted in double precision, as the whole kinematic fit is (fit_kinematics);
estimate_plane sets it itself, so a caller outside that fit gets the same plane. In single
precision L-BFGS stopped where the loss's rounding noise hid its last descent, at a place set
by that noise: moving the points by a micrometre moved the camera height by up to 4.3 cm, and
so did another processor's rounding (the tilted-floor test, which called it outside the fit,
put the camera 5.8 cm high on one machine and 8.2 on another; 3.6 in double precision). In
double precision the same micrometre moves it by under a millimetre.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from physpose.kinematics.camera import UP_LEVEL
from physpose.kinematics.config import GroundConfig
from physpose.kinematics.evidence import pad, padded_length
from physpose.kinematics.losses import ground_term
from physpose.kinematics.optim import minimize
from physpose.kinematics.precision import double_precision

_GP_SCALE = 0.02  # m: L_gp is divided by this, so a 2 cm change weighs like one prior sigma


class PlaneParams(NamedTuple):
    tilt: np.ndarray    # (2,) normal = normalise(n0 + tilt[0] e1 + tilt[1] e2)
    offset: np.ndarray  # () d in n . x + d = 0
    depth_gain: np.ndarray  # () frame t scaled about the camera centre by exp(gain * u_t)


def _basis(n0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    e1 = np.cross(n0, [0.0, 0.0, 1.0])
    if np.linalg.norm(e1) < 1e-6:
        e1 = np.cross(n0, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n0, e1)


def _normal(tilt, n0, e1, e2):
    n = n0 + tilt[0] * e1 + tilt[1] * e2
    return n / jnp.linalg.norm(n)


_SUPPORT_BAND = 0.03  # m: surface points this close to the lowest one form the support
_BALANCE_FULL_RISE = 0.6  # m: a centre of mass this high above the lowest point counts fully
_BALANCE_MIN_RISE = 0.25  # m: ... and one this low (lying, sitting on the floor) not at all
_MAX_ROUNDS = 3       # restarts of the plane fit from its own result


def _plane_loss(p: PlaneParams, n0, e1, e2, points, weight, left, right, balance, lever,
                depth_u, roll_sigma, balance_sigma, gain_sigma, *, k, delta, body_weight):
    n = _normal(p.tilt, n0, e1, e2)
    dist = jnp.exp(p.depth_gain * depth_u)[:, None] * (points @ n) + p.offset   # (T, P)
    per = (ground_term(dist[:, left], k, delta) + ground_term(dist[:, right], k, delta)
           + body_weight * ground_term(dist, k, delta)) / _GP_SCALE
    roll = jnp.arctan2(n[0], -n[1])
    lean = 2.0 * lever * (1.0 - balance @ n) / balance_sigma ** 2
    return (jnp.sum(weight * (per + lean)) / jnp.sum(weight) + (roll / roll_sigma) ** 2
            + (p.depth_gain / gain_sigma) ** 2)


_plane_value_and_grad = jax.jit(jax.value_and_grad(_plane_loss),
                                static_argnames=("k", "delta", "body_weight"))


def balance_directions(points: np.ndarray, com: np.ndarray, up: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors (T, 3) from each frame's support (centroid of the surface points within
    _SUPPORT_BAND of the lowest along `up`) to its centre of mass, and how much each frame's
    direction counts (T,): 0 where the centre of mass rises less than _BALANCE_MIN_RISE above
    the lowest point along `up`, rising as a square to 1 at _BALANCE_FULL_RISE. A body lying
    on the floor has its centre of mass a few tenths of a metre above a support of a few
    points under it, and the direction between them says nothing about which way is up."""
    heights = points @ up
    near = heights <= heights.min(axis=1, keepdims=True) + _SUPPORT_BAND
    support = (points * near[..., None]).sum(1) / near.sum(1, keepdims=True)
    b = com - support
    rise = np.maximum(com @ up - heights.min(axis=1), 0.0)
    return (b / np.maximum(np.linalg.norm(b, axis=-1, keepdims=True), 1e-9),
            np.clip((rise - _BALANCE_MIN_RISE) / (_BALANCE_FULL_RISE - _BALANCE_MIN_RISE),
                    0.0, 1.0) ** 2)


def _lowest_foot_normal(points: np.ndarray, feet: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """Normal of the least-squares plane through each frame's lowest foot point. Where those
    points lie along a line (a person walking straight on), the plane through that line
    nearest `fallback`: the contacts still fix the floor's slope along it. Where they spread
    less (a person staying on one spot, whose line is the noisy one between the feet),
    `fallback`."""
    heights = points[:, feet] @ fallback
    low = points[:, feet][np.arange(len(points)), np.argmin(heights, axis=1)]
    if len(low) < 3:
        return fallback
    centred = low - low.mean(axis=0)
    _, s, vt = np.linalg.svd(centred, full_matrices=False)
    if s[1] < 0.2 * s[0] or s[1] < 0.05:  # along a line or on one spot
        if s[0] < 0.3 * np.sqrt(len(low)):  # spread under 0.3 m RMS: no line to trust
            return fallback
        line = vt[0]
        n = fallback - (fallback @ line) * line
        return n / np.linalg.norm(n)
    n = vt[2]
    return n if n @ fallback > 0 else -n


def estimate_plane(points: np.ndarray, left: np.ndarray, right: np.ndarray, com: np.ndarray,
                   cfg: GroundConfig) -> tuple[np.ndarray, float]:
    """The ground plane (4,) = (n, d), n . x + d = 0 with n up, from posed surface points.

    points: (T, P, 3) camera axes, frames with evidence only; left, right: (P,) bool sole
    points of each foot; com: (T, 3) centres of mass. Returns the plane and its loss.
    """
    with double_precision():  # see the module's docstring: single precision stops short
        return _best_plane(np.asarray(points, dtype=float), left, right,
                           np.asarray(com, dtype=float), cfg)


def _best_plane(points: np.ndarray, left: np.ndarray, right: np.ndarray, com: np.ndarray,
                cfg: GroundConfig) -> tuple[np.ndarray, float]:
    """estimate_plane's search: the best of the descents from every start."""
    feet = np.flatnonzero(left | right)
    starts = []
    for up in (UP_LEVEL, -UP_LEVEL):  # a camera upright, and one upside down
        balance, lever = balance_directions(points, com, up)
        mean = (lever[:, None] * balance).sum(axis=0) if lever.sum() > 0 else balance.mean(0)
        starts += [up, mean / np.linalg.norm(mean)]
        starts.append(_lowest_foot_normal(points, feet, starts[-1]))
    best = min((_descend(points, left, right, com, n0, cfg) for n0 in starts),
               key=lambda r: r[0])
    value, n, d = best
    return np.concatenate([n, [d]]), value


def relative_depth(points: np.ndarray) -> np.ndarray:
    """(T,) u_t = (r_t - mean r) / mean r, r_t the distance of frame t's centroid (camera axes)."""
    r = np.linalg.norm(np.asarray(points).mean(axis=1), axis=-1)
    return (r - r.mean()) / r.mean()


def _descend(points, left, right, com, n0, cfg: GroundConfig) -> tuple[float, np.ndarray, float]:
    """(loss, normal, offset) of the plane fit from n0. The support (hence the balance
    directions) depends on the normal, and L-BFGS stops at the kinks of the k-smallest
    selection: restart from each result while it improves."""
    best, n = (np.inf, n0, 0.0), n0
    for _ in range(_MAX_ROUNDS):
        balance, lever = balance_directions(points, com, n)
        v, n_new, d = _fit_plane(points, left, right, balance, lever, n, cfg)
        if v > best[0] - 1e-6:
            break
        best, n = (v, n_new, d), n_new
    return best


def _fit_plane(points, left, right, balance, lever, n0, cfg: GroundConfig):
    e1, e2 = _basis(n0)
    feet = np.flatnonzero(left | right)
    d0 = -float(np.percentile(np.min(points[:, feet] @ n0, axis=1), 10.0))
    length = padded_length(len(points))  # a few array sizes: compiled code is reused
    weight = np.zeros(length)
    weight[:len(points)] = 1.0
    args = tuple(jnp.asarray(a) for a in (  # on the device once, not at every evaluation
        n0, e1, e2, pad(points, length), weight, np.flatnonzero(left), np.flatnonzero(right),
        pad(balance, length), pad(lever, length), pad(relative_depth(points), length),
        np.radians(cfg.roll_sigma_deg), np.radians(cfg.balance_sigma_deg),
        max(cfg.depth_gain_sigma, 1e-6)))

    def value_and_grad(p: PlaneParams):
        return _plane_value_and_grad(p, *args, k=cfg.k, delta=cfg.delta,
                                     body_weight=cfg.body_weight)

    free = ("tilt", "offset") + (("depth_gain",) if cfg.depth_gain_sigma > 0 else ())
    res = minimize(value_and_grad, PlaneParams(np.zeros(2), np.asarray(d0), np.asarray(0.0)),
                   free, iterations=200)
    n = np.asarray(_normal(res.params.tilt, n0, e1, e2))
    return res.value, n, float(res.params.offset)


def level_plane(points: np.ndarray, feet: np.ndarray, percentile: float) -> np.ndarray:
    """The level-camera guess (no +G): up = -y (camera axes), the floor under the lowest sole
    point in `percentile` % of frames. points: (T, P, 3); feet: (P,) bool. Returns (4,)."""
    heights = np.min(points[:, feet] @ UP_LEVEL, axis=1)
    return np.concatenate([UP_LEVEL, [-float(np.percentile(heights, percentile))]])
