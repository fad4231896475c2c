"""Servo-target splines: basis properties, derivatives, coefficient ranges, least-squares fit."""

from __future__ import annotations

import numpy as np
import pytest

from physpose.dynamics.spline import KnotGrid, cubic_bspline, evaluate, fit_coefficients

GRIDS = [KnotGrid(0.1, 1.0), KnotGrid(0.2, 1.3), KnotGrid(0.15, 0.05)]


@pytest.mark.parametrize("grid", GRIDS, ids=lambda g: f"h{g.spacing}-d{g.duration}")
def test_partition_of_unity_and_linear_reproduction(grid):
    t = np.linspace(0.0, grid.duration, 97)
    basis = grid.basis(t)
    assert basis.shape == (len(t), grid.num_coefs)
    np.testing.assert_allclose(basis.sum(axis=1), 1.0, atol=1e-12)
    # Coefficients equal to a linear function at the knot centres reproduce it exactly.
    a, b = 0.7, -1.3
    np.testing.assert_allclose(basis @ (a * grid.centres() + b), a * t + b, atol=1e-12)
    assert (basis >= 0).all()


def test_derivatives_match_finite_differences():
    grid = KnotGrid(0.1, 1.0)
    coefs = np.random.default_rng(0).normal(size=grid.num_coefs)
    t = np.linspace(0.05, 0.95, 301)
    h = 1e-6
    value = lambda tt: grid.basis(tt) @ coefs  # noqa: E731
    np.testing.assert_allclose(grid.basis(t, derivative=1) @ coefs,
                               (value(t + h) - value(t - h)) / (2 * h), rtol=1e-5, atol=1e-5)
    d1 = lambda tt: grid.basis(tt, derivative=1) @ coefs  # noqa: E731
    np.testing.assert_allclose(grid.basis(t, derivative=2) @ coefs,
                               (d1(t + h) - d1(t - h)) / (2 * h), rtol=1e-4, atol=1e-3)
    with pytest.raises(ValueError):
        cubic_bspline(np.zeros(3), derivative=3)


@pytest.mark.parametrize("start", [0.0, 0.39, 0.4, 0.41, 0.8])
def test_active_and_started_before(start):
    grid = KnotGrid(0.2, 1.0)
    after = grid.basis(np.linspace(start + 1e-6, 1.0, 200))
    nonzero = np.flatnonzero(np.abs(after).max(axis=0) > 0)
    active = grid.active(start, 1.0)
    assert (active.start, active.stop) == (nonzero.min(), nonzero.max() + 1)
    if start > 0:
        before = grid.basis(np.linspace(0.0, start - 1e-6, 200))
        touched = np.flatnonzero(np.abs(before).max(axis=0) > 0)
        assert grid.started_before(start) == touched.max() + 1
    assert grid.searched(start, 1.0, continued=False) == active
    # Continuing a window, those begun before start (non-zero at some earlier time) are kept.
    kept = grid.searched(start, 1.0, continued=True)
    earlier = np.abs(grid.basis(np.linspace(start - 1.0, start - 1e-6, 400))).max(axis=0) > 0
    assert kept.stop == active.stop
    assert not earlier[kept].any() and earlier[active.start:kept.start].all()


def test_fit_recovers_coefficients_and_evaluate_batches():
    grid = KnotGrid(0.1, 1.0)
    rng = np.random.default_rng(1)
    coefs = rng.normal(size=(grid.num_coefs, 48))
    t = np.arange(200) * 0.005
    basis = grid.basis(t)
    values = evaluate(basis, coefs)
    np.testing.assert_allclose(fit_coefficients(basis, values, ridge=1e-12), coefs, atol=1e-6)
    batch = np.stack([coefs, 2 * coefs])
    out = evaluate(basis, batch)
    assert out.shape == (2, 200, 48)
    np.testing.assert_allclose(out[1], 2 * values)


@pytest.mark.parametrize("grid", GRIDS, ids=lambda g: f"h{g.spacing}-d{g.duration}")
@pytest.mark.parametrize("derivative", [0, 1, 2])
def test_the_sparse_basis_holds_the_same_values(grid, derivative):
    t = np.linspace(0.0, grid.duration, 97)
    dense = grid.basis(t, derivative=derivative)
    sparse = grid.sparse_basis(t, derivative)
    assert sparse.nnz <= 4 * len(t)
    assert np.array_equal(sparse.toarray(), dense)


def test_a_long_clip_gets_the_sparse_basis_and_the_same_fit(monkeypatch):
    """Over minutes of steps the dense basis took gigabytes; clips of ordinary length keep it
    (and their digits)."""
    grid = KnotGrid(0.1, 3.0)
    t = np.arange(0.0, 3.0, 0.005)
    assert isinstance(grid.matrix(t), np.ndarray)
    monkeypatch.setattr("physpose.dynamics.spline.DENSE_ENTRIES", len(t) * grid.num_coefs - 1)
    sparse = grid.matrix(t)
    assert not isinstance(sparse, np.ndarray)
    values = np.stack([np.sin(3 * t), t ** 2], axis=1)
    np.testing.assert_allclose(fit_coefficients(sparse, values, ridge=1e-3),
                               fit_coefficients(grid.basis(t), values, ridge=1e-3), atol=1e-10)
    one = fit_coefficients(sparse, values[:, :1], ridge=1e-3)  # one column stays a column
    assert one.shape == (grid.num_coefs, 1)
