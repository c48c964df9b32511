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
import math
import time
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from sqlalchemy import delete, select

from twisted.store.boundary import StoredValueError, shown, stored_object
from twisted.store.db import Store
from twisted.store.models import utcnow
from twisted.store.payloads import UnsafePayloadError, load_tensors, stored_bytes
from twisted.store.rl import (
    RlCheckpoint,
    RlRun,
    RlSuccess,
    add_checkpoint,
    add_success,
    checkpoint_counters,
)

__all__ = [
    "RlProgress",
    "SacConfig",
    "SacOutcome",
    "evaluate_policy",
    "inference_model",
    "make_env",
    "require_rl",
    "train_sac",
]


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
    def from_stored(cls, parameters: Any, run_id: int) -> SacConfig:
        """The settings of SAC run ``run_id`` as stored (``rl_runs.parameters``), checked like new ones:
        a JSON object whose known settings have their declared types and pass :meth:`validate`.
        StoredValueError naming the setting otherwise (the CLI's exit 2), before anything is written."""
        table, field_name = "rl_runs", "parameters"
        stored = stored_object(parameters, table, run_id, field_name)
        for spec in dataclasses.fields(cls):
            if spec.name in stored:
                problem = _setting_problem(str(spec.type), stored[spec.name])
                if problem is not None:
                    raise StoredValueError(table, run_id, f"{field_name}.{spec.name}", problem)
        config = cls.from_dict(stored)
        try:
            config.validate()
        except ValueError as exc:
            raise StoredValueError(table, run_id, field_name, str(exc)) from None
        return config

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SacConfig:
        known = {f.name for f in dataclasses.fields(cls)}
        kw = {k: v for k, v in d.items() if k in known}
        for k in ("goals", "goal_crossings", "net_arch"):
            if kw.get(k) is not None:
                kw[k] = tuple(kw[k])
        return cls(**kw)


def _setting_problem(declared: str, value: Any) -> str | None:
    """Why a stored setting is not of its declared type (``SacConfig``'s annotation), or None (the
    JSON text's size is bounded where it is parsed, :func:`twisted.store.boundary.parse_json`)."""
    optional = declared.endswith(" | None")
    kind = declared.removesuffix(" | None")
    if value is None:
        return None if optional else f"must be {kind}, got null"
    kinds: dict[str, Callable[[Any], bool]] = {
        "int": lambda v: isinstance(v, int) and not isinstance(v, bool),
        "float": lambda v: isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v),
        "bool": lambda v: isinstance(v, bool),
        "str": lambda v: isinstance(v, str),
    }
    if kind.startswith("tuple["):
        item = kind.removeprefix("tuple[").removesuffix(", ...]")
        fits = isinstance(value, list | tuple) and all(kinds[item](v) for v in value)
        return None if fits else f"must be a list of {item}, got {shown(value)}"
    return None if kinds[kind](value) else f"must be {kind}, got {shown(value)}"


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


# ---- stored policies and replay buffers: tensors and plain data only (docs/security.md) ---------------
#
# Stable-Baselines3's own ``save`` pickles parts of a model (spaces, schedules, the whole replay buffer),
# and its ``load`` unpickles them: a crafted row would run code. What is stored instead is
# ``torch.save`` of state dicts, tensors and numbers, read back with ``weights_only=True``
# (:func:`twisted.store.payloads.load_tensors`) into a model rebuilt from the run's settings.

POLICY_FORMAT = "twisted-sac-policy/1"
BUFFER_FORMAT = "twisted-sac-buffer/1"
# the arrays of a (Her/Dict)ReplayBuffer; observations are dicts of arrays
BUFFER_ARRAYS = (
    "observations",
    "next_observations",
    "actions",
    "rewards",
    "dones",
    "timeouts",
    "ep_start",
    "ep_length",
    "_current_ep_start",
)
MAX_SB3_ZIP_BYTES = 4 << 30  # what an old-format policy may unpack to


def _torch_bytes(obj: Any) -> bytes:
    import torch

    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def _policy_bytes(model: Any) -> bytes:
    """The policy, optimisers, entropy coefficient and counters of ``model`` (:data:`POLICY_FORMAT`)."""
    from stable_baselines3.common.save_util import recursive_getattr

    _, variables = model._get_torch_save_params()
    return _torch_bytes(
        {
            "format": POLICY_FORMAT,
            "params": model.get_parameters(),
            "variables": {name: recursive_getattr(model, name).detach().cpu() for name in variables},
            "counters": {
                "num_timesteps": int(model.num_timesteps),
                "n_updates": int(model._n_updates),
                "episode_num": int(model._episode_num),
            },
        }
    )


