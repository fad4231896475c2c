"""The registry of pipeline variants the benchmark can run.

A variant is a function `(observations, context) -> Reconstruction`. Modules register theirs with
`register_variant(name, fn)` at import time; the registry imports every module named in
`PROVIDERS` the first time it is asked for a variant, so a later stage adds its variants by
adding one line there (or by importing its module before running the benchmark).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from physpose.errors import PhysposeError
from physpose.observations import Observations
from physpose.reconstruction import Reconstruction

# Modules that define variants (imported lazily, in this order). One line per stage.
PROVIDERS: list[str] = [
    "physpose.benchmark.baseline",
    "physpose.kinematics.variants",
    "physpose.dynamics.variants",
    "physpose.benchmark.oracle",
]


@dataclass(frozen=True, eq=False)
class VariantContext:
    """What a benchmark run may tell a variant besides the observations."""

    camera_K: np.ndarray | None = None            # (3, 3) known intrinsics, pixels
    camera_T_world2cam: np.ndarray | None = None  # (4, 4) known extrinsics (world z up, floor z=0)
    person_height: float | None = None            # m, the person's stature when known
    seed: int = 0                                 # for variants that sample
    # Oracle, for the diagnostic variants of benchmark/oracle.py only (MaterialConfig.truth_input):
    truth_landmarks: np.ndarray | None = None     # (T, 33, 3) the truth's landmarks, world, m
    truth_T_world2cam: np.ndarray | None = None   # (4, 4) the camera in the truth's world


VariantFn = Callable[[Observations, VariantContext], Reconstruction]
VARIANTS: dict[str, VariantFn] = {}
_loaded = False


def register_variant(name: str, fn: VariantFn) -> VariantFn:
    """Add a variant under `name` (an error if the name is taken by another function)."""
    if not name or any(c.isspace() for c in name):
        raise ValueError(f"invalid variant name {name!r}")
    if VARIANTS.get(name, fn) is not fn:
        raise ValueError(f"variant {name!r} is already registered by {VARIANTS[name]!r}")
    VARIANTS[name] = fn
    return fn


def _load_providers() -> None:
    global _loaded
    if not _loaded:
        for module in PROVIDERS:
            importlib.import_module(module)
        _loaded = True


def available_variants() -> tuple[str, ...]:
    """Names of every registered variant, in registration order."""
    _load_providers()
    return tuple(VARIANTS)


def get_variant(name: str) -> VariantFn:
    """The variant registered under `name`; PhysposeError listing the known names otherwise."""
    _load_providers()
    if name not in VARIANTS:
        raise PhysposeError(f"unknown variant {name!r}",
                            remedy=f"choose one of: {', '.join(VARIANTS) or '(none registered)'}")
    return VARIANTS[name]
