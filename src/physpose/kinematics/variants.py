"""The kinematic variants as benchmark variants ("S", "SO", "SO+G", "SO+T", "SO+GT").

Registered when this module is imported (listed in physpose.benchmark.variants.PROVIDERS).
A benchmark context's known intrinsics and person height are passed on; known extrinsics are
not used (the variants estimate the ground themselves, which is what +G is scored on).
"""

from __future__ import annotations

import numpy as np

from physpose.benchmark.variants import VariantContext, register_variant
from physpose.body import build_body
from physpose.kinematics.config import VARIANT_NAMES, KinematicConfig
from physpose.kinematics.fit import fit_kinematics
from physpose.kinematics.result import KinematicFit
from physpose.observations import Observations
from physpose.reconstruction import Reconstruction


def reconstruction_of(fit: KinematicFit, obs: Observations) -> Reconstruction:
    """The reconstruction.npz contract of a fit (physics keys absent), with the body's MJCF
    and what the overlay needs (image size) in meta."""
    rec = fit.to_reconstruction(obs, build_body(fit.shape).xml)
    meta = dict(rec.meta, image_size=list(obs.image_size),
                timings_s={k: float(v) for k, v in fit.timings.items()})
    return rec.replace(meta=meta)


def kinematic_variant(name: str):
    """The benchmark function of one variant."""
    config = KinematicConfig.preset(name)

    def run(obs: Observations, context: VariantContext) -> Reconstruction:
        K = None if context.camera_K is None else np.asarray(context.camera_K, dtype=float)
        fit = fit_kinematics(obs, config, height=context.person_height, camera_K=K)
        return reconstruction_of(fit, obs)

    run.__name__ = f"kinematics_{name.replace('+', '_')}"
    return run


for _name in VARIANT_NAMES:
    register_variant(_name, kinematic_variant(_name))