def _buffer_bytes(model: Any) -> bytes:
    """The replay buffer's arrays and position (:data:`BUFFER_FORMAT`), zlib-compressed."""
    import numpy as np
    import torch

    rb = model.replay_buffer

    def tensor(a: Any) -> Any:
        return torch.from_numpy(np.ascontiguousarray(a))

    arrays = {}
    for name in BUFFER_ARRAYS:
        value = getattr(rb, name, None)
        if isinstance(value, dict):
            arrays[name] = {k: tensor(v) for k, v in value.items()}
        elif value is not None:
            arrays[name] = tensor(value)
    state = {"format": BUFFER_FORMAT, "pos": int(rb.pos), "full": bool(rb.full), "arrays": arrays}
    return zlib.compress(_torch_bytes(state), 1)


def _is_sb3_zip(blob: bytes) -> bool:
    """Whether ``blob`` is a ``SAC.save`` archive (the format of earlier versions), not a torch file."""
    import zipfile

    if not zipfile.is_zipfile(io.BytesIO(blob)):
        return False
    with zipfile.ZipFile(io.BytesIO(blob)) as archive:
        return "data" in archive.namelist() and "policy.pth" in archive.namelist()


def read_policy(blob: bytes, what: str) -> dict[str, Any]:
    """The stored policy state of :func:`_policy_bytes`, or of a ``SAC.save`` archive of earlier versions
    (its state dicts read as tensors only, its JSON counters; its pickled entries are never decoded).

    Raises :class:`UnsafePayloadError` (a ValueError) naming ``what`` for anything else.
    """
    blob = stored_bytes(blob, what)
    if _is_sb3_zip(blob):
        return _read_sb3_zip(blob, what)
    state = load_tensors(blob, what)
    if not (
        isinstance(state, dict)
        and state.get("format") == POLICY_FORMAT
        and isinstance(state.get("params"), dict)
        and isinstance(state.get("variables"), dict)
        and isinstance(state.get("counters"), dict)
    ):
        raise UnsafePayloadError(f"{what} is not a SAC policy stored by twisted")
    return state


def _read_sb3_zip(blob: bytes, what: str) -> dict[str, Any]:
    import json
    import zipfile

    with zipfile.ZipFile(io.BytesIO(blob)) as archive:
        if sum(info.file_size for info in archive.infolist()) > MAX_SB3_ZIP_BYTES:
            raise UnsafePayloadError(f"{what}: its archive unpacks to more than {MAX_SB3_ZIP_BYTES:,} bytes")
        try:
            data = json.loads(archive.read("data"))  # ":serialized:" entries (pickles) stay text
        except ValueError as exc:
            raise UnsafePayloadError(f"{what}: its settings are not JSON ({exc})") from None
        params: dict[str, Any] = {}
        variables: dict[str, Any] = {}
        for name in archive.namelist():
            if name.endswith(".pth"):
                loaded = load_tensors(archive.read(name), f"{what} ({name})")
                if name == "pytorch_variables.pth":
                    variables = loaded if isinstance(loaded, dict) else {}
                else:
                    params[name.removesuffix(".pth")] = loaded
    counters = {
        key: data.get(field, 0) if isinstance(data, dict) else 0
        for key, field in (
            ("num_timesteps", "num_timesteps"),
            ("n_updates", "_n_updates"),
            ("episode_num", "_episode_num"),
        )
    }
    return {"format": "sb3-zip", "params": params, "variables": variables, "counters": counters}


def apply_policy(model: Any, state: dict[str, Any], what: str) -> None:
    """Load :func:`read_policy`'s ``state`` into ``model`` (built with the run's settings); a state
    that does not fit raises :class:`UnsafePayloadError`."""
    import torch
    from stable_baselines3.common.save_util import recursive_getattr

    _, variables = model._get_torch_save_params()
    try:
        model.set_parameters(state["params"], exact_match=True, device=model.device)
        for name, value in state["variables"].items():
            if name not in variables or not isinstance(value, torch.Tensor):
                raise ValueError(f"unexpected variable {name!r}")
            with torch.no_grad():
                recursive_getattr(model, name).copy_(value)
        counters = state["counters"]
        model.num_timesteps = int(counters["num_timesteps"])
        model._n_updates = int(counters["n_updates"])
        model._episode_num = int(counters["episode_num"])
    except (KeyError, TypeError, ValueError, RuntimeError, AttributeError) as exc:
        raise UnsafePayloadError(
            f"{what} does not fit a SAC model of its run ({type(exc).__name__}: {exc})"
        ) from None


