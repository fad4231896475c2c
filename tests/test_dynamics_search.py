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
    # Its first samples are what pycma's seed option alone (NumPy's global stream) drew.
    seeded_globally = cma.CMAEvolutionStrategy(x0, cfg.sigma0, {
        "seed": 5, "popsize": cfg.popsize, "CMA_diagonal": bool(cfg.diagonal), "verbose": -9,
        "verb_log": 0, "verb_disp": 0})
    np.testing.assert_array_equal(np.array(seeded_globally.ask()), alone)


def test_a_strategy_draws_the_same_samples_whatever_else_draws_from_numpy_in_between():
    # With 300 or more coordinates pycma's step-size rule (two-point adaptation) itself takes
    # random coordinates from NumPy's global stream after the fourth iteration; neither that
    # nor anyone else's draws may change the samples.
    x0, cfg = np.zeros(320), PRESETS["fast"]

    def samples(foreign_draws: bool) -> np.ndarray:
        es = cma_strategy(x0, cfg, seed=5)
        drawn = []
        for _ in range(8):
            pop = np.array(es.ask())
            drawn.append(pop)
            if foreign_draws:
                np.random.randint(0, 10, size=7)
            es.tell(list(pop), [float(np.sum((p - 0.3) ** 2)) for p in pop])
        return np.array(drawn)

    np.testing.assert_array_equal(samples(True), samples(False))
