"""Robust triangulation on synthetic cameras and points."""

from __future__ import annotations

import numpy as np
import pytest

from physpose.errors import PhysposeError
from physpose.multiview.triangulate import TriangulationConfig, triangulate


def _look_at(center: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(3, 4) [R | t] of an OpenCV camera at `center` looking at `target`, world z up."""
    z = target - center
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return np.hstack([R, (-R @ center)[:, None]])


def _rig(n_views: int = 4) -> np.ndarray:
    K = np.array([[1500.0, 0, 540], [0, 1500.0, 960], [0, 0, 1]])
    angles = np.linspace(0, 2 * np.pi, n_views, endpoint=False) + 0.3
    centers = np.stack([4 * np.cos(angles), 4 * np.sin(angles), np.full(n_views, 2.0)], 1)
    return np.stack([K @ _look_at(c, np.array([0.0, 0.0, 1.0])) for c in centers])


def _project(P: np.ndarray, X: np.ndarray) -> np.ndarray:
    """(N, 3, 4), (T, J, 3) -> (N, T, J, 2)."""
    Xh = np.concatenate([X, np.ones(X.shape[:-1] + (1,))], -1)
    proj = np.einsum("nij,tkj->ntki", P, Xh)
    return proj[..., :2] / proj[..., 2:]


def _scene(rng: np.random.Generator, t: int = 5, j: int = 7) -> np.ndarray:
    return rng.uniform([-0.5, -0.5, 0.0], [0.5, 0.5, 1.8], size=(t, j, 3))


def test_exact_recovery_without_noise():
    rng = np.random.default_rng(0)
    P, X = _rig(), _scene(rng)
    kp = np.concatenate([_project(P, X), rng.uniform(0.5, 1, X.shape[:2] + (1,))[None]
                         .repeat(4, 0)], -1)
    tri = triangulate(P, kp)
    np.testing.assert_allclose(tri.points, X, atol=1e-6)
    assert tri.used.all()
    assert np.nanmax(tri.errors) < 1e-4


def test_outlier_view_is_rejected():
    rng = np.random.default_rng(1)
    P, X = _rig(), _scene(rng)
    uv = _project(P, X) + rng.normal(0, 1.0, (4,) + X.shape[:2] + (2,))
    uv[2] += 150.0  # view 2 is wrong by 150 px everywhere (e.g. a left/right swap)
    kp = np.concatenate([uv, np.ones((4,) + X.shape[:2] + (1,))], -1)
    tri = triangulate(P, kp, TriangulationConfig(inlier_px=20.0))
    assert not tri.used[..., 2].any()
    assert tri.used[..., [0, 1, 3]].all()
    assert np.abs(tri.points - X).max() < 0.02
    assert np.nanmedian(tri.view_errors[..., 2]) > 100
    # without rejection the same input is visibly wrong
    naive = triangulate(P, kp, TriangulationConfig(inlier_px=1e6))
    assert np.abs(naive.points - X).max() > 0.05


def test_two_outliers_of_five_views_are_rejected():
    rng = np.random.default_rng(2)
    P, X = _rig(5), _scene(rng)
    uv = _project(P, X)
    uv[0] -= 80.0
    uv[3, ..., 1] += 120.0
    kp = np.concatenate([uv, np.ones((5,) + X.shape[:2] + (1,))], -1)
    tri = triangulate(P, kp)
    assert tri.used[..., [1, 2, 4]].all() and not tri.used[..., [0, 3]].any()
    np.testing.assert_allclose(tri.points, X, atol=1e-6)


def test_low_confidence_views_are_ignored_and_single_views_give_nan():
    rng = np.random.default_rng(3)
    P, X = _rig(3), _scene(rng, t=2, j=3)
    kp = np.concatenate([_project(P, X), np.ones((3, 2, 3, 1))], -1)
    kp[1, 0, 0, :2] = 5000.0
    kp[1, 0, 0, 2] = 0.1            # junk, but flagged as unreliable
    kp[[0, 1], 1, 2, 2] = 0.0       # point seen by one view only
    tri = triangulate(P, kp)
    np.testing.assert_allclose(tri.points[0, 0], X[0, 0], atol=1e-6)
    assert not tri.used[0, 0, 1]
    assert np.isnan(tri.view_errors[0, 0, 1])
    assert np.isnan(tri.points[1, 2]).all() and not tri.valid[1, 2] and not tri.used[1, 2].any()


def test_confidence_weights_favour_confident_views():
    rng = np.random.default_rng(4)
    P, X = _rig(4), _scene(rng, t=1, j=20)
    uv = _project(P, X)
    uv[1] += rng.normal(0, 15.0, uv[1].shape)  # noisy but within the inlier threshold
    conf = np.ones((4, 1, 20, 1))
    equal = triangulate(P, np.concatenate([uv, conf], -1))
    conf[1] = 0.35
    weighted = triangulate(P, np.concatenate([uv, conf], -1))
    err_equal = np.linalg.norm(equal.points - X, axis=-1).mean()
    err_weighted = np.linalg.norm(weighted.points - X, axis=-1).mean()
    assert err_weighted < 0.7 * err_equal


def test_bad_config_and_shapes():
    with pytest.raises(PhysposeError):
        TriangulationConfig(min_views=1)
    with pytest.raises(ValueError):
        triangulate(np.zeros((2, 3, 4)), np.zeros((3, 1, 1, 3)))