def inference_model(blob: bytes, parameters: dict[str, Any], what: str) -> Any:
    """The SAC model of a stored policy ``blob`` (:func:`read_policy`) for acting only: built from its
    run's ``parameters`` without an environment (a one-slot plain buffer replaces the HER buffer)."""
    require_rl()
    from stable_baselines3 import SAC
    from stable_baselines3.common.buffers import DictReplayBuffer

    from twisted.envs.rope_knot import env_spaces

    state = read_policy(blob, what)
    try:
        config = SacConfig.from_dict(parameters)
    except (TypeError, ValueError) as exc:
        raise UnsafePayloadError(f"{what}: the settings of its run cannot be read ({exc})") from None
    observation_space, action_space = env_spaces()
    model = SAC(
        "MultiInputPolicy",
        None,  # type: ignore[arg-type]  # spaces set below, as SB3 does when it loads
        learning_rate=config.learning_rate,
        target_entropy=-float(action_space.shape[0]),  # SB3's "auto" (it reads the missing env)
        buffer_size=1,
        replay_buffer_class=DictReplayBuffer,
        policy_kwargs={"net_arch": list(config.net_arch)},
        device="cpu",
        _init_setup_model=False,
    )
    model.observation_space, model.action_space = observation_space, action_space
    model.n_envs = 1
    model._setup_model()
    apply_policy(model, state, what)
    return model


def _buffer_limit(rb: Any) -> int:
    """The most bytes a stored copy of the replay buffer ``rb`` may unpack to (its arrays, and room)."""
    total = 0
    for name in BUFFER_ARRAYS:
        value = getattr(rb, name, None)
        for array in value.values() if isinstance(value, dict) else [value] if value is not None else []:
            total += int(array.nbytes)
    return 2 * total + (1 << 20)


def read_buffer(blob: bytes, what: str, limit: int) -> dict[str, Any]:
    """The stored replay buffer state (:data:`BUFFER_FORMAT`), unpacked to at most ``limit`` bytes.

    A buffer pickled by earlier versions is refused (:class:`UnsafePayloadError`): reading it would
    mean unpickling it.
    """
    inflate = zlib.decompressobj()
    try:
        raw = inflate.decompress(stored_bytes(blob, what), limit)
    except zlib.error as exc:
        raise UnsafePayloadError(f"{what} is not a compressed replay buffer ({exc})") from None
    if inflate.unconsumed_tail:
        raise UnsafePayloadError(f"{what} unpacks to more than {limit:,} bytes, more than its run's buffer")
    if raw[:1] == b"\x80" or not raw.startswith(b"PK"):
        raise UnsafePayloadError(
            f"{what} is a pickled replay buffer (the format of earlier versions), which is not read: "
            "unpickling can run code. Resume with --no-replay-buffer to continue without it"
        )
    state = load_tensors(raw, what, max_bytes=limit)  # its inner archive: no member unpacks further
    if not (
        isinstance(state, dict)
        and state.get("format") == BUFFER_FORMAT
        and isinstance(state.get("arrays"), dict)
    ):
        raise UnsafePayloadError(f"{what} is not a replay buffer stored by twisted")
    return state


