"""CMA-ES search of window problems: batched rollouts of every problem's samples together.

A window problem (windows.py) is searched from the best of its start guesses; each iteration
asks every strategy for its samples, rolls them all out in one batch and scores them. With
``searches`` > 1 each problem is searched that many times side by side under other seeds and
the average of the results is kept where it scores no worse (see ``search_averaged``).
"""

from __future__ import annotations

import sys
import time
import warnings
from dataclasses import dataclass

import cma
import numpy as np
from tqdm import tqdm

from physpose.dynamics.config import DynamicsConfig
from physpose.dynamics.objective import ObjectiveReference
from physpose.dynamics.rollout import Simulator, Trajectories
from physpose.dynamics.windows import WindowProblem, ranked_fitness, score


def cma_strategy(x0: np.ndarray, cfg: DynamicsConfig, seed: int) -> cma.CMAEvolutionStrategy:
    """pycma's strategy from x0 for ``cfg.iterations`` (separable when ``cfg.diagonal``), its
    own stopping tests and output off: the loop stops it.

    Its samples come from a random stream of its own: pycma's ``seed`` alone reseeds NumPy's
    global stream, which strategies asked in turn would share, so a window's samples would
    depend on which other windows were searched beside it (independent windows, side-by-side
    searches) and a resumed run would draw differently. The stream starts where ``seed`` puts
    the global one, so the first four iterations draw what the shared stream drew. After them,
    pycma's two-point step-size rule (its choice for 300 or more coordinates: the fast preset's
    1 s windows searched from the estimate's state have 312, continued ones 240) takes coordinates
    for a consistency check from the global stream, which the shared stream's samples then
    followed and these do not: since stop 83 such searches draw other samples than before it
    (docs/dynamics_history.md, stop 85)."""
    opts = {"seed": seed, "randn": np.random.RandomState(seed).randn, "popsize": cfg.popsize,
            "CMA_diagonal": bool(cfg.diagonal), "verbose": -9, "verb_log": 0, "verb_disp": 0,
            "maxiter": max(cfg.iterations, 1), "tolfun": 0.0, "tolx": 0.0, "tolfunhist": 0.0,
            "tolflatfitness": 10 ** 9, "tolstagnation": 10 ** 9}
    return cma.CMAEvolutionStrategy(x0.ravel(), cfg.sigma0, opts)


def window_seed(seed: int, index: int) -> int:
    """CMA-ES seed of a window (pycma treats 0 as 'from the clock', so never 0)."""
    return (seed * 1_000_003 + index) % (2 ** 31 - 1) + 1


@dataclass
class Best:
    """The best sample of a search so far: its coefficients, scores and trajectory."""

    x: np.ndarray
    loss: float       # objective (+inf when the sample left the valid state space)
    fitness: float    # ranked fitness (finite)
    valid: bool
    terms: dict
    states: np.ndarray
    sensors: np.ndarray
    ctrl: np.ndarray  # (S, 48) servo targets applied, balance feedback included


def _rows(traj: Trajectories, rows: slice, steps: int) -> Trajectories:
    """The trajectories of one problem's samples (rows of a shared batch), its steps only."""
    return Trajectories(states=traj.states[rows, :steps + 1],
                        sensors=traj.sensors[rows, :steps + 1],
                        broken=traj.broken[rows, :steps + 1], ctrl=traj.ctrl[rows, :steps])


