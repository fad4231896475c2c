"""L-BFGS-B over a chosen subset of a parameter pytree, with JAX gradients (scipy drives it).

All frames are one problem: the objective is a jitted function of the whole parameter tuple,
the optimiser sees only the free fields flattened into one float64 vector.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from typing import NamedTuple

import numpy as np
import scipy.optimize


_ON_ITERATION: ContextVar[Callable[[], object] | None] = ContextVar("on_iteration", default=None)


@contextmanager
def reporting_iterations(callback: Callable[[], object]) -> Iterator[None]:
    """Within the block every `minimize` calls callback() after each L-BFGS iteration (a
    progress bar's update), however deep the step that calls it."""
    token = _ON_ITERATION.set(callback)
    try:
        yield
    finally:
        _ON_ITERATION.reset(token)


class Result(NamedTuple):
    params: NamedTuple
    value: float
    iterations: int
    evaluations: int
    message: str


def minimize(value_and_grad: Callable, params: NamedTuple, free: tuple[str, ...], *,
             bounds: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None,
             iterations: int = 300, tolerance: float = 1e-9) -> Result:
    """Minimise value_and_grad(params) -> (value, grads like params) over the `free` fields.

    bounds: field -> (lower, upper) arrays broadcastable to the field's shape.
    tolerance: relative decrease of the value below which L-BFGS-B stops (its ftol).
    """
    fields = params._fields
    unknown = set(free) - set(fields)
    if unknown:
        raise ValueError(f"unknown parameters {sorted(unknown)}")
    shapes = {f: np.shape(getattr(params, f)) for f in free}
    sizes = {f: int(np.prod(shapes[f], dtype=int)) for f in free}
    x0 = np.concatenate([np.ravel(np.asarray(getattr(params, f), dtype=float)) for f in free])

    def unpack(x: np.ndarray) -> NamedTuple:
        out, i = {}, 0
        for f in free:
            out[f] = x[i:i + sizes[f]].reshape(shapes[f])
            i += sizes[f]
        return params._replace(**out)

    def fun(x: np.ndarray) -> tuple[float, np.ndarray]:
        value, grads = value_and_grad(unpack(x))
        g = np.concatenate([np.ravel(np.asarray(getattr(grads, f), dtype=float)) for f in free])
        value = float(value)
        if not np.isfinite(value) or not np.isfinite(g).all():
            return np.inf, np.zeros_like(x)
        return value, g

    box = None
    if bounds:
        lo, hi = [], []
        for f in free:
            b = bounds.get(f)
            if b is None:
                lo.append(np.full(sizes[f], -np.inf))
                hi.append(np.full(sizes[f], np.inf))
            else:
                lo.append(np.ravel(np.broadcast_to(b[0], shapes[f])))
                hi.append(np.ravel(np.broadcast_to(b[1], shapes[f])))
        lo, hi = np.concatenate(lo), np.concatenate(hi)
        x0 = np.clip(x0, lo, hi)
        box = scipy.optimize.Bounds(lo, hi)
    report = _ON_ITERATION.get()
    res = scipy.optimize.minimize(fun, x0, jac=True, method="L-BFGS-B", bounds=box,
                                  callback=None if report is None else lambda _x: report(),
                                  options={"maxiter": iterations, "ftol": tolerance,
                                           "gtol": 1e-10, "maxcor": 10})
    return Result(params=unpack(res.x), value=float(res.fun), iterations=int(res.nit),
                  evaluations=int(res.nfev), message=str(res.message))
