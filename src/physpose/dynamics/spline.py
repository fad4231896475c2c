"""Servo targets as uniform cubic B-splines over time: the variables the optimiser searches.

One spline per actuated hinge, all on one knot grid: coefficient k is centred at time
``k0 + (k - 1) * spacing`` and its basis function (the cubic B-spline of width 4 spacings)
reaches from ``(k - 3) * spacing`` to ``(k + 1) * spacing`` after ``k0``. Evaluating the splines
at fixed times is a fixed matrix product,

    targets = basis @ coefs          # (nsteps, ncoef) @ (ncoef, 48) -> (nsteps, 48)

so a batch of coefficient sets (B, ncoef, 48) becomes B control sequences with one matmul.
The basis is a partition of unity and reproduces linear functions (coefficients equal to the
function at the knot centres), so a constant or linear target needs no fitting.

Over a whole clip the basis has a row per simulation step and a column per knot, four of them
non-zero: dense, a three-minute clip's matrix alone took 0.5 GB and a ten-minute clip's would
take 6 GB. `KnotGrid.matrix` keeps it dense up to DENSE_ENTRIES, so that the clips of
ordinary length keep the digits they had, and sparse beyond.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

DENSE_ENTRIES = 10_000_000  # a minute of steps at 200 Hz against its 600 knots, about 80 MB


def cubic_bspline(x: np.ndarray, derivative: int = 0) -> np.ndarray:
    """The uniform cubic B-spline centred at 0 (support [-2, 2], peak 2/3 at 0) or its
    first or second derivative with respect to x."""
    x = np.asarray(x, dtype=float)
    a, sign = np.abs(x), np.sign(x)
    if derivative == 0:
        inner, outer = (4.0 - 6.0 * a ** 2 + 3.0 * a ** 3) / 6.0, (2.0 - a) ** 3 / 6.0
    elif derivative == 1:
        inner, outer = sign * (-2.0 * a + 1.5 * a ** 2), -sign * 0.5 * (2.0 - a) ** 2
    elif derivative == 2:
        inner, outer = -2.0 + 3.0 * a, 2.0 - a
    else:
        raise ValueError(f"derivative {derivative} not supported (0, 1 or 2)")
    return np.where(a < 1.0, inner, np.where(a < 2.0, outer, 0.0))


@dataclass(frozen=True, eq=False)
class KnotGrid:
    """Uniform knots every ``spacing`` seconds covering [0, duration] (clip time, seconds)."""

    spacing: float   # s between knots
    duration: float  # s covered

    def __post_init__(self) -> None:
        if not (self.spacing > 0 and self.duration >= 0):
            raise ValueError(f"knot spacing {self.spacing} must be > 0 and duration "
                             f"{self.duration} >= 0")

    @property
    def num_coefs(self) -> int:
        """Coefficients whose basis functions touch [0, duration]."""
        return int(np.ceil(self.duration / self.spacing - 1e-9)) + 3

    def centres(self) -> np.ndarray:
        """(ncoef,) time (s) of each coefficient's peak."""
        return (np.arange(self.num_coefs) - 1.0) * self.spacing

    def basis(self, times: np.ndarray, coefs: slice | None = None, derivative: int = 0
              ) -> np.ndarray:
        """(len(times), ncoef) basis matrix (or its time derivative, per s or s^2),
        optionally restricted to a coefficient range."""
        t = np.asarray(times, dtype=float)[:, None] / self.spacing
        k = np.arange(self.num_coefs)[None, :] - 1.0
        b = cubic_bspline(t - k, derivative) / self.spacing ** derivative
        return b if coefs is None else b[:, coefs]

    def sparse_basis(self, times: np.ndarray, derivative: int = 0) -> scipy.sparse.csr_matrix:
        """basis(times, derivative=...) as a sparse matrix: the four coefficients whose
        basis functions reach each time, the same values."""
        t = np.asarray(times, dtype=float) / self.spacing
        cols = np.floor(t).astype(int)[:, None] + np.arange(4)[None, :]  # k - 1 within t +- 2
        values = cubic_bspline(t[:, None] - (cols - 1.0), derivative) / self.spacing ** derivative
        inside = (cols >= 0) & (cols < self.num_coefs)
        rows = np.broadcast_to(np.arange(len(t))[:, None], cols.shape)
        return scipy.sparse.csr_matrix((values[inside], (rows[inside], cols[inside])),
                                       shape=(len(t), self.num_coefs))

    def matrix(self, times: np.ndarray, derivative: int = 0
               ) -> np.ndarray | scipy.sparse.csr_matrix:
        """The basis over a whole clip: dense up to DENSE_ENTRIES entries, sparse beyond."""
        if len(times) * self.num_coefs <= DENSE_ENTRIES:
            return self.basis(times, derivative=derivative)
        return self.sparse_basis(times, derivative)

    def active(self, start: float, end: float) -> slice:
        """Coefficients whose basis is non-zero somewhere in the open interval (start, end)."""
        lo = int(np.floor(start / self.spacing + 1e-9))     # first k with (k+1)h > start
        hi = int(np.ceil(end / self.spacing - 1e-9)) + 3    # first k with (k-3)h >= end
        return slice(max(lo, 0), min(hi, self.num_coefs))

    def started_before(self, time: float) -> int:
        """Index of the first coefficient whose basis is zero at every time before ``time``."""
        return max(0, min(int(np.ceil(time / self.spacing - 1e-9)) + 3, self.num_coefs))

    def searched(self, start: float, end: float, continued: bool) -> slice:
        """Coefficients that a window over (start, end) searches: those active in it, less
        those begun before ``start`` when it continues the window before (kept as found)."""
        active = self.active(start, end)
        first = self.started_before(start) if continued else 0
        return slice(max(active.start, first), active.stop)


def evaluate(basis: np.ndarray, coefs: np.ndarray) -> np.ndarray:
    """Targets from coefficients: basis (S, K), coefs (..., K, D) -> (..., S, D)."""
    return np.matmul(basis, coefs)


def fit_coefficients(basis: np.ndarray, values: np.ndarray, ridge: float = 1e-6,
                     prior: np.ndarray | None = None) -> np.ndarray:
    """Least-squares coefficients (K, D) whose spline best matches values (S, D) at the basis rows.

    ``ridge`` pulls coefficients that the samples hardly constrain towards ``prior`` (K, D)
    (zero when None), which keeps the fit defined at the ends of the grid. basis may be
    sparse (`KnotGrid.matrix`).
    """
    values = np.asarray(values, dtype=float)
    k = basis.shape[1]
    prior = np.zeros((k, values.shape[1])) if prior is None else np.asarray(prior, dtype=float)
    if scipy.sparse.issparse(basis):
        lhs = (basis.T @ basis + ridge * scipy.sparse.identity(k)).tocsc()
        # spsolve returns a 1-d array for a single right-hand side: keep (K, D).
        return scipy.sparse.linalg.spsolve(lhs, basis.T @ values + ridge * prior).reshape(k, -1)
    basis = np.asarray(basis, dtype=float)
    lhs = basis.T @ basis + ridge * np.eye(k)
    rhs = basis.T @ values + ridge * prior
    return np.linalg.solve(lhs, rhs)
