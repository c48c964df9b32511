"""Nothing loaded from the store runs code (issue 37, item 1; docs/security.md).

Every place a payload comes out of the store gets a crafted one, a pickle whose ``__reduce__`` would
create a file when unpickled, and the command that reads it must refuse it with exit 2 without the
file appearing: training checkpoints (``train --resume``), model weights (``models --export``,
``plan``), SAC policies (``plan --planner sac``, ``rl train --resume``), SAC replay buffers
(``rl train --resume``), and planner checkpoints and nodes (``plan --resume``, which read JSON and raw
float64 arrays). The formats of earlier versions stay readable where that is safe (an SB3 ``SAC.save``
archive: its tensors and JSON, never its pickled entries).
"""

from __future__ import annotations

import hashlib
import io
import json
import pickle
import sqlite3
import zlib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from cli.main import app
from twisted.store import open_store
from twisted.store.payloads import UnsafePayloadError, load_tensors

runner = CliRunner()
ONE = '[[1,"O",2,"+"],[2,"U",1,"+"]]'


class Planted:
    """Unpickling this opens (creates) ``path`` for writing: the stand-in for any code."""

    def __init__(self, path: Path) -> None:
        self.path = str(path)

    def __reduce__(self) -> tuple[Any, ...]:
        return (open, (self.path, "w"))


def torch_bomb(path: Path, wrap: Any = None) -> bytes:
    """A torch file (zip) whose pickle holds :class:`Planted` (inside ``wrap``'s dict when given)."""
    buf = io.BytesIO()
    torch.save({**(wrap or {}), "net": Planted(path)}, buf)
    return buf.getvalue()


def pickle_bomb(path: Path) -> bytes:
    """A bare pickle of :class:`Planted` (torch reads it as its legacy format)."""
    return pickle.dumps(Planted(path))


def digest(db: Path) -> str:
    conn = sqlite3.connect(f"{db.resolve().as_uri()}?mode=ro", uri=True)
    try:
        return hashlib.sha256("\n".join(conn.iterdump()).encode()).hexdigest()
    finally:
        conn.close()


def refused(args: list[str], db: Path, marker: Path) -> str:
    """Run the CLI: it must exit 2, leave the store as it was, and not create ``marker``."""
    before = digest(db)
    result = runner.invoke(app, ["--db", f"sqlite:///{db}", *args])
    assert result.exit_code == 2, result.output
    assert not marker.exists(), "a payload from the store ran code"
    assert digest(db) == before, "a refused payload changed the store"
    assert "Traceback" not in result.output
    return " ".join(result.output.split())


@pytest.fixture
def db(tmp_path: Path) -> Path:
    path = tmp_path / "t.db"
    open_store(f"sqlite:///{path}").close()
    return path


# ---- the loader itself --------------------------------------------------------------------------------


@pytest.mark.parametrize("make", [torch_bomb, pickle_bomb])
def test_load_tensors_refuses_a_pickle_that_names_code(tmp_path: Path, make: Any) -> None:
    marker = tmp_path / "ran"
    with pytest.raises(UnsafePayloadError, match="could run code"):
        load_tensors(make(marker), "payload 7")
    assert not marker.exists()


def test_load_tensors_reads_tensors_and_plain_data() -> None:
    buf = io.BytesIO()
    state = {"w": torch.arange(3.0), "n": 4, "f": float("inf"), "t": (1, "a"), "none": None}
    torch.save(state, buf)
    back = load_tensors(buf.getvalue(), "x")
    assert back["n"] == 4 and back["t"] == (1, "a") and torch.equal(back["w"], state["w"])
    for junk in (b"", b"junk", b"\x80\x04K\x01."[:3]):
        with pytest.raises(UnsafePayloadError, match="payload 1 cannot be loaded"):
            load_tensors(junk, "payload 1")


# ---- training checkpoints: train --resume ------------------------------------------------------------


@pytest.mark.parametrize("kind", ["torch", "pickle"])
def test_train_resume_refuses_a_planted_checkpoint(db: Path, tmp_path: Path, kind: str) -> None:
    from twisted.model.config import TrainConfig
    from twisted.store.training import Checkpoint, TrainingRun

    marker = tmp_path / "ran"
    payload = torch_bomb(marker, {"epoch": 0}) if kind == "torch" else pickle_bomb(marker)
    with open_store(f"sqlite:///{db}") as store, store.session(write=True) as session:
        run = TrainingRun(
            seed=0,
            parameters=TrainConfig().to_dict(),
            max_transition_id=0,
            status="interrupted",
            n_train=0,
            n_val=0,
            epochs_done=0,
            elapsed_s=1.0,
            metrics={},
        )
        session.add(run)
        session.flush()
        session.add(
            Checkpoint(training_run_id=run.id, epoch=0, batch_index=1, elapsed_s=1.0, payload=payload)
        )
    out = refused(["train", "--resume"], db, marker)
    assert "checkpoint 1 of training run 1 cannot be loaded" in out


