"""Robust, confidence-weighted DLT triangulation of landmarks seen by several calibrated views.

Per point: views whose confidence is below a threshold are ignored. Every pair of the remaining
views proposes a point; the pair with most views re-projecting within `inlier_px` (ties: the
smaller summed error) wins, its inliers are re-triangulated with confidence weights, and then the
view with the largest error is dropped while it exceeds `inlier_px` and more than `min_views`
views remain. Points without `min_views` usable views are NaN.

Inputs are ideal (undistorted) pixel coordinates with pinhole projections P = K [R | t]; undistort
detections first (`CameraCalibration.undistort`).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from physpose.errors import PhysposeError


@dataclass(frozen=True)
class TriangulationConfig:
    """Thresholds of the robust triangulation."""

    min_confidence: float = 0.3   # detections below this confidence are ignored, [0, 1]
    inlier_px: float = 40.0       # re-projection error above which a view is an outlier, px
    min_views: int = 2            # fewest views a point is triangulated from

    def __post_init__(self) -> None:
        if self.min_views < 2:
            raise PhysposeError(f"triangulation config: min_views={self.min_views} < 2",
                                remedy="a 3d point needs at least two views")
        if not self.inlier_px > 0:
            raise PhysposeError("triangulation config: inlier_px must be > 0")


@dataclass(frozen=True, eq=False)
class Triangulation:
    """Triangulated points and how well they agree with the views."""

    points: np.ndarray        # (T, P, 3) world coordinates (NaN where not triangulable)
    view_errors: np.ndarray   # (T, P, N) re-projection error in every view, px (NaN: behind
                              # the camera, no point, or the view had no usable detection)
    used: np.ndarray          # (T, P, N) bool, views the final point was computed from

    @property
    def errors(self) -> np.ndarray:
        """(T, P) mean re-projection error over the used views, px (NaN where no point)."""
        err = np.where(self.used, self.view_errors, 0.0)
        n = self.used.sum(-1)
        with np.errstate(invalid="ignore"):
            return np.where(n > 0, err.sum(-1) / np.maximum(n, 1), np.nan)

    @property
    def valid(self) -> np.ndarray:
        """(T, P) bool, points that were triangulated."""
        return np.isfinite(self.points).all(-1)


def triangulate(projections: np.ndarray, keypoints: np.ndarray,
                cfg: TriangulationConfig = TriangulationConfig()) -> Triangulation:
    """Triangulate every point of every frame.

    projections: (N, 3, 4) pinhole projection matrices of the N views.
    keypoints: (N, T, P, 3) ideal pixel x, y + confidence in [0, 1] per view, frame and point.
    """
    P = np.asarray(projections, dtype=float)
    kp = np.asarray(keypoints, dtype=float)
    n_views = P.shape[0]
    if P.shape[1:] != (3, 4) or kp.ndim != 4 or kp.shape[0] != n_views or kp.shape[-1] != 3:
        raise ValueError(f"projections {P.shape} and keypoints {kp.shape} do not match "
                         "(N, 3, 4) and (N, T, P, 3)")
    _, t, p, _ = kp.shape
    uv = np.moveaxis(kp[..., :2], 0, 2).reshape(-1, n_views, 2)      # (M, N, 2)
    conf = np.moveaxis(kp[..., 2], 0, 2).reshape(-1, n_views)        # (M, N)
    usable = (conf >= cfg.min_confidence) & np.isfinite(uv).all(-1)
    weights = np.where(usable, conf, 0.0)

    mask = _best_pair_inliers(P, uv, weights, usable, cfg)
    X = _dlt(P, uv, weights * mask)
    err = _reprojection_errors(P, uv, X)
    for _ in range(n_views):  # greedy: drop the worst view while it is an outlier
        masked = np.where(mask, np.nan_to_num(err, nan=np.inf), -np.inf)
        worst = np.argmax(masked, axis=1)
        worst_err = masked[np.arange(len(masked)), worst]
        drop = (worst_err > cfg.inlier_px) & (mask.sum(1) > cfg.min_views)
        if not drop.any():
            break
        mask[np.flatnonzero(drop), worst[drop]] = False
        X[drop] = _dlt(P, uv[drop], weights[drop] * mask[drop])
        err[drop] = _reprojection_errors(P, uv[drop], X[drop])

    ok = mask.sum(1) >= cfg.min_views
    X[~ok] = np.nan
    mask[~ok] = False
    err = np.where(usable & ok[:, None], err, np.nan)
    return Triangulation(points=X.reshape(t, p, 3), view_errors=err.reshape(t, p, n_views),
                         used=mask.reshape(t, p, n_views))


def _best_pair_inliers(P: np.ndarray, uv: np.ndarray, weights: np.ndarray, usable: np.ndarray,
                       cfg: TriangulationConfig) -> np.ndarray:
    """(M, N) bool: the inlier views of the best two-view hypothesis of each point."""
    m, n = usable.shape
    best_count = np.full(m, -1)
    best_cost = np.full(m, np.inf)
    best_mask = usable.copy()  # fallback for points with fewer than two usable views
    for a, b in itertools.combinations(range(n), 2):
        pair = np.zeros(n)
        pair[[a, b]] = 1.0
        has = usable[:, a] & usable[:, b]
        if not has.any():
            continue
        X = _dlt(P, uv[has], weights[has] * pair)
        err = _reprojection_errors(P, uv[has], X)
        inl = usable[has] & (err <= cfg.inlier_px)
        count = inl.sum(1)
        cost = np.where(inl, err, 0.0).sum(1)
        idx = np.flatnonzero(has)
        better = (count > best_count[idx]) | ((count == best_count[idx]) & (cost < best_cost[idx]))
        # A pair that does not even agree with itself keeps both views (the greedy step decides).
        chosen = np.where((count >= 2)[:, None], inl, usable[has] & (pair > 0))
        best_count[idx[better]] = count[better]
        best_cost[idx[better]] = cost[better]
        best_mask[idx[better]] = chosen[better]
    return best_mask


def _dlt(P: np.ndarray, uv: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted linear triangulation: uv (M, N, 2), weights (M, N) -> (M, 3); NaN if < 2 views."""
    rows_x = uv[..., 0:1] * P[None, :, 2] - P[None, :, 0]   # (M, N, 4)
    rows_y = uv[..., 1:2] * P[None, :, 2] - P[None, :, 1]
    rows = np.concatenate([rows_x, rows_y], axis=1)          # (M, 2N, 4)
    rows = np.nan_to_num(rows)
    norm = np.linalg.norm(rows, axis=-1, keepdims=True)
    w = np.concatenate([weights, weights], axis=1)[..., None]
    A = rows / np.maximum(norm, 1e-12) * w  # unit rows: weights alone set each view's influence
    _, _, vt = np.linalg.svd(A)
    h = vt[:, -1]
    with np.errstate(divide="ignore", invalid="ignore"):
        X = h[:, :3] / h[:, 3:4]
    X[(weights > 0).sum(1) < 2] = np.nan
    return X


def _reprojection_errors(P: np.ndarray, uv: np.ndarray, X: np.ndarray) -> np.ndarray:
    """(M, N) pixel distance between uv (M, N, 2) and the projections of X (M, 3); NaN behind."""
    Xh = np.concatenate([X, np.ones((len(X), 1))], axis=1)
    proj = np.einsum("nij,mj->mni", P, Xh)                   # (M, N, 3)
    depth = proj[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        px = proj[..., :2] / depth[..., None]
        err = np.linalg.norm(px - uv, axis=-1)
    return np.where(depth > 0, err, np.nan)