class WindowSearch:
    """CMA-ES on a group of window problems in lockstep, sharing batched rollouts."""

    def __init__(self, problems: list[WindowProblem], simulator: Simulator,
                 objective: ObjectiveReference, cfg: DynamicsConfig, timing: dict):
        self.problems, self.simulator, self.cfg = problems, simulator, cfg
        self.objective = objective
        self.timing = timing
        self.evaluations = [0] * len(problems)

    def evaluate(self, problems: list[WindowProblem], xs: list[np.ndarray]) -> list[tuple]:
        """(scores, trajectories) of the samples xs[i] (B_i, n) of problems[i], one rollout."""
        t0 = time.perf_counter()
        ctrls = [p.ctrl(x) for p, x in zip(problems, xs)]
        longest = max(c.shape[1] for c in ctrls)
        ctrl = np.concatenate([np.concatenate([c, np.repeat(c[:, -1:], longest - c.shape[1], 1)],
                                              axis=1) for c in ctrls])
        state0 = np.concatenate([np.repeat(p.state0[None], len(x), 0)
                                 for p, x in zip(problems, xs)])
        ends = np.cumsum([len(x) for x in xs])
        rows = [slice(int(e) - len(x), int(e)) for e, x in zip(ends, xs)]  # each problem's
        feedback = [(r, p.balance) for p, r in zip(problems, rows) if p.balance is not None]
        traj = self.simulator.run(state0, ctrl, feedback)
        t1 = time.perf_counter()
        out = []
        for p, r in zip(problems, rows):
            part = _rows(traj, r, p.window.num_steps)
            scores, _ = score(p, part, self.objective, self.cfg.weights,
                              self.cfg.max_root_distance, self.cfg.max_penetration)
            out.append((scores, part))
        self.timing["rollout"] = self.timing.get("rollout", 0.0) + t1 - t0
        self.timing["objective"] = self.timing.get("objective", 0.0) + time.perf_counter() - t1
        return out

    @staticmethod
    def keep_better(best: Best | None, x: np.ndarray, scores, part: Trajectories,
                    fitness: np.ndarray) -> Best:
        """Keep the lowest ranked fitness seen (valid samples before invalid ones)."""
        k = int(np.argmin(fitness))
        if best is not None and fitness[k] >= best.fitness:
            return best
        return Best(x=np.array(x[k]), loss=float(scores.total[k]), fitness=float(fitness[k]),
                    valid=bool(np.isfinite(scores.total[k])),
                    terms={n: float(v[k]) for n, v in scores.terms.items()},
                    states=part.states[k].copy(), sensors=part.sensors[k].copy(),
                    ctrl=part.ctrl[k].copy())

    def run(self, seeds: list[int], label: str, progress: bool, force_start: int | None = None
            ) -> tuple[list[Best], list[dict]]:
        """Search every problem; returns the best sample of each and its initial record.

        The search starts from the best-scoring start guess, or from start ``force_start``
        (0: the problem's own, k: its k-th alternative) where a problem has it.

        Each iteration also rolls out every strategy's current mean (not told to CMA-ES):
        the mean is the smoothest candidate and often the best.
        """
        frames = [len(p.positions) for p in self.problems]
        # Start guesses: each problem's own start and its alternative start controls, one
        # rollout each; the search goes on from the best (its problem replaces the original).
        groups = [[p] + [p.starting_from(a) for a in p.alternatives] for p in self.problems]
        flat = [c for g in groups for c in g]
        evaluated = self.evaluate(flat, [c.x0.reshape(1, -1) for c in flat])
        best: list[Best | None] = [None] * len(self.problems)
        initial, row = [], 0
        for i, group in enumerate(groups):
            fitness = np.array([ranked_fitness(s, frames[i])[0] for s, _ in
                                evaluated[row:row + len(group)]])
            k = int(np.argmin(fitness))
            if force_start is not None and force_start < len(group):
                k = force_start
            s, part = evaluated[row + k]
            self.problems[i] = group[k]
            self.evaluations[i] = len(group)
            best[i] = self.keep_better(None, group[k].x0.reshape(1, -1), s, part,
                                       fitness[k:k + 1])
            s0 = evaluated[row][0]
            initial.append({"loss": float(s0.total[0]), "valid": bool(np.isfinite(s0.total[0])),
                            "terms": {n: float(v[0]) for n, v in s0.terms.items()}, "start": k})
            row += len(group)
        strategies = [cma_strategy(b.x, self.cfg, seed) for b, seed in zip(best, seeds)]
        bar = tqdm(total=self.cfg.iterations, desc=label, disable=not progress, file=sys.stderr,
                   leave=False, dynamic_ncols=True)
        with warnings.catch_warnings():
            # sep-CMA's diagonal update warns about >7.4 sigma steps, which the ranked
            # penalties of failed samples can cause; the update itself is bounded.
            warnings.filterwarnings("ignore", message="elements of z2", category=UserWarning)
            for _ in range(self.cfg.iterations):
                xs = [np.vstack([np.array(es.ask()), es.mean[None]]) for es in strategies]
                evaluated = self.evaluate(self.problems, xs)
                for i, (es, x, (scores, part)) in enumerate(zip(strategies, xs, evaluated)):
                    self.evaluations[i] += len(x)
                    fitness = ranked_fitness(scores, frames[i])
                    es.tell(list(x[:-1]), fitness[:-1].tolist())
                    best[i] = self.keep_better(best[i], x, scores, part, fitness)
                bar.update(1)
                bar.set_postfix(loss=" ".join(f"{b.loss:.3g}" for b in best))
        bar.close()
        return best, initial