def apply_buffer(model: Any, state: dict[str, Any], what: str) -> None:
    """Copy :func:`read_buffer`'s arrays into ``model``'s replay buffer; they must match it exactly.

    Every value's type, shape and dtype is checked against the run's buffer before it is iterated or
    copied, and no message is built from a stored array's elements (a crafted one may hold billions).
    """
    import torch

    rb = model.replay_buffer

    def put(target: Any, value: Any, name: str) -> None:
        if not isinstance(value, torch.Tensor):
            raise ValueError(f"{name} is a {type(value).__name__}, not an array")
        if tuple(value.shape) != target.shape or value.numpy().dtype != target.dtype:
            shape, want = list(value.shape)[:8], list(target.shape)
            raise ValueError(f"{name} is {value.dtype}{shape}, the run's is {target.dtype}{want}")
        target[...] = value.numpy()

    def keys_of(value: Any, name: str, want: Any) -> None:
        if not isinstance(value, dict):
            raise ValueError(f"{name} is a {type(value).__name__}, the run's is a dict of {len(want)} arrays")
        if len(value) != len(want) or not all(isinstance(k, str) and k in want for k in value):
            raise ValueError(f"{name} has {len(value):,} entries, not the run's {sorted(want)}")

    try:
        arrays = state["arrays"]
        for name in BUFFER_ARRAYS:
            target = getattr(rb, name, None)
            if target is None:
                continue
            if name not in arrays:
                raise ValueError(f"{name} is missing")
            if isinstance(target, dict):
                keys_of(arrays[name], name, target)
                for key in target:
                    put(target[key], arrays[name][key], f"{name}.{key}")
            else:
                put(target, arrays[name], name)
        pos, full = state["pos"], state["full"]
        if type(pos) is not int or type(full) is not bool:
            raise ValueError("its position is not a whole number and a flag")
        if not 0 <= pos < rb.buffer_size:
            raise ValueError(f"position {pos:,} outside the buffer of {rb.buffer_size:,}")
        rb.pos, rb.full = pos, full
    except (KeyError, TypeError, ValueError, RuntimeError, AttributeError) as exc:
        raise UnsafePayloadError(f"{what} does not fit the run's replay buffer ({exc})") from None


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


def train_sac(
    store: Store,
    config: SacConfig | None = None,
    *,
    resume_run_id: int | None = None,
    progress: Callable[[RlProgress], None] | None = None,
    time_limit_s: float | None = None,
    read_replay_buffer: bool = True,
) -> SacOutcome:
    """Train (or, with ``resume_run_id``, continue) a SAC+HER policy; see the module docstring.

    On KeyboardInterrupt a checkpoint is stored, the run marked ``interrupted`` and the interrupt
    re-raised. After ``time_limit_s`` seconds (of this call) training stops at the next step with a
    checkpoint and status ``interrupted`` (resumable). Raises ValueError for bad settings or an
    unknown / finished run to resume, :class:`UnsafePayloadError` (a ValueError) for a stored policy
    or replay buffer that is not plain data or does not fit the run (before anything is written).
    ``read_replay_buffer=False`` resumes without the stored replay buffer.
    """
    require_rl()
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    resume_row: RlCheckpoint | None = None
    resumed_at = (0, 0, 0.0)  # steps, episodes, elapsed_s of the checkpoint resumed from
    if resume_run_id is None:
        # settings and goals are checked before a run row exists, so bad input leaves no trace
        config = config or SacConfig()
        config.validate()
    else:
        with store.session() as session:
            found = session.get(RlRun, resume_run_id)
            if found is None:
                raise ValueError(
                    f"there is no SAC run {resume_run_id} in the database (see `twisted rl list`)"
                )
            if found.status == "finished":
                raise ValueError(f"SAC run {resume_run_id} has finished: start a new run instead")
            config = SacConfig.from_stored(found.parameters, found.id)
            resume_row = session.scalars(
                select(RlCheckpoint)
                .where(RlCheckpoint.rl_run_id == found.id)
                .order_by(RlCheckpoint.id.desc())
                .limit(1)
            ).first()
            if resume_row is not None:  # where the run goes back to, checked before anything is written
                resumed_at = checkpoint_counters(resume_row)
    env = make_env(config, _url(store))
    vec_env = DummyVecEnv([lambda: Monitor(env)])
    model = _new_model(config, vec_env)
    without_buffer = False
    if resume_row is not None:
        # the stored state is read (tensors and plain data only) and checked before anything is written
        what = f"SAC checkpoint {resume_row.id} of run {resume_run_id}"
        try:
            apply_policy(model, read_policy(resume_row.policy, what), what)
            if resume_row.replay_buffer is not None and read_replay_buffer:
                limit = _buffer_limit(model.replay_buffer)
                apply_buffer(
                    model, read_buffer(resume_row.replay_buffer, f"the replay buffer of {what}", limit), what
                )
            else:
                without_buffer = True
        except BaseException:
            vec_env.close()
            raise
    with store.session(write=True) as session:
        if resume_run_id is not None:
            run = session.get(RlRun, resume_run_id)
            assert run is not None
            # the counters go back to the checkpoint (or to 0): steps after it are lost with the process
            run.steps_done, run.episodes, run.elapsed_s = resumed_at
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

    if resume_row is not None:
        model.set_random_seed(config.seed + steps_at_start)
        if without_buffer:
            metrics["resumed_without_replay_buffer"] = True
    else:
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
