"""Benchmark variants of the dynamics stage (registered with physpose.benchmark).

``dynamics``: the paper's HUND+SO+GT + Dynamics analogue (SO+GT kinematics, then the
trajectory optimisation with the default preset); ``dynamics-so``: on the SO kinematics;
``dynamics-paper``: the paper preset (its full budget);
``dynamics-full``: the default preset with the paper's objective terms and weights (the
default has no COM term and adds the swing term); ``dynamics-<ablation>`` (no2d, no3d, nocom,
nocompose, noprior): the bottom half of the paper's Table 2, that full model with objective
terms removed (the search alone, as before stop 37); ``dynamics-default-<ablation>``: the
default preset with the same terms removed from the search and from its refinement, and
``dynamics-default-com``: the default with the paper's COM term added. ``dynamics-10ms``: the
default preset on 10 ms simulation steps instead of 5 ms (stop 43, not kept).
``dynamics-search``, ``dynamics-refine-every``, ``dynamics-refine-noimage``, ``dynamics-ilqr``
and ``dynamics-ilqr-image``: the search alone (no iLQR refinement), the
default of stop 40 (two retries, every attempt of a window refined), the refinement as it was
before stop 40 (no image term), and iLQR instead of the search; all with two retries, as
measured before stop 41. ``dynamics-no-hopeless-retry``: the default without a retry after a
first search that misses by more than 0.5 m (stop 42). ``dynamics-reference``: no physics, the
SO+GT estimate as the default preset's windows are asked to follow it (on the floor, standing
feet flat, low-passed; stop 60). The benchmark's ``--seed`` offsets every
variant's CMA-ES seed (``seeded``). Window checkpoints go to the stage cache, so an interrupted
benchmark resumes its dynamics runs.
"""

from __future__ import annotations

import dataclasses
import math
import time

from physpose.benchmark.variants import VariantContext, register_variant
from physpose.body import BodyConfig, build_body
from physpose.dynamics.objective import ObjectiveWeights
from physpose.dynamics.config import ABLATIONS, PRESETS, DynamicsConfig, ablated
from physpose.dynamics.ilqr import RefineConfig
from physpose.dynamics.optimize import optimize_dynamics, reference_motion
from physpose.fk import fk_qpos
from physpose.kinematics.config import KinematicConfig
from physpose.kinematics.result import KinematicFit
from physpose.observations import Observations
from physpose.reconstruction import Reconstruction


def seeded(config: DynamicsConfig, context: VariantContext) -> DynamicsConfig:
    """The config with its CMA-ES seed offset by the benchmark's seed (``--seed``), which also
    draws the detector simulator's noise. Seed 0 leaves the config, and its checkpoint keys, as
    they were."""
    return dataclasses.replace(config, seed=config.seed + context.seed)


def _timed_fit(obs: Observations, context: VariantContext, kinematic_variant: str
               ) -> tuple[KinematicFit, float]:
    """The named variant's kinematic fit (the intrinsics and stature the benchmark gives)
    and the seconds it took."""
    from physpose.kinematics.fit import fit_kinematics  # noqa: PLC0415 (heavy JAX import)

    start = time.perf_counter()
    kin = fit_kinematics(obs, KinematicConfig.preset(kinematic_variant),
                         camera_K=context.camera_K, height=context.person_height)
    return kin, time.perf_counter() - start


def run_dynamics_variant(obs: Observations, context: VariantContext, kinematic_variant: str,
                         config: DynamicsConfig, name: str,
                         body_config: BodyConfig = BodyConfig()) -> Reconstruction:
    """Kinematic fit of the named variant, then dynamics; both fields in the reconstruction."""
    kin, kinematics_s = _timed_fit(obs, context, kinematic_variant)
    return simulate_fit(kin, kinematics_s, obs, context, config, name, body_config)


def simulate_fit(kin: KinematicFit, kinematics_s: float, obs: Observations,
                 context: VariantContext, config: DynamicsConfig, name: str,
                 body_config: BodyConfig = BodyConfig()) -> Reconstruction:
    """Dynamics on a kinematic fit that took kinematics_s seconds (the benchmark's ``--seed``
    offsetting the CMA-ES seed); both fields in the reconstruction, meta naming the variant."""
    body = build_body(kin.shape, config=body_config)
    phys = optimize_dynamics(body, kin, obs, seeded(config, context), progress=False)
    recon = kin.to_reconstruction(obs, body_mjcf=body.xml)
    meta = dict(recon.meta, variant=name, dynamics=phys.meta(),
                timings_s={"kinematics": kinematics_s, "dynamics": phys.timings["total"]})
    return recon.replace(**phys.reconstruction_fields(), meta=meta)


def reference_fit(kin: KinematicFit, kinematics_s: float, obs: Observations,
                  config: DynamicsConfig, name: str) -> Reconstruction:
    """The motion the physics is asked to follow (``optimize.reference_motion``) as a
    kinematic reconstruction of a fit that took kinematics_s seconds: what the physics
    stage's preparation alone does to ``kin``."""
    start = time.perf_counter()
    body = build_body(kin.shape)
    qpos = reference_motion(body, kin, obs, config)
    joints, landmarks = fk_qpos(kin.shape.bones(), qpos)
    moved = dataclasses.replace(kin, qpos=qpos, joints=joints, landmarks=landmarks)
    recon = moved.to_reconstruction(obs, body_mjcf=body.xml)
    meta = dict(recon.meta, variant=name,
                timings_s={"kinematics": kinematics_s, "reference": time.perf_counter() - start})
    return recon.replace(meta=meta)