def copy_seed(seed: int, copy: int) -> int:
    """CMA-ES seed of the copy-th side-by-side search of a window (copy 0 keeps ``seed``)."""
    return seed if copy == 0 else (seed + 104_729 * copy) % (2 ** 31 - 1) + 1


def search_averaged(problems: list[WindowProblem], simulator: Simulator,
                    objective: ObjectiveReference, cfg: DynamicsConfig, timing: dict,
                    seeds: list[int], label: str, progress: bool, force_start: int | None = None
                    ) -> tuple[list[WindowProblem], list[Best], list[dict], list[int]]:
    """Search every problem ``cfg.searches`` times side by side (other seeds, shared rollouts)
    and keep the average of the searches' results where it is valid and no worse than the
    worst of them, else the best search's. Returns, per problem: the problem as searched (its
    chosen start), the kept result, its initial record (``kept``: "average" or "search k")
    and the number of evaluations.

    Why: the searches' offsets from their common start are nearly uncorrelated (0.13 on
    motion-capture windows, docs/dynamics.md, Search): most of each is CMA-ES's
    random walk in directions the loss hardly sees, which the average cancels while it keeps
    the correction they share."""
    n = cfg.searches
    copies = [p for p in problems for _ in range(n)]
    search = WindowSearch(copies, simulator, objective, cfg, timing)
    bests, initials = search.run([copy_seed(s, c) for s in seeds for c in range(n)], label,
                                 progress, force_start=force_start)
    out: tuple[list, list, list, list] = ([], [], [], [])
    for i in range(len(problems)):
        rows = list(range(i * n, (i + 1) * n))
        evaluations = sum(search.evaluations[r] for r in rows)
        # Offsets add to a start guess: only searches from the same start can be averaged.
        same = [r for r in rows if initials[r]["start"] == initials[rows[0]]["start"]]
        kept, label_kept = min(rows, key=lambda r: bests[r].fitness), None
        best = bests[kept]
        if len(same) > 1:
            x = np.mean([bests[r].x for r in same], axis=0)[None]
            ((scores, part),) = search.evaluate([search.problems[rows[0]]], [x])
            frames = len(search.problems[rows[0]].positions)
            average = WindowSearch.keep_better(None, x, scores, part,
                                               ranked_fitness(scores, frames))
            evaluations += 1
            if average.valid and average.loss <= max(bests[r].loss for r in same):
                kept, best, label_kept = same[0], average, "average"
        out[0].append(search.problems[kept])
        out[1].append(best)
        out[2].append(dict(initials[rows[0]], kept=label_kept or f"search {kept - rows[0]}",
                           search_losses=[bests[r].loss for r in rows]))
        out[3].append(evaluations)
    return out
