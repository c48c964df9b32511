"""The options of a collect run (:class:`CollectOptions`) and what it reports (docs/DESIGN.md section 7)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from twisted.rope import MAX_CROSSINGS

RUN_KIND = "collect"
MAX_HOURS = 1e5  # more is a typo (and overflows the clock arithmetic near 1e308)
ACROSS_SHARE = 0.8  # bench/bench_collect_curves.py: kept per hour per core, uniform vs across curves


class CollectError(ValueError):
    """Invalid collection options or an unusable D_Q; the message says which and why."""


@dataclass(frozen=True)
class CollectOptions:
    """What one ``twisted collect`` run does (stored in ``runs.parameters``)."""

    hours: float
    workers: int = 1
    seed: int | None = None
    batch_size: int = 20
    batch_seconds: float = 2.0
    max_cross: int = MAX_CROSSINGS  # what the inverse model encodes
    cross_bias: float = 1.0
    max_kept: int | None = None
    max_tries: int | None = None
    friction_scale: float = 1.0
    refresh_seconds: float = 2.0
    # share of curves aimed across another strand (twisted.proposals); the rest are uniform
    across_share: float = ACROSS_SHARE
    # probability of keeping a transition that removes crossings (0: only rising ones, the paper's D_Q)
    remove_share: float = 0.0

    def validate(self) -> None:
        """Raise :class:`CollectError` naming the first bad option."""

        def positive(name: str, value: float | int | None, allow_none: bool = False) -> None:
            if value is None and allow_none:
                return
            if value is None or isinstance(value, bool) or not math.isfinite(value) or value <= 0:
                raise CollectError(f"--{name.replace('_', '-')} must be a positive number, got {value!r}")

        positive("hours", self.hours)
        if self.hours > MAX_HOURS:
            raise CollectError(f"--hours must be at most {MAX_HOURS:g} (about 11 years), got {self.hours!r}")
        positive("workers", self.workers)
        positive("batch_size", self.batch_size)
        positive("batch_seconds", self.batch_seconds)
        positive("refresh_seconds", self.refresh_seconds)
        positive("friction_scale", self.friction_scale)
        if self.friction_scale > 100:
            raise CollectError(f"--friction-scale must be at most 100, got {self.friction_scale!r}")
        if not (math.isfinite(self.cross_bias) and 0 <= self.cross_bias <= 10):
            raise CollectError(f"--cross-bias must be between 0 and 10, got {self.cross_bias!r}")
        if not (math.isfinite(self.across_share) and 0 <= self.across_share <= 1):
            raise CollectError(f"--across-share must be between 0 and 1, got {self.across_share!r}")
        if not (math.isfinite(self.remove_share) and 0 <= self.remove_share <= 1):
            raise CollectError(f"--remove-share must be between 0 and 1, got {self.remove_share!r}")
        positive("max_kept", self.max_kept, allow_none=True)
        positive("max_tries", self.max_tries, allow_none=True)
        if not 1 <= self.max_cross <= 20:
            raise CollectError(f"--max-cross must be between 1 and 20, got {self.max_cross}")
        if self.seed is not None and not 0 <= self.seed < 2**63:
            raise CollectError(f"--seed must be in 0..2**63-1, got {self.seed}")


@dataclass
class CollectProgress:
    """Counters of the running collection (what was committed so far), for a progress display."""

    run_id: int
    elapsed_s: float
    total_s: float
    tried: int = 0
    kept: int = 0
    rejected: int = 0
    batches: int = 0
    workers: int = 0
    stopping: bool = False

    @property
    def kept_per_hour(self) -> float:
        return self.kept * 3600.0 / self.elapsed_s if self.elapsed_s > 0 else 0.0


@dataclass
class CollectSummary:
    """How a collection run ended."""

    run_id: int
    status: str  # finished | interrupted | failed
    seed: int
    workers: int
    tried: int
    kept: int
    rejected: int
    batches: int
    wall_seconds: float
    sim_seconds: float
    message: str | None = None
    kept_by_to_cross: dict[int, int] = field(default_factory=dict)
    commit_seconds: float = 0.0  # the writer's time spent committing batches
    signum: int | None = None  # the signal that stopped it (interrupted)

    @property
    def kept_per_hour(self) -> float:
        return self.kept * 3600.0 / self.wall_seconds if self.wall_seconds > 0 else 0.0

    @property
    def kept_per_hour_per_worker(self) -> float:
        return self.kept_per_hour / max(1, self.workers)
