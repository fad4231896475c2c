"""The dynamics configuration: presets, ablations and refused settings."""

from __future__ import annotations

import dataclasses
import math
import os
from types import SimpleNamespace

import pytest

from physpose.dynamics import ABLATIONS, PRESETS, DynamicsConfig, ablated
from physpose.dynamics.config import REFINE_COUNTERPARTS, available_cores
from physpose.dynamics.objective import ObjectiveWeights
from physpose.dynamics.variants import (EVERY_ATTEMPT, FULL_OBJECTIVE, NO_HOPELESS_RETRY,
                                        SEARCH_ONLY)
from physpose.errors import PhysposeError


def test_presets_and_ablations():
    assert PRESETS["paper"].popsize == 100 and PRESETS["paper"].iterations == 2000
    assert PRESETS["paper"].window == 1.0
    # The paper preset keeps the paper's weights (no swing term); the fast one drops the COM
    # term and adds the swing term.
    assert PRESETS["paper"].weights.as_dict() == ObjectiveWeights().as_dict()
    assert ObjectiveWeights().swing == 0.0
    assert PRESETS["fast"].weights.com == 0.0 and PRESETS["fast"].weights.pose == 0.5
    assert PRESETS["fast"].weights.swing > 0
    # The fast preset refines each window by iLQR after its search; the paper's has no
    # refinement, nor do the search-alone ablations of the paper's full objective.
    assert PRESETS["fast"].refine.enabled and not PRESETS["paper"].refine.enabled
    # Since stop 40 the fast preset's refinement also pulls the landmarks onto the detections.
    assert PRESETS["fast"].refine.image > 0
    # Since stop 79 the fast preset also cuts where the simulated head falls below the
    # estimate's, as far as the COM may stray; the paper preset cuts on the COM alone.
    assert PRESETS["fast"].fall_distance == PRESETS["fast"].reset_distance
    assert PRESETS["paper"].fall_distance == math.inf
    assert SEARCH_ONLY == dataclasses.replace(PRESETS["fast"], refine=SEARCH_ONLY.refine,
                                              retries=2)
    assert not SEARCH_ONLY.refine.enabled
    assert FULL_OBJECTIVE == dataclasses.replace(SEARCH_ONLY, weights=ObjectiveWeights())
    for name, terms in ABLATIONS.items():
        w = ablated(FULL_OBJECTIVE, name).weights
        for term in terms:
            assert getattr(w, term) == 0.0
        assert sum(getattr(w, t) > 0 for t in ("com", "pose", "reprojection", "prior")) \
            == 4 - len(terms)
    with pytest.raises(PhysposeError):
        ablated(PRESETS["fast"], "nothing")
    with pytest.raises(PhysposeError):
        DynamicsConfig(overlap=2.0)
    with pytest.raises(PhysposeError, match="knot spacing"):
        DynamicsConfig(window=0.05, overlap=0.0, knot_spacing=0.1)
    with pytest.raises(PhysposeError):
        DynamicsConfig(search="arms")
    with pytest.raises(PhysposeError):
        DynamicsConfig(candidates=0)


def test_ablating_the_refined_default_removes_the_refinements_counterparts():
    fast = PRESETS["fast"]
    no2d = ablated(fast, "no2d")
    assert no2d.weights.reprojection == 0 and no2d.refine.image == 0
    assert no2d.refine.hinge == fast.refine.hinge and no2d.refine.iterations == 6
    no3d = ablated(fast, "no3d")
    assert no3d.refine.hinge == no3d.refine.root_orientation == no3d.refine.hinge_velocity == 0
    assert no3d.refine.image == fast.refine.image and no3d.refine.root_position > 0
    nocom = ablated(fast, "nocom")
    assert nocom.refine.root_position == nocom.refine.root_velocity == 0
    assert nocom.refine.hinge == fast.refine.hinge
    # The prior has no counterpart; the search alone keeps its (switched off) refinement as is.
    assert ablated(fast, "noprior").refine == fast.refine
    assert ablated(FULL_OBJECTIVE, "no2d").refine == FULL_OBJECTIVE.refine
    assert set(REFINE_COUNTERPARTS) == {t for terms in ABLATIONS.values() for t in terms}


def test_rollouts_use_every_core_by_default():
    """The thread count changes only the time (benchmarks/bench_threads.py checks the result
    bit for bit), so it defaults to every core this process may use, not a fixed 2."""
    cores = available_cores()
    assert cores >= 1 and DynamicsConfig().nthread == cores
    if hasattr(os, "sched_getaffinity"):
        assert cores == len(os.sched_getaffinity(0))
    assert "nthread" not in DynamicsConfig().identity()


def test_window_identity_leaves_out_what_does_not_change_the_windows():
    base = PRESETS["fast"]
    same = dataclasses.replace(base, candidates=3, place_stretches=False, nthread=1)
    assert same.window_identity() == base.window_identity()
    assert dataclasses.replace(base, seed=1).window_identity() != base.window_identity()
    assert "place_stretches" in base.identity()  # still recorded with the result


def test_a_zero_swing_weight_keeps_the_keys_from_before_the_term():
    """Runs without the swing term keep their checkpoints: the weight is left out at 0."""
    assert "swing" not in FULL_OBJECTIVE.identity()["weights"]
    assert set(FULL_OBJECTIVE.identity()["weights"]) == {"com", "pose", "reprojection", "prior",
                                                          "tv", "lim"}
    assert PRESETS["fast"].identity()["weights"]["swing"] == PRESETS["fast"].weights.swing


def test_swing_confidence_is_in_the_key_only_where_it_changes_the_runs():
    """Switched off, or without a swing term, the runs are those from before the setting."""
    fast = PRESETS["fast"]
    assert fast.swing_confidence and fast.identity()["swing_confidence"] is True
    assert "swing_confidence" not in dataclasses.replace(fast, swing_confidence=False).identity()
    assert "swing_confidence" not in FULL_OBJECTIVE.identity()


