"""Goals drawn the way people name them: uniform over the rope states of a crossing count, and knots.

Uniform up to 5 crossings. Every state of ``c <= 5`` crossings is enumerated
(:func:`twisted.moves.enumerate_states`: 7,968 at 4, 130,304 at 5, about a minute) and goals are
drawn from the sorted list by one seeded generator without replacement (:func:`uniform_states`).

A sampler at 6. Enumerating 6 crossings does not fit (millions of states), so :func:`sample_states`
walks a tree instead. Retracting the head tip past its first crossing (deleting the crossing of visit
1) turns every state of ``n`` crossings into one of ``n - 1`` (the argument of
:mod:`twisted.moves`: it undoes a Cross move of the head, or an R1 curl on segment 0), so every state
has exactly one *head parent* (:func:`head_parent`) and the states form a tree rooted at the empty
rope; a state's *head children* (:func:`head_children`) are the states one move away with one more
crossing whose head parent it is. A walk from the empty rope that picks a head child uniformly at
every level reaches state ``s`` with the known probability ``q(s) = prod 1 / children`` (one path per
state), so ``w(s) = 1 / q(s)`` is an exact importance weight toward uniform: the mean weight
estimates the number of states of that count (Knuth's estimator), and drawing from a pool of walks
with probabilities proportional to ``w`` (sampling-importance-resampling) tends to the uniform
distribution as the pool grows. Goals are drawn without replacement from the pool (a state drawn twice
is drawn again). ``bench/sampler_tv.py`` measures the result against the exact enumeration at 5.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from twisted.topology import EMPTY, PData

__all__ = [
    "SAMPLER_POOL",
    "MAX_UNIFORM_ENUMERATED",
    "Walk",
    "head_children",
    "head_parent",
    "sample_states",
    "uniform_states",
    "walk",
]

# Up to this many crossings a uniform draw enumerates every state.
MAX_UNIFORM_ENUMERATED = 5
# Walks per goal drawn by the sampler (the pool of sampling-importance-resampling).
SAMPLER_POOL = 40


def head_parent(p: PData) -> PData:
    """``p`` with the crossing of its first visit deleted (both visits), positions renumbered."""
    if p.cross == 0:
        raise ValueError("the empty rope has no head parent")
    first = p.visits[0]
    gone = {first.position, first.partner}
    kept = sorted(pos for pos in range(1, len(p.visits) + 1) if pos not in gone)
    renumber = {old: new for new, old in enumerate(kept, start=1)}
    return PData.from_crossings((renumber[o], renumber[u], s) for o, u, s in p.crossings() if o not in gone)


@lru_cache(maxsize=4096)
def head_children(p: PData) -> tuple[PData, ...]:
    """The states one move from ``p`` with one more crossing whose head parent is ``p``, sorted by key."""
    from twisted.moves import successors

    found = {
        s.state.key: s.state
        for s in successors(p)
        if s.state.cross == p.cross + 1 and head_parent(s.state) == p
    }
    return tuple(found[k] for k in sorted(found))


@dataclass(frozen=True)
class Walk:
    """One walk down the head tree: the state reached and its weight ``1 / q(state)``."""

    state: PData
    weight: float


def walk(crossings: int, rng: np.random.Generator) -> Walk:
    """A walk from the empty rope to a state of ``crossings`` crossings, a uniform head child per level."""
    p, weight = EMPTY, 1.0
    for _ in range(crossings):
        children = head_children(p)
        weight *= len(children)
        p = children[int(rng.integers(len(children)))]
    return Walk(p, weight)


def sample_states(
    crossings: int,
    n: int,
    rng: np.random.Generator,
    *,
    pool: int = SAMPLER_POOL,
    exclude: frozenset[str] = frozenset(),
) -> list[PData]:
    """``n`` distinct states of ``crossings`` crossings, close to uniform (module docstring).

    ``pool * n`` walks are made; states are drawn from them without replacement with probabilities
    proportional to their weights, leaving out keys in ``exclude``. Fewer than ``n`` come back only
    when the pool holds fewer distinct states.
    """
    if crossings < 1 or n < 1 or pool < 1:
        raise ValueError(f"crossings, n and pool must be at least 1, got {crossings}, {n}, {pool}")
    walks = [walk(crossings, rng) for _ in range(pool * n)]
    weights: dict[str, float] = {}
    states: dict[str, PData] = {}
    for w in walks:  # a state walked k times is k entries of the pool
        if w.state.key in exclude:
            continue
        weights[w.state.key] = weights.get(w.state.key, 0.0) + w.weight
        states[w.state.key] = w.state
    keys = sorted(weights)
    chosen: list[PData] = []
    if not keys:
        return chosen
    w_arr = np.array([weights[k] for k in keys])
    picks = rng.choice(len(keys), size=min(n, len(keys)), replace=False, p=w_arr / w_arr.sum())
    for i in picks:
        chosen.append(states[keys[int(i)]])
    return chosen


def _enumerated(crossings: int) -> tuple[PData, ...]:
    from twisted.knots import primed_states

    known = primed_states(crossings)  # the store's cache (twisted.store.knots), when it was read
    return known if known is not None else _enumeration(crossings)


@lru_cache(maxsize=8)
def _enumeration(crossings: int) -> tuple[PData, ...]:
    from twisted.moves import enumerate_states

    return tuple(enumerate_states(crossings)[crossings])


def uniform_states(
    crossings: int,
    n: int,
    rng: np.random.Generator,
    *,
    exclude: frozenset[str] = frozenset(),
    states: Sequence[PData] | None = None,
) -> list[PData]:
    """``n`` states drawn uniformly without replacement from every state of ``crossings`` crossings.

    ``states``: the enumeration, when the caller has it (e.g. from the store's cache); sorted by key.
    Keys in ``exclude`` are never drawn.
    """
    if not 1 <= crossings <= MAX_UNIFORM_ENUMERATED:
        raise ValueError(
            f"uniform draws enumerate 1 to {MAX_UNIFORM_ENUMERATED} crossings, got {crossings} "
            "(use the sampler, sample_states, beyond)"
        )
    pool = list(states) if states is not None else list(_enumerated(crossings))
    if exclude:
        pool = [p for p in pool if p.key not in exclude]
    if n >= len(pool):
        return pool
    picks = rng.choice(len(pool), size=n, replace=False)
    return [pool[int(i)] for i in picks]