def test_a_real_checkpoint_reads_back_as_plain_data() -> None:
    """What train.py stores (weights, AdamW state, RNG state, numbers) passes the restricted loader."""
    from twisted.model.config import NetConfig, TrainConfig
    from twisted.model.network import InverseNet

    config = TrainConfig(net=NetConfig(hidden=16, layers=1))
    net = InverseNet(config.net)
    opt = torch.optim.AdamW(net.parameters(), lr=1e-3)
    sum(p.sum() for p in net.parameters()).backward()
    opt.step()
    state = {
        "net": net.state_dict(),
        "optimizer": opt.state_dict(),
        "epoch": 2,
        "batch_index": 3,
        "torch_rng": torch.get_rng_state(),
        "best_val_loss": float("inf"),
        "best_epoch": -1,
        "best_net": None,
    }
    buf = io.BytesIO()
    torch.save(state, buf)
    back = load_tensors(buf.getvalue(), "checkpoint")
    assert back["optimizer"]["param_groups"] == opt.state_dict()["param_groups"]
    assert torch.equal(back["torch_rng"], state["torch_rng"])


# ---- model weights: models --export, plan --------------------------------------------------------------


def _plant_model(db: Path, weights: bytes) -> None:
    from twisted.store.training import TrainedModel

    with open_store(f"sqlite:///{db}") as store, store.session(write=True) as session:
        session.add(
            TrainedModel(name="planted", data_size=0, metrics={}, config={}, size_bytes=1, weights=weights)
        )


def test_models_export_and_plan_refuse_planted_weights(db: Path, tmp_path: Path) -> None:
    marker = tmp_path / "ran"
    _plant_model(db, torch_bomb(marker))
    out = refused(["models", "--export", str(tmp_path / "out.pt")], db, marker)
    assert "could run code" in out
    assert not (tmp_path / "out.pt").exists()
    out = refused(["plan", "--goal", ONE, "--workers", "1"], db, marker)
    assert "could run code" in out


# ---- SAC policies and replay buffers ---------------------------------------------------------------------


sb3 = pytest.importorskip  # the rl extra is optional: the SAC tests skip without it


@pytest.fixture
def sac_run(db: Path) -> Any:
    """A SAC run row (interrupted, small settings) and a function that stores a checkpoint for it."""
    sb3("stable_baselines3", reason="the rl extra is not installed")
    from twisted.rl import SacConfig
    from twisted.store.rl import RlCheckpoint, RlRun

    config = SacConfig(total_steps=40, max_curves=3, learning_starts=10, batch_size=8, net_arch=(16, 16))
    with open_store(f"sqlite:///{db}") as store, store.session(write=True) as session:
        run = RlRun(status="interrupted", seed=0, parameters=config.to_dict(), total_steps=40, metrics={})
        session.add(run)
        session.flush()
        run_id = run.id

    def store_checkpoint(policy: bytes, buffer: bytes | None) -> int:
        with open_store(f"sqlite:///{db}") as store, store.session(write=True) as session:
            row = RlCheckpoint(
                rl_run_id=run_id,
                steps=20,
                episodes=2,
                elapsed_s=1.0,
                policy=policy,
                replay_buffer=buffer,
                size_bytes=len(policy),
            )
            session.add(row)
            session.flush()
            return row.id

    return config, run_id, store_checkpoint


def _model(config: Any) -> Any:
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    from twisted.rl.sac import _new_model, make_env

    env = make_env(config)
    return _new_model(config, DummyVecEnv([lambda: Monitor(env)]))


@pytest.mark.parametrize("kind", ["torch", "pickle"])
def test_sac_policy_planted_is_refused_by_plan_and_rl_resume(
    sac_run: Any, db: Path, tmp_path: Path, kind: str
) -> None:
    _config, run_id, store_checkpoint = sac_run
    marker = tmp_path / "ran"
    policy = torch_bomb(marker) if kind == "torch" else pickle_bomb(marker)
    policy_id = store_checkpoint(policy, None)
    out = refused(
        ["plan", "--goal", ONE, "--planner", "sac", "--model", str(policy_id), "--workers", "1"], db, marker
    )
    assert f"SAC policy {policy_id} cannot be loaded" in out
    out = refused(["rl", "train", "--resume", str(run_id)], db, marker)
    assert "cannot be loaded" in out