def test_refine_within_is_in_the_key_only_where_it_changes_the_runs():
    fast = PRESETS["fast"]
    assert fast.identity()["refine_within"] == fast.refine_within < math.inf
    every = dataclasses.replace(fast, refine_within=math.inf)
    assert "refine_within" not in every.identity()  # stop 40's runs and checkpoints
    assert "refine_within" not in DynamicsConfig().identity()  # no refinement at all
    with pytest.raises(PhysposeError, match="refine_within"):
        DynamicsConfig(refine_within=0.0)


def test_start_sight_smoothing_is_in_the_key_only_where_it_changes_the_runs():
    off = DynamicsConfig()
    assert "start_sight_smoothing" not in off.identity()  # the runs from before stop 48
    on = dataclasses.replace(off, start_sight_smoothing=0.25)
    assert on.identity()["start_sight_smoothing"] == 0.25
    with pytest.raises(PhysposeError, match="start_sight_smoothing"):
        DynamicsConfig(start_sight_smoothing=-0.1)
    # Neither preset low-passes the start's depth speed (measured in stop 48, not kept).
    assert PRESETS["fast"].start_sight_smoothing == PRESETS["paper"].start_sight_smoothing == 0


def test_retry_within_is_in_the_key_only_where_it_changes_the_runs():
    fast = PRESETS["fast"]
    hopeless = dataclasses.replace(fast, retry_within=0.5)
    assert hopeless.identity()["retry_within"] == 0.5
    assert "retry_within" not in dataclasses.replace(fast, retry_within=math.inf).identity()
    assert "retry_within" not in dataclasses.replace(hopeless, retries=0).identity()
    with pytest.raises(PhysposeError, match="retry_within"):
        DynamicsConfig(retry_within=-1.0)


def test_the_fast_preset_retries_once_and_the_earlier_variants_twice():
    assert PRESETS["fast"].retries == 1
    assert EVERY_ATTEMPT.retries == 2 and EVERY_ATTEMPT.refine_within == math.inf
    assert EVERY_ATTEMPT.refine == PRESETS["fast"].refine


def test_the_presets_retry_hopeless_windows_and_a_variant_does_not():
    """retry_within 0.5 m was measured (stop 42) and not kept: the presets, and so the
    variants measured before, retry whatever the miss (their checkpoint keys unchanged)."""
    for config in (*PRESETS.values(), EVERY_ATTEMPT, SEARCH_ONLY, FULL_OBJECTIVE):
        assert config.retry_within == math.inf and "retry_within" not in config.identity()
    assert NO_HOPELESS_RETRY == dataclasses.replace(PRESETS["fast"], retry_within=0.5)


class _Stop(Exception):
    """Raised by the stubbed optimiser once it has recorded what it was given."""


@pytest.fixture
def stubbed_dynamics(monkeypatch):
    """The dynamics variants with the kinematic fit and the optimiser stubbed out: the fit
    records its variant name in ``fitted``, the optimiser its config and the body's time step
    in ``seen``, then raises _Stop."""
    import physpose.dynamics.variants as dynamics_variants
    import physpose.kinematics.fit as kinematics_fit
    from physpose.benchmark import oracle
    from physpose.shape import BodyShape

    stub = SimpleNamespace(seen=[], fitted=[])
    kin = SimpleNamespace(shape=BodyShape.from_height(1.7))

    def fit(obs, config, **kwargs):
        stub.fitted.append(config.variant)
        return kin

    def optimise(body, kin, obs, config, progress):
        stub.seen.append((config, body.model.opt.timestep))
        raise _Stop

    monkeypatch.setattr(kinematics_fit, "fit_kinematics", fit)
    monkeypatch.setattr(oracle, "_timed_truth_fit", lambda *args: (kin, 0.0))
    monkeypatch.setattr(dynamics_variants, "optimize_dynamics", optimise)
    return stub


def test_the_benchmark_seed_reaches_the_search_and_seed_0_changes_nothing(stubbed_dynamics):
    """`physpose benchmark --seed N` (VariantContext.seed) offsets the CMA-ES seed of the
    dynamics variants as well as drawing the detector noise; under seed 0 the configs, and so
    their checkpoint keys, are those measured before it did."""
    import physpose.dynamics.variants as dynamics_variants
    from physpose.benchmark import VariantContext, get_variant

    for name in ("dynamics", "dynamics-truth", "dynamics-10ms"):
        for seed in (0, 3):
            with pytest.raises(_Stop):
                get_variant(name)(None, VariantContext(seed=seed))
    seen = stubbed_dynamics.seen
    fast, ten_ms = PRESETS["fast"], dynamics_variants.TEN_MS_STEPS
    assert seen == [(fast, 0.005), (dataclasses.replace(fast, seed=3), 0.005)] * 2 + [
        (ten_ms, 0.01), (dataclasses.replace(ten_ms, seed=3), 0.01)]
    assert ten_ms.refine.derivative_stride == 1 and fast.refine.derivative_stride == 2


def test_the_paper_variant_runs_the_paper_preset(stubbed_dynamics):
    """`--variant dynamics-paper` optimises the SO+GT fit with the paper's budget."""
    from physpose.benchmark import VariantContext, get_variant

    with pytest.raises(_Stop):
        get_variant("dynamics-paper")(None, VariantContext())
    seen = [config for config, _ in stubbed_dynamics.seen]
    assert seen == [PRESETS["paper"]] and seen[0].iterations == 2000 and seen[0].popsize == 100
    assert stubbed_dynamics.fitted == ["SO+GT"]
