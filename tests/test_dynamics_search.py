"""CMA-ES strategies of the window search (`dynamics.search`)."""

from __future__ import annotations

import cma
import numpy as np

from physpose.dynamics.config import PRESETS
from physpose.dynamics.search import cma_strategy


def test_a_strategy_draws_the_same_samples_whatever_is_searched_beside_it():
    x0, cfg = np.zeros(12), PRESETS["fast"]
    alone = np.array(cma_strategy(x0, cfg, seed=5).ask())
    first = cma_strategy(x0, cfg, seed=5)
    other = cma_strategy(x0, cfg, seed=9)  # made after it, as a group's strategies are
    np.testing.assert_array_equal(np.array(first.ask()), alone)
    assert not np.allclose(np.array(other.ask()), alone)
    # Alone, it draws what pycma's seed option alone (NumPy's global stream) drew, so a
    # sequential run's windows keep their samples.
    seeded_globally = cma.CMAEvolutionStrategy(x0, cfg.sigma0, {
        "seed": 5, "popsize": cfg.popsize, "CMA_diagonal": bool(cfg.diagonal), "verbose": -9,
        "verb_log": 0, "verb_disp": 0})
    np.testing.assert_array_equal(np.array(seeded_globally.ask()), alone)