def test_sac_replay_buffer_planted_or_pickled_is_refused(sac_run: Any, db: Path, tmp_path: Path) -> None:
    from twisted.rl.sac import _policy_bytes

    config, run_id, store_checkpoint = sac_run
    policy = _policy_bytes(_model(config))
    marker = tmp_path / "ran"
    store_checkpoint(policy, zlib.compress(torch_bomb(marker)))
    out = refused(["rl", "train", "--resume", str(run_id)], db, marker)
    assert "replay buffer" in out and "could run code" in out
    # the format of earlier versions, a pickled buffer, is never unpickled: refused, with the way on
    store_checkpoint(policy, zlib.compress(pickle_bomb(marker)))
    out = refused(["rl", "train", "--resume", str(run_id)], db, marker)
    assert "not read" in out and "--no-replay-buffer" in out
    # a compressed bomb is refused before it is unpacked beyond the size of the run's buffer
    store_checkpoint(policy, zlib.compress(b"PK" + bytes(200_000_000)))
    out = refused(["rl", "train", "--resume", str(run_id)], db, marker)
    assert "unpacks to more than" in out


def test_sac_state_round_trips_and_old_sb3_archives_load_without_their_pickles(
    sac_run: Any, tmp_path: Path
) -> None:
    import base64

    from twisted.rl.sac import (
        _buffer_bytes,
        _buffer_limit,
        _policy_bytes,
        apply_buffer,
        apply_policy,
        inference_model,
        read_buffer,
        read_policy,
    )

    config, *_ = sac_run
    model = _model(config)
    model.learn(total_timesteps=24)
    obs = {k: v[None] for k, v in model.observation_space.sample().items()}
    want = model.predict(obs, deterministic=True)[0]

    other = _model(config)
    apply_policy(other, read_policy(_policy_bytes(model), "p"), "p")
    apply_buffer(other, read_buffer(_buffer_bytes(model), "b", _buffer_limit(other.replay_buffer)), "b")
    assert other.num_timesteps == model.num_timesteps and other.replay_buffer.pos == model.replay_buffer.pos
    np.testing.assert_array_equal(other.replay_buffer.actions, model.replay_buffer.actions)
    np.testing.assert_allclose(other.predict(obs, deterministic=True)[0], want)

    # SAC.save, the format of earlier versions; a pickled entry of its JSON is made to create a file
    buf = io.BytesIO()
    model.save(buf)
    marker = tmp_path / "ran"
    import zipfile

    archive = zipfile.ZipFile(io.BytesIO(buf.getvalue()))
    data = json.loads(archive.read("data"))
    data["observation_space"][":serialized:"] = base64.b64encode(pickle.dumps(Planted(marker))).decode()
    rebuilt = io.BytesIO()
    with zipfile.ZipFile(rebuilt, "w") as out:
        for name in archive.namelist():
            out.writestr(name, json.dumps(data) if name == "data" else archive.read(name))
    old = inference_model(rebuilt.getvalue(), config.to_dict(), "old policy")
    assert not marker.exists()
    np.testing.assert_allclose(old.predict(obs, deterministic=True)[0], want)
    assert old.num_timesteps == model.num_timesteps


# ---- planner checkpoints and nodes: JSON and raw float64 arrays --------------------------------------------


def test_planner_checkpoint_and_nodes_hold_no_code(db: Path, tmp_path: Path) -> None:
    """A pickle planted in a planner checkpoint (JSON) or node (float64 BLOB) is data, never code."""
    from twisted.store.search_tree import SearchCheckpoint, SearchNode

    result = runner.invoke(
        app,
        [
            "--db",
            f"sqlite:///{db}",
            "plan",
            "--goal",
            ONE,
            "--planner",
            "random-low",
            "--max-iterations",
            "1",
            "--workers",
            "1",
            "--json",
        ],
    )
    assert result.exit_code in (0, 3), result.output
    run_id = json.loads(result.output)["run_id"]
    marker = tmp_path / "ran"
    with open_store(f"sqlite:///{db}") as store, store.session(write=True) as session:
        ckpt = session.get(SearchCheckpoint, run_id)
        ckpt.rng_state = pickle_bomb(marker).decode("latin-1")
        node = session.query(SearchNode).filter(SearchNode.run_id == run_id).first()
        node.q = pickle_bomb(marker)
    result = runner.invoke(
        app, ["--db", f"sqlite:///{db}", "plan", "--resume", str(run_id), "--workers", "1"]
    )
    assert not marker.exists()
    assert result.exit_code == 2 and "damaged" in result.output, result.output