def reference_variant(obs: Observations, context: VariantContext) -> Reconstruction:
    """The SO+GT estimate as the default preset's windows are asked to follow it (no physics)."""
    kin, kinematics_s = _timed_fit(obs, context, "SO+GT")
    return reference_fit(kin, kinematics_s, obs, PRESETS["fast"], "dynamics-reference")


def _variant(kinematic_variant: str, config: DynamicsConfig, name: str,
             body_config: BodyConfig = BodyConfig()):
    def fn(obs: Observations, context: VariantContext) -> Reconstruction:
        return run_dynamics_variant(obs, context, kinematic_variant, config, name, body_config)

    fn.__name__ = fn.__qualname__ = name.replace("-", "_")
    return fn


# The search alone (the fast preset before stop 37, without the iLQR refinement; two retries,
# as the fast preset had until stop 41).
SEARCH_ONLY = dataclasses.replace(PRESETS["fast"], refine=RefineConfig(iterations=0), retries=2)
# The ablations (the paper's Table 2) on the search alone, with the paper's weights: stop 20's
# table, from before the refinement became the default (the refined default's are below).
FULL_OBJECTIVE = dataclasses.replace(SEARCH_ONLY, weights=ObjectiveWeights())

register_variant("dynamics", _variant("SO+GT", PRESETS["fast"], "dynamics"))
register_variant("dynamics-reference", reference_variant)
register_variant("dynamics-so", _variant("SO", PRESETS["fast"], "dynamics-so"))
# The paper's budget (2000 iterations x 100 samples per window): 11-24 min per window
# measured on 2-core machines, so for a short clip or a larger machine.
register_variant("dynamics-paper", _variant("SO+GT", PRESETS["paper"], "dynamics-paper"))
register_variant("dynamics-search", _variant("SO+GT", SEARCH_ONLY, "dynamics-search"))
register_variant("dynamics-full", _variant("SO+GT", FULL_OBJECTIVE, "dynamics-full"))
for _ablation in ABLATIONS:
    _name = f"dynamics-{_ablation}"
    register_variant(_name, _variant("SO+GT", ablated(FULL_OBJECTIVE, _ablation), _name))

# The same table on the default preset, refinement on (stop 45): each ablation removes the
# search's terms and their counterparts in the refinement's tracking cost
# (config.REFINE_COUNTERPARTS); ``dynamics-default-com`` adds the paper's COM term (weight 15),
# which the default leaves out, so that it and the ablations bracket the default.
for _ablation in ABLATIONS:
    _name = f"dynamics-default-{_ablation}"
    register_variant(_name, _variant("SO+GT", ablated(PRESETS["fast"], _ablation), _name))
WITH_COM = dataclasses.replace(PRESETS["fast"], weights=dataclasses.replace(
    PRESETS["fast"].weights, com=ObjectiveWeights().com))
register_variant("dynamics-default-com", _variant("SO+GT", WITH_COM, "dynamics-default-com"))

# The fast preset of stop 40: two retries, every attempt of a window refined (not only those
# that could come within the retry distance, and the kept one).
EVERY_ATTEMPT = dataclasses.replace(PRESETS["fast"], refine_within=math.inf, retries=2)
register_variant("dynamics-refine-every", _variant("SO+GT", EVERY_ATTEMPT,
                                                   "dynamics-refine-every"))

# The fast preset without a retry after a first search that misses by more than 0.5 m
# (stop 42; not kept: docs/dynamics.md, Hopeless windows).
NO_HOPELESS_RETRY = dataclasses.replace(PRESETS["fast"], retry_within=0.5)
register_variant("dynamics-no-hopeless-retry", _variant("SO+GT", NO_HOPELESS_RETRY,
                                                        "dynamics-no-hopeless-retry"))

# The fast preset on 10 ms simulation steps (the body's default is 5 ms, the paper's 200 Hz),
# the iLQR refinement linearised every step, so every 10 ms as on 5 ms steps (stop 43; not
# kept: the feet slid in more frames for 0.82x the time; docs/dynamics.md, The simulation step).
TEN_MS_BODY = BodyConfig(timestep=0.01)
TEN_MS_STEPS = dataclasses.replace(PRESETS["fast"], refine=dataclasses.replace(
    PRESETS["fast"].refine, derivative_stride=1))
register_variant("dynamics-10ms", _variant("SO+GT", TEN_MS_STEPS, "dynamics-10ms", TEN_MS_BODY))

# The fast preset from stop 37 to 39: its refinement tracked the reference without the image
# term (root position 1e3).
_TRACKING_REFINE = RefineConfig(iterations=6)
register_variant("dynamics-refine-noimage", _variant("SO+GT", dataclasses.replace(
    EVERY_ATTEMPT, refine=_TRACKING_REFINE), "dynamics-refine-noimage"))

# iLQR instead of the search (ilqr.py): six iterations without CMA-ES iterations, on the
# tracking cost alone or with the image term (the fast preset's refinement since stop 40).
_ILQR = dataclasses.replace(EVERY_ATTEMPT, iterations=0)
register_variant("dynamics-ilqr", _variant("SO+GT", dataclasses.replace(
    _ILQR, refine=_TRACKING_REFINE), "dynamics-ilqr"))
register_variant("dynamics-ilqr-image", _variant("SO+GT", dataclasses.replace(
    _ILQR, refine=RefineConfig(iterations=6, root_position=100.0, image=3e3)),
    "dynamics-ilqr-image"))
