"""Self-supervised data collection with the D_Q reset scheme (docs/DESIGN.md section 7).

``D_Q`` is the set of configurations in the store added by ``collect`` runs (the straight rope is put in
as the root when there is none). Each iteration a worker

1. samples a start configuration q from D_Q, biased toward more crossings: among the crossing counts
   ``c < max_cross`` present in D_Q it picks ``c`` with probability proportional to
   ``(1 + c) ** cross_bias``, then a configuration uniformly among those with ``c`` crossings. The
   default ``cross_bias = 1`` weighs a count by ``1 + c`` (the planner's prioritise-crosses weight);
   0 is uniform over the counts present. Weighing counts rather than configurations keeps the one
   straight rope (the only 0-crossing configuration) in use, and a steeper bias (e.g. ``2 ** c``) was
   measured to halve the kept rate: random curves from 4-5 crossings are kept 1-3 % of the time
   against 5-8 % from 1-3 crossings;
2. applies a random curve ``c_t``: with probability ``across_share`` one aimed across another strand
   of q (:func:`twisted.proposals.across_curve`), else a uniform one (``twisted.sim.sample_curve``);
3. keeps the transition ``(q, s, c_t, q', s')`` when the simulation is valid and
   ``Cross(s) < Cross(s') <= max_cross``; q' joins D_Q once committed.

Stopping: at the deadline, at ``max_kept``/``max_tries``, or on SIGINT/SIGTERM the workers finish their
current curve, send their last batch, and the run is marked ``finished`` (deadline/limits) or
``interrupted`` (signal). After SIGKILL at most the batches not yet committed are lost; the run stays
``running`` until the next collect on the same host marks it ``interrupted``. Running collect again
always starts a NEW run that continues the same D_Q (every collect configuration in the store), not
the straight rope. Several collectors may write one database at the same time.

Replay: every random choice comes from the seeded per-worker generators, but which configurations are
in D_Q when a worker samples depends on commit timing across processes, so a multi-process run is not
bit-for-bit replayable; each transition's curve and start configuration are stored, and replaying a
stored transition in ``RopeSim`` is exact.

Modules: ``options`` (what a run is asked and what it reports), ``loop`` (the collect loop of one
worker, used by the worker processes and by the Ray actors of :mod:`twisted.distributed`), ``driver``
(the driver's side of a run: the runs row, signals, commits, progress, logging, the summary),
``processes`` (:func:`collect`: worker processes and one writer), ``stats`` (``twisted stats``).
"""

from twisted.collect.driver import CollectRun
from twisted.collect.loop import Budget, CollectLoop, DQIndex, ensure_root
from twisted.collect.options import (
    ACROSS_SHARE,
    MAX_HOURS,
    RUN_KIND,
    CollectError,
    CollectOptions,
    CollectProgress,
    CollectSummary,
)
from twisted.collect.processes import collect
from twisted.collect.stats import REFERENCE_PLUS_ONE_RATE, collection_stats

__all__ = [
    "ACROSS_SHARE",
    "MAX_HOURS",
    "REFERENCE_PLUS_ONE_RATE",
    "RUN_KIND",
    "Budget",
    "CollectError",
    "CollectLoop",
    "CollectOptions",
    "CollectProgress",
    "CollectRun",
    "CollectSummary",
    "DQIndex",
    "collect",
    "collection_stats",
    "ensure_root",
]
