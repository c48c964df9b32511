"""SAC+HER on :class:`twisted.envs.RopeKnotEnv` (the paper's model-free baseline), stored in the database.

``train_sac(store, config)`` trains Stable-Baselines3's SAC with a ``HerReplayBuffer`` ("future"
goals), logs the training episodes' success per goal crossing count to ``rl_success`` every
``log_every`` steps, and stores checkpoints in ``rl_checkpoints`` every ``checkpoint_every`` steps,
on Ctrl-C (KeyboardInterrupt) and at the end. ``train_sac(store, resume_run_id=ID)`` continues a run
from its newest checkpoint with its replay buffer (stored on the newest checkpoint only). A resumed
run continues the policy, optimiser and experience exactly, but not the random streams: it does not
replay bit for bit what an uninterrupted run would have done.

Needs the ``rl`` extra (gymnasium, stable-baselines3).
"""

from __future__ import annotations

import dataclasses
import io
import time
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from sqlalchemy import delete, select

from twisted.store.db import Store
from twisted.store.models import utcnow
from twisted.store.rl import RlCheckpoint, RlRun, RlSuccess, add_checkpoint, add_success

__all__ = ["RlProgress", "SacConfig", "SacOutcome", "evaluate_policy", "make_env", "require_rl", "train_sac"]


def require_rl() -> None:
    """Raise ImportError with the install command when the ``rl`` extra is missing."""
    try:
        import gymnasium  # noqa: F401
        import stable_baselines3  # noqa: F401
    except ImportError as exc:
        raise ImportError(
            f"SAC+HER needs the rl extra ({exc.name} is missing): pip install 'twisted-knots[rl]'"
        ) from exc


