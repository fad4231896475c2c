"""JAX's 64-bit mode for the kinematic fit: its L-BFGS runs stop short in single precision."""

from __future__ import annotations

import jax


def double_precision():
    """A context in which JAX computes in 64 bits: ``jax.enable_x64(True)`` from JAX 0.8, whose
    later releases removed the experimental context manager that older ones have. Contexts
    nest, so a stage that needs it may enter it inside a caller that already has."""
    if hasattr(jax, "enable_x64"):
        return jax.enable_x64(True)
    from jax.experimental import enable_x64
    return enable_x64()