def test_a_plan_run_that_dies_is_marked_failed_with_the_reason(db: Path) -> None:
    """Item 4: a search that dies of an exception is not left ``running`` (nor resumable as such)."""
    url = f"sqlite:///{db}"
    args = ["plan", "--goal", ONE, "--planner", "random-low", "--max-iterations", "1", "--workers", "1"]
    result = runner.invoke(app, ["--db", url, *args, "--json"])
    assert result.exit_code in (0, 3), result.output
    run_id = json.loads(result.output)["run_id"]
    conn = sqlite3.connect(db)
    # stored states of the wrong length (a multiple of 8 bytes, so they read back): the simulator refuses them
    conn.execute("update search_nodes set q = ? where run_id = ?", (bytes(8 * 5), run_id))
    conn.commit()
    result = runner.invoke(app, ["--db", url, "plan", "--resume", str(run_id), "--workers", "1"])
    assert result.exit_code != 0
    status, message = conn.execute("select status, message from runs where id = ?", (run_id,)).fetchone()
    conn.close()
    assert status == "failed" and message.startswith("ValueError"), (status, message)


# ---- issue 62: payloads bounded by what they declare, before anything is unpacked -------------------------


def deflated(payload: bytes) -> bytes:
    """``payload`` (a torch zip) with every member deflated: what torch.save never writes."""
    import zipfile

    src = zipfile.ZipFile(io.BytesIO(payload))
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as archive:
        for info in src.infolist():
            archive.writestr(info.filename, src.read(info.filename))
    return out.getvalue()


def _torch_bytes(obj: Any) -> bytes:
    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def test_load_tensors_refuses_compressed_members_and_views_beyond_their_storage() -> None:
    """Item 1 / 9: a few kilobytes that inflate to megabytes, or one byte seen as 10^8, are refused from
    the zip directory / the storage size, before anything is unpacked or iterated."""
    bomb = deflated(_torch_bytes({"w": torch.zeros(5_000_000, dtype=torch.uint8)}))
    assert len(bomb) < 10_000
    with pytest.raises(UnsafePayloadError, match="is compressed .* unpack"):
        load_tensors(bomb, "payload 3")
    view = _torch_bytes({"w": torch.zeros(1, dtype=torch.uint8).expand(100_000_000)})
    with pytest.raises(UnsafePayloadError, match="claims 100,000,000 bytes over a storage of 1"):
        load_tensors(view, "payload 4")
    plain = _torch_bytes({"w": torch.arange(4.0)})
    with pytest.raises(UnsafePayloadError, match="more than the 10"):
        load_tensors(plain, "payload 5", max_bytes=10)
    assert torch.equal(load_tensors(plain, "payload 5", max_bytes=len(plain))["w"], torch.arange(4.0))


def test_sac_replay_buffer_of_the_wrong_shape_is_refused_without_touching_its_elements(
    sac_run: Any, db: Path, tmp_path: Path
) -> None:
    """Item 1: a tensor where the run's buffer has a dict of arrays (and a deflated one), exit 2 at once,
    and the message is not built from the stored elements."""
    from twisted.rl.sac import BUFFER_FORMAT, _policy_bytes

    config, run_id, store_checkpoint = sac_run
    policy = _policy_bytes(_model(config))
    marker = tmp_path / "ran"
    for observations in (torch.zeros(20_000, dtype=torch.uint8), [0] * 20_000, "x" * 20_000):
        state = {"format": BUFFER_FORMAT, "pos": 0, "full": False, "arrays": {"observations": observations}}
        store_checkpoint(policy, zlib.compress(_torch_bytes(state)))
        out = refused(["rl", "train", "--resume", str(run_id), "--threads", "1"], db, marker)
        assert "observations is a" in out and len(out) < 600, out
    state = {"format": BUFFER_FORMAT, "arrays": {"observations": torch.zeros(5_000_000, dtype=torch.uint8)}}
    store_checkpoint(policy, zlib.compress(deflated(_torch_bytes(state))))
    out = refused(["rl", "train", "--resume", str(run_id), "--threads", "1"], db, marker)
    assert "is compressed" in out


def test_model_weights_are_bounded_by_their_row_and_their_config(db: Path, tmp_path: Path) -> None:
    """Item 9: deflated weights (even of a good model) are refused by `models --import` and `plan` before
    anything is unpacked; a config that declares another network is refused before that one is built."""
    from twisted.model.registry import default_model_path

    good = default_model_path().read_bytes()
    packed = tmp_path / "packed.pt"
    packed.write_bytes(deflated(good))
    assert len(packed.read_bytes()) < len(good)
    marker = tmp_path / "ran"
    out = refused(["models", "--import", str(packed)], db, marker)
    assert "is compressed" in out
    _plant_model(db, packed.read_bytes())
    out = refused(["plan", "--goal", ONE, "--workers", "1", "--timeout", "5"], db, marker)
    assert "is compressed" in out

    blob = load_tensors(good, "good")
    blob["config"]["hidden"] *= 8  # an architecture 64 times the weights it comes with
    wide = tmp_path / "wide.pt"
    wide.write_bytes(_torch_bytes(blob))
    out = refused(["models", "--import", str(wide)], db, marker)
    assert "do not fit the architecture its config declares" in out