@dataclass(frozen=True)
class SacConfig:
    """Goal source, environment and SAC/HER settings of a run (stored in ``rl_runs.parameters``)."""

    total_steps: int = 20_000  # environment steps (curves)
    seed: int = 0
    # goal source: at most one of goals / problem_set / knot; none = every state of goal_crossings
    goals: tuple[str, ...] | None = None  # P-data keys
    problem_set: str | None = None
    knot: str | None = None
    knot_crossings: int | None = None
    goal_crossings: tuple[int, ...] = (1, 2, 3)
    max_curves: int = 10
    friction_scale: float = 1.0
    # SAC + HER
    learning_rate: float = 3e-4
    batch_size: int = 256
    gamma: float = 0.95  # short horizons (max_curves): the usual HER value
    tau: float = 0.005
    learning_starts: int = 500  # uniform random curves before the policy acts and learns
    buffer_size: int | None = None  # None: total_steps (the whole run fits)
    n_sampled_goal: int = 4
    net_arch: tuple[int, ...] = (256, 256)
    # bookkeeping
    log_every: int = 500  # steps between success rows / progress lines
    checkpoint_every: int = 2_000  # steps between checkpoints
    keep_replay_buffer: bool = True  # store it with the newest checkpoint (resume with experience)

    def validate(self) -> None:
        """Raise ValueError naming the setting that is out of range."""
        for name in ("total_steps", "max_curves", "batch_size", "log_every", "checkpoint_every"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1, got {getattr(self, name)}")
        if self.learning_starts < 0:
            raise ValueError(f"learning_starts must be >= 0, got {self.learning_starts}")
        if self.buffer_size is not None and self.buffer_size < 1:
            raise ValueError(f"buffer_size must be at least 1, got {self.buffer_size}")
        if not 0.0 < self.gamma <= 1.0:
            raise ValueError(f"gamma must lie in (0, 1], got {self.gamma}")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SacConfig:
        known = {f.name for f in dataclasses.fields(cls)}
        kw = {k: v for k, v in d.items() if k in known}
        for k in ("goals", "goal_crossings", "net_arch"):
            if kw.get(k) is not None:
                kw[k] = tuple(kw[k])
        return cls(**kw)


@dataclass
class RlProgress:
    """What a progress callback sees every ``log_every`` steps (and at the end)."""

    run_id: int
    steps: int
    total_steps: int
    episodes: int
    elapsed_s: float
    interval: dict[int, tuple[int, int]]  # goal crossings -> (episodes, successes) in the last interval
    cumulative: dict[int, tuple[int, int]]


@dataclass
class SacOutcome:
    """The end of :func:`train_sac`: status finished or interrupted, the last checkpoint (policy id)."""

    run_id: int
    status: str
    steps: int
    episodes: int
    elapsed_s: float
    checkpoint_id: int
    success: dict[int, tuple[int, int]] = field(default_factory=dict)  # whole run, per goal crossings


def make_env(config: SacConfig, db_url: str | None = None) -> Any:
    """The run's :class:`RopeKnotEnv` (``db_url`` is needed for a problem-set goal source)."""
    from twisted.envs import RopeKnotEnv

    return RopeKnotEnv(
        list(config.goals) if config.goals is not None else None,
        problem_set=config.problem_set,
        db_url=db_url,
        knot=config.knot,
        knot_crossings=config.knot_crossings,
        goal_crossings=config.goal_crossings,
        max_curves=config.max_curves,
        friction_scale=config.friction_scale,
    )


def _url(store: Store) -> str:
    return store.url.render_as_string(hide_password=False)


def _policy_bytes(model: Any) -> bytes:
    buf = io.BytesIO()
    model.save(buf)
    return buf.getvalue()


def _buffer_bytes(model: Any) -> bytes:
    buf = io.BytesIO()
    model.save_replay_buffer(buf)
    return zlib.compress(buf.getvalue(), 1)


def _new_model(config: SacConfig, vec_env: Any) -> Any:
    from stable_baselines3 import SAC, HerReplayBuffer

    return SAC(
        "MultiInputPolicy",
        vec_env,
        learning_rate=config.learning_rate,
        buffer_size=config.buffer_size or config.total_steps,
        learning_starts=config.learning_starts,
        batch_size=config.batch_size,
        tau=config.tau,
        gamma=config.gamma,
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={"n_sampled_goal": config.n_sampled_goal, "goal_selection_strategy": "future"},
        policy_kwargs={"net_arch": list(config.net_arch)},
        seed=config.seed,
        device="cpu",
        verbose=0,
    )


def _load_model(row: RlCheckpoint, vec_env: Any) -> Any:
    from stable_baselines3 import SAC

    model = SAC.load(io.BytesIO(row.policy), env=vec_env, device="cpu")
    if row.replay_buffer is not None:
        model.load_replay_buffer(io.BytesIO(zlib.decompress(row.replay_buffer)))
    return model


def train_sac(
    store: Store,
    config: SacConfig | None = None,
    *,
    resume_run_id: int | None = None,
    progress: Callable[[RlProgress], None] | None = None,
    time_limit_s: float | None = None,
) -> SacOutcome:
    """Train (or, with ``resume_run_id``, continue) a SAC+HER policy; see the module docstring.

    On KeyboardInterrupt a checkpoint is stored, the run marked ``interrupted`` and the interrupt
    re-raised. After ``time_limit_s`` seconds (of this call) training stops at the next step with a
    checkpoint and status ``interrupted`` (resumable). Raises ValueError for bad settings or an
    unknown / finished run to resume.
    """
    require_rl()
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    resume_row: RlCheckpoint | None = None
    if resume_run_id is None:
        # settings and goals are checked before a run row exists, so bad input leaves no trace
        config = config or SacConfig()
        config.validate()
        env = make_env(config, _url(store))
    with store.session(write=True) as session:
        if resume_run_id is not None:
            run = session.get(RlRun, resume_run_id)
            if run is None:
                raise ValueError(
                    f"there is no SAC run {resume_run_id} in the database (see `twisted rl list`)"
                )
            if run.status == "finished":
                raise ValueError(f"SAC run {resume_run_id} has finished: start a new run instead")
            config = SacConfig.from_dict(run.parameters)
            resume_row = session.scalars(
                select(RlCheckpoint)
                .where(RlCheckpoint.rl_run_id == run.id)
                .order_by(RlCheckpoint.id.desc())
                .limit(1)
            ).first()
            if resume_row is not None:
                # the counters go back to the checkpoint: steps after it are lost with the process
                run.steps_done, run.episodes, run.elapsed_s = (
                    resume_row.steps,
                    resume_row.episodes,
                    resume_row.elapsed_s,
                )
            else:
                run.steps_done, run.episodes, run.elapsed_s = 0, 0, 0.0
            # ... and so do the success intervals a killed process logged after it (they are re-run)
            session.execute(
                delete(RlSuccess).where(RlSuccess.rl_run_id == run.id, RlSuccess.steps > run.steps_done)
            )
            run.status, run.message, run.ended_at = "running", None, None
        else:
            assert config is not None
            run = RlRun(
                status="running",
                seed=config.seed,
                parameters=config.to_dict(),
                total_steps=config.total_steps,
                steps_done=0,
                episodes=0,
                elapsed_s=0.0,
                metrics={},
            )
            session.add(run)
        session.flush()
        run_id = run.id
        steps_at_start, episodes_at_start, elapsed_at_start = run.steps_done, run.episodes, run.elapsed_s
        metrics = dict(run.metrics or {})

    if resume_run_id is not None:
        env = make_env(config, _url(store))
    vec_env = DummyVecEnv([lambda: Monitor(env)])
    if resume_row is not None:
        model = _load_model(resume_row, vec_env)
        model.set_random_seed(config.seed + steps_at_start)
        if resume_row.replay_buffer is None:
            metrics["resumed_without_replay_buffer"] = True
    else:
        model = _new_model(config, vec_env)
        steps_at_start = 0

    assert config is not None  # set above, from the argument or the resumed run
    cfg: SacConfig = config
    started = time.monotonic()
    cumulative: dict[int, list[int]] = {
        int(k): list(v) for k, v in (metrics.get("success_by_goal_cross") or {}).items()
    }
    interval: dict[int, list[int]] = {}
    state = {"episodes": episodes_at_start}

    def elapsed() -> float:
        return elapsed_at_start + time.monotonic() - started

    def save(status: str, *, final: bool = False, message: str | None = None) -> int:
        policy = _policy_bytes(model)
        buffer = _buffer_bytes(model) if config.keep_replay_buffer else None
        with store.session(write=True) as session:
            row = session.get(RlRun, run_id)
            assert row is not None
            row.steps_done = int(model.num_timesteps)
            row.episodes = state["episodes"]
            row.elapsed_s = elapsed()
            row.status = status
            row.updated_at = utcnow()
            row.metrics = {**metrics, "success_by_goal_cross": {str(k): v for k, v in cumulative.items()}}
            if status != "running":
                row.ended_at = utcnow()
                row.message = message
            return add_checkpoint(session, row, policy=policy, replay_buffer=buffer, final=final)

    def log_interval() -> None:
        steps = int(model.num_timesteps)
        snapshot = {k: (v[0], v[1]) for k, v in interval.items()}
        with store.session(write=True) as session:
            add_success(session, run_id, steps, snapshot)
            row = session.get(RlRun, run_id)
            assert row is not None
            row.steps_done, row.episodes, row.elapsed_s, row.updated_at = (
                steps,
                state["episodes"],
                elapsed(),
                utcnow(),
            )
        if progress is not None:
            progress(
                RlProgress(
                    run_id=run_id,
                    steps=steps,
                    total_steps=config.total_steps,
                    episodes=state["episodes"],
                    elapsed_s=elapsed(),
                    interval=snapshot,
                    cumulative={k: (v[0], v[1]) for k, v in cumulative.items()},
                )
            )
        interval.clear()

    class Bookkeeping(BaseCallback):  # type: ignore[misc]
        def _on_step(self) -> bool:
            for done, info in zip(self.locals["dones"], self.locals["infos"], strict=True):
                if done:
                    cross = int(info["goal_cross"])
                    hit = int(bool(info["is_success"]))
                    for table in (interval, cumulative):
                        counts = table.setdefault(cross, [0, 0])
                        counts[0] += 1
                        counts[1] += hit
                    state["episodes"] += 1
            steps = int(self.num_timesteps)
            if steps % cfg.log_every == 0:
                log_interval()
            if steps % cfg.checkpoint_every == 0 and steps < cfg.total_steps:
                save("running")
            if time_limit_s is not None and time.monotonic() - started >= time_limit_s:
                state["timed_out"] = 1
                return False  # SB3 ends learn() here
            return True

    remaining = config.total_steps - steps_at_start
    try:
        if remaining > 0:
            model.learn(
                total_timesteps=remaining,
                callback=Bookkeeping(),
                reset_num_timesteps=resume_row is None,
            )
    except KeyboardInterrupt:
        save("interrupted", message="interrupted (Ctrl-C); continue with `twisted rl train --resume RUN`")
        raise
    except BaseException as exc:
        with store.session(write=True) as session:
            row = session.get(RlRun, run_id)
            if row is not None:
                row.status, row.message, row.ended_at = "failed", f"{type(exc).__name__}: {exc}", utcnow()
        raise
    finally:
        vec_env.close()
    if interval:
        log_interval()
    status = "interrupted" if state.get("timed_out") else "finished"
    message = f"time limit {time_limit_s} s reached; continue with `twisted rl train --resume RUN`"
    checkpoint_id = save(
        status, final=status == "finished", message=message if status != "finished" else None
    )
    return SacOutcome(
        run_id=run_id,
        status=status,
        steps=int(model.num_timesteps),
        episodes=state["episodes"],
        elapsed_s=elapsed(),
        checkpoint_id=checkpoint_id,
        success={k: (v[0], v[1]) for k, v in cumulative.items()},
    )


def evaluate_policy(
    model: Any,
    config: SacConfig,
    episodes_per_cross: int,
    *,
    seed: int = 0,
    deterministic: bool = True,
    db_url: str | None = None,
) -> dict[int, tuple[int, int]]:
    """``{goal crossings: (episodes, successes)}`` of the policy alone from the straight rope.

    For each crossing count in the run's goal pool, ``episodes_per_cross`` episodes with goals drawn
    uniformly from that count (seeded), each up to ``config.max_curves`` curves.
    """
    import numpy as np

    env = make_env(config, db_url)
    rng = np.random.default_rng(seed)
    by_cross: dict[int, list[Any]] = {}
    for p in env.goals:
        by_cross.setdefault(p.cross, []).append(p)
    out: dict[int, tuple[int, int]] = {}
    for cross in sorted(by_cross):
        pool = by_cross[cross]
        hits = 0
        for i in range(episodes_per_cross):
            goal = pool[int(rng.integers(len(pool)))]
            obs, info = env.reset(seed=seed + i, options={"goal": goal})
            done = False
            while not done:
                action, _ = model.predict(obs, deterministic=deterministic)
                obs, _, terminated, truncated, info = env.step(action)
                done = terminated or truncated
            hits += int(info["is_success"])
        out[cross] = (episodes_per_cross, hits)
    env.close()
    return out
