"""Training from the store: data loading and split, resume from a checkpoint, stored models, CLI."""

from __future__ import annotations

import io
import json
from collections.abc import Iterator
from dataclasses import replace

import numpy as np
import pytest
import torch
from sqlalchemy import select
from typer.testing import CliRunner

from cli.main import app
from tests.test_model import SMALL, random_rope
from twisted.model.config import TrainConfig
from twisted.model.data import NoTrainingDataError, load_transitions, split_by_start
from twisted.model.network import InverseModel, InverseNet
from twisted.model.registry import ModelError, default_model_path, list_models, load_model
from twisted.model.success import held_out_transitions, step_name
from twisted.model.train import train
from twisted.sim import sample_curve
from twisted.store import Configuration, Transition, open_store
from twisted.store.queries import add_configuration, start_run
from twisted.store.training import Checkpoint, TrainedModel, TrainingRun
from twisted.topology import top


@pytest.fixture(autouse=True)
def one_torch_thread() -> Iterator[None]:
    """Tiny batches: one thread is faster, and far faster on a shared, busy machine."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def fill_store(url: str, n_transitions: int, seed: int = 0, removing: int = 0) -> dict[str, int]:
    """A small store of synthetic transitions between random ropes (cross rising by 1 or 2; a few flat
    ones), and ``removing`` more whose cross falls by 1 (``counts["minus1"]``)."""
    rng = np.random.default_rng(seed)
    store = open_store(url)
    by_cross: dict[int, list[int]] = {}
    counts = {"plus1": 0, "plus2": 0, "too_long": 0, "flat": 0, "minus1": 0}
    with store.session(write=True) as session:
        run = start_run(session, "collect", {"synthetic": True}, seed=seed)
        for s in range(4 * n_transitions):
            pts = random_rope(seed * 100_000 + s, bend=0.6)
            p = top(pts)
            if p.cross > 4:
                continue
            c = add_configuration(session, run_id=run.id, p_data=p, q=np.zeros(93), points=pts)
            by_cross.setdefault(p.cross, []).append(c.id)
        made = 0
        while made < n_transitions + removing:
            a = int(rng.integers(0, 3))
            step = 1 if rng.random() < 0.7 else 2
            if rng.random() < 0.05:
                step = 0  # transitions that add no crossing are not training data
            if made >= n_transitions:
                a, step = a + 1, -1  # the rest remove a crossing
            if not by_cross.get(a) or not by_cross.get(a + step):
                continue
            src = int(rng.choice(by_cross[a]))
            dst = int(rng.choice(by_cross[a + step]))
            curve = sample_curve(rng)
            cs, cd = session.get(Configuration, src), session.get(Configuration, dst)
            session.add(
                Transition(
                    run_id=run.id,
                    from_configuration_id=src,
                    to_configuration_id=dst,
                    link=curve.link,
                    z_max_m=curve.z_max_m,
                    x_m=curve.x_m,
                    y_m=curve.y_m,
                    from_state_id=cs.state_id,
                    to_state_id=cd.state_id,
                    from_cross=cs.cross,
                    to_cross=cd.cross,
                )
            )
            counts["flat" if step == 0 else f"plus{step}" if step > 0 else "minus1"] += 1
            made += step != 0
    store.close()
    return counts


@pytest.fixture
def small_store(sqlite_url: str) -> tuple[str, dict[str, int]]:
    return sqlite_url, fill_store(sqlite_url, 120)


FAST = dict(batch_size=16, lr=1e-3, seed=3, val_fraction=0.25, net=SMALL)


def test_empty_database_asks_to_collect_first(sqlite_url: str) -> None:
    store = open_store(sqlite_url)
    with pytest.raises(NoTrainingDataError, match="collect first"):
        train(store, TrainConfig(epochs=1, **FAST))
    result = CliRunner().invoke(app, ["--db", sqlite_url, "train", "--epochs", "1"])
    assert result.exit_code == 2
    assert "collect first" in result.output


def test_loading_in_chunks_reads_every_adding_transition_once(
    small_store: tuple[str, dict[str, int]],
) -> None:
    url, counts = small_store
    store = open_store(url)
    whole = load_transitions(store)
    chunked = load_transitions(store, chunk_size=7)
    assert len(whole) == counts["plus1"] + counts["plus2"]  # +1 and +2 steps, never flat ones
    assert np.array_equal(whole.transition_ids, chunked.transition_ids)
    assert torch.equal(whole.points, chunked.points) and torch.equal(whole.curves, chunked.curves)
    assert set(np.unique(whole.to_cross - whole.from_cross)) == {1, 2}
    # state encodings: 4 variants per state, and the identity variant of each state differs from its mirror
    assert whole.state_enc.shape[1] == 4
    limited = load_transitions(store, max_id=int(whole.transition_ids[9]))
    assert len(limited) == 10


def test_removing_transitions_train_the_model_only_when_asked(tmp_path) -> None:
    url = f"sqlite:///{tmp_path / 'r.db'}"
    counts = fill_store(url, 80, seed=4, removing=40)
    assert counts["minus1"] == 40
    store = open_store(url)
    adding = load_transitions(store)
    both = load_transitions(store, removing=True)
    assert len(adding) == counts["plus1"] + counts["plus2"]
    assert len(both) == len(adding) + 40  # flat ones never
    assert set(np.unique(both.to_cross - both.from_cross)) == {-1, 1, 2}
    assert set(adding.transition_ids) < set(both.transition_ids)
    # a removing pair's move, where one explains it, is marked -1 in its kind's entry (encode_move)
    removing = np.flatnonzero(both.to_cross < both.from_cross)
    kinds = both.move_enc[both.pair[removing], 0, 1:4]
    assert (kinds <= 0).all() and (kinds < 0).any(dim=1).sum() > len(removing) // 2
    runs = {}
    for flag in (True, False):
        done = train(store, TrainConfig(epochs=1, removing=flag, **FAST))
        with store.session() as session:
            run = session.get_one(TrainingRun, done.training_run_id)
            runs[flag] = (run.n_train + run.n_val, run.parameters["removing"])
    assert runs == {True: (len(both), True), False: (len(adding), False)}
    # a run stored before the option trained on adding transitions only, and resumes so
    params = TrainConfig(epochs=1, **FAST).to_dict()
    del params["removing"]
    assert TrainConfig.from_dict(params).removing is False
    result = CliRunner().invoke(app, ["--db", url, "train", "--help"])
    assert "--no-removing" in result.output


def test_success_steps_name_removing_transitions(tmp_path) -> None:
    names = (step_name(3, 2), step_name(4, 2), step_name(2, 4), step_name(0, 1))
    assert names == ("3->2", "-2", "+2", "0->1")
    url = f"sqlite:///{tmp_path / 's.db'}"
    fill_store(url, 40, seed=5, removing=30)
    store = open_store(url)
    model = InverseModel(InverseNet(SMALL), metadata={})  # no snapshot: every transition is held out
    steps = ("1->0", "2->1", "3->2")
    held = held_out_transitions(store, model, per_step=1000, rng=np.random.default_rng(0), steps=steps)
    assert len(held) == 30
    assert all(h.p_to.cross == h.p_from.cross - 1 and h.step in steps for h in held)


def test_split_never_puts_a_start_configuration_on_both_sides() -> None:
    starts = np.random.default_rng(0).integers(0, 300, 2000)
    train_idx, val_idx = split_by_start(starts, 0.2, seed=5)
    assert not set(starts[train_idx]) & set(starts[val_idx])
    assert len(train_idx) + len(val_idx) == len(starts)
    assert 0.1 < len(val_idx) / len(starts) < 0.3
    again = split_by_start(starts, 0.2, seed=5)
    assert np.array_equal(again[1], val_idx)
    assert not np.array_equal(split_by_start(starts, 0.2, seed=6)[1], val_idx)


def test_interrupted_training_resumes_with_the_same_batches_and_weights(tmp_path) -> None:
    config = TrainConfig(epochs=3, **FAST)
    runs = {}
    for name in ("straight", "interrupted"):
        url = f"sqlite:///{tmp_path / name}.db"
        fill_store(url, 120, seed=1)
        runs[name] = url
    seen_straight: list[list[int]] = []
    store = open_store(runs["straight"])
    done = train(store, config, on_batch=lambda idx: seen_straight.append(idx.tolist()))
    assert done.status == "finished" and done.model_id is not None
    per_epoch = len(seen_straight) // 3
    assert per_epoch >= 3

    # stop in the middle of epoch 1, then resume
    seen: list[list[int]] = []
    store2 = open_store(runs["interrupted"])
    stop_after = per_epoch + 2
    first = train(
        store2,
        config,
        on_batch=lambda idx: seen.append(idx.tolist()),
        should_stop=lambda: len(seen) >= stop_after,
    )
    assert first.status == "interrupted" and first.model_id is None
    with store2.session() as session:
        run = session.get(TrainingRun, first.training_run_id)
        assert run.status == "interrupted"
        ckpt = session.scalars(select(Checkpoint).order_by(Checkpoint.id.desc())).first()
        assert (ckpt.epoch, ckpt.batch_index) == (1, 2)
    second = train(store2, resume=True, on_batch=lambda idx: seen.append(idx.tolist()))
    assert second.status == "finished" and second.training_run_id == first.training_run_id
    assert seen == seen_straight
    a = load_model(open_store(runs["straight"])).net.state_dict()
    b = load_model(store2).net.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert second.metrics["val_loss"] == pytest.approx(done.metrics["val_loss"], rel=1e-6)
    with pytest.raises(ValueError, match="no unfinished training run"):
        train(store2, resume=True)


def test_finished_model_is_stored_listed_and_loaded_newest_first(
    small_store: tuple[str, dict[str, int]],
) -> None:
    url, _ = small_store
    store = open_store(url)
    first = train(store, TrainConfig(epochs=1, **FAST))
    second = train(store, TrainConfig(epochs=2, **FAST))
    models = list_models(store)
    assert [m.id for m in models] == [second.model_id, first.model_id]
    info = models[0]
    assert info.training_run_id == second.training_run_id and info.data_size == second.n_train > 0
    assert {"val_loss", "val_nll_link", "val_link_accuracy"} <= set(info.metrics)
    assert 0 <= info.metrics["val_link_accuracy"] <= 1
    # the stored weights are those of the epoch with the lowest validation loss
    with store.session() as session:
        history = session.get(TrainingRun, second.training_run_id).metrics["history"]
    assert [h["epoch"] for h in history] == [0, 1]
    best = min(history, key=lambda h: h["val_loss"])
    assert info.metrics["best_epoch"] == best["epoch"]
    assert info.metrics["val_loss"] == pytest.approx(best["val_loss"], rel=1e-5)
    newest = load_model(store)
    assert newest.model_id == second.model_id and newest.metadata["data_size"] == second.n_train
    assert load_model(store, first.model_id).model_id == first.model_id
    with pytest.raises(ModelError, match="no model 999"):
        load_model(store, 999)
    # a model stored by an incompatible version is refused with what to do
    blob = torch.load(io.BytesIO(newest.to_bytes()), weights_only=True)
    blob["format_version"] = 999
    buffer = io.BytesIO()
    torch.save(blob, buffer)
    with store.session(write=True) as session:
        session.get(TrainedModel, second.model_id).weights = buffer.getvalue()
    with pytest.raises(ModelError, match="format 999.*train a new one"):
        load_model(store)
    curves = load_model(store, first.model_id).sample(
        random_rope(1), None, top(random_rope(2, bend=0.9)), 6, np.random.default_rng(0)
    )
    assert len(curves) == 6


def test_an_empty_model_table_falls_back_to_the_shipped_default(sqlite_url: str) -> None:
    store = open_store(sqlite_url)
    path = default_model_path()
    if not path.is_file():
        with pytest.raises(ModelError, match="train one with `twisted train`"):
            load_model(store)
        return
    model = load_model(store)
    assert model.model_id is None
    assert model.metadata == InverseModel.from_bytes(path.read_bytes()).metadata
    assert model.metadata["data_size"] > 0
    assert path.stat().st_size <= 10 * 1024 * 1024


def test_cli_train_then_models(small_store: tuple[str, dict[str, int]], tmp_path) -> None:
    url, _ = small_store
    runner = CliRunner()
    result = runner.invoke(
        app, ["--db", url, "train", "--epochs", "1", "--batch-size", "32", "--hidden", "32", "--seed", "4"]
    )
    assert result.exit_code == 0, result.output
    assert "val" in result.output
    result = runner.invoke(app, ["--db", url, "models"])
    assert result.exit_code == 0, result.output
    assert "run-1" in result.output
    exported = tmp_path / "exported.pt"
    result = runner.invoke(app, ["--db", url, "models", "--export", str(exported)])
    assert result.exit_code == 0, result.output
    assert InverseModel.from_bytes(exported.read_bytes()).metadata["training_run_id"] == 1
    result = runner.invoke(app, ["--db", url, "train", "--resume"])
    assert result.exit_code == 2 and "no unfinished training run" in result.output


def test_held_out_transitions_are_the_validation_side_and_newer_ones(tmp_path) -> None:
    url = f"sqlite:///{tmp_path / 'h.db'}"
    fill_store(url, 150, seed=2)
    store = open_store(url)
    data = load_transitions(store)
    cut = int(data.transition_ids[99])
    config = TrainConfig(epochs=1, **FAST)
    # a model whose data snapshot ends at `cut`: every later transition is held out
    model = InverseModel(
        InverseNet(SMALL), metadata={"max_transition_id": cut, "parameters": config.to_dict()}
    )
    steps = ("0->1", "1->2", "2->3", "+2")
    held = held_out_transitions(store, model, per_step=1000, rng=np.random.default_rng(0), steps=steps)
    snapshot = data.transition_ids <= cut
    train_idx, _ = split_by_start(data.start_ids[snapshot], config.val_fraction, config.seed)
    train_starts = set(data.start_ids[snapshot][train_idx])
    names = np.array([step_name(a, b) for a, b in zip(data.from_cross, data.to_cross, strict=True)])
    _, val_all = split_by_start(data.start_ids, config.val_fraction, config.seed)
    val_starts = set(data.start_ids[val_all])
    expected = {
        int(t)
        for t, start, name in zip(data.transition_ids, data.start_ids, names, strict=True)
        if name in steps and (start in val_starts or (t > cut and start not in train_starts))
    }
    assert {h.transition_id for h in held} == expected
    assert any(h.transition_id > cut for h in held) and any(h.transition_id <= cut for h in held)
    assert all(data.start_ids[data.transition_ids == h.transition_id][0] not in train_starts for h in held)
    by_id = dict(zip(data.transition_ids.tolist(), names, strict=True))
    for h in held:
        assert h.step == by_id[h.transition_id]
        assert h.points.shape == (22, 3) and h.p_to.cross > h.p_from.cross
    few = held_out_transitions(store, model, per_step=2, rng=np.random.default_rng(0), steps=steps)
    assert len(few) <= 2 * len(steps)


def test_time_budget_stops_early_and_still_stores_a_model(small_store: tuple[str, dict[str, int]]) -> None:
    url, _ = small_store
    store = open_store(url)
    seen: list[int] = []
    done = train(
        store, TrainConfig(epochs=50, hours=1e-9, **FAST), on_batch=lambda idx: seen.append(len(idx))
    )
    assert done.status == "finished" and done.model_id is not None
    assert len(seen) == 1  # the budget is checked after every batch
    with store.session() as session:
        run = session.get(TrainingRun, done.training_run_id)
        assert run.status == "finished" and run.epochs_done == 0


def test_models_import_stores_an_exported_model_and_refuses_other_files(tmp_path) -> None:
    runner = CliRunner()
    url = f"sqlite:///{tmp_path / 'imp.db'}"
    junk = tmp_path / "junk.pt"
    junk.write_text("not a model")
    for args, named in (
        (["--import", str(junk)], "--import"),
        (["--import", str(tmp_path / "missing.pt")], "--import"),
        (["--name", "x"], "--import"),
        (["--import", str(default_model_path()), "--export", str(tmp_path / "o.pt")], "--export"),
    ):
        result = runner.invoke(app, ["--db", url, "models", *args])
        assert result.exit_code == 2 and named in result.output, (args, result.output)
        assert not (tmp_path / "imp.db").exists()  # refused before the database is opened
    args = ["--import", str(default_model_path()), "--name", "shipped"]
    result = runner.invoke(app, ["--db", url, "models", *args])
    assert result.exit_code == 0, result.output
    store = open_store(url)
    [info] = list_models(store)
    assert info.name == "shipped" and info.training_run_id is None
    model, shipped = load_model(store), load_model(None)
    assert model.model_id == info.id and info.data_size == shipped.metadata["data_size"]
    for a, b in zip(model.net.state_dict().values(), shipped.net.state_dict().values(), strict=True):
        assert torch.equal(a, b)
    store.close()
    # exported again, it is the same model
    out = tmp_path / "again.pt"
    assert runner.invoke(app, ["--db", url, "models", "--export", str(out)]).exit_code == 0
    again = InverseModel.from_bytes(out.read_bytes())
    assert again.metadata == shipped.metadata


def test_fine_tuning_starts_from_a_stored_model_and_keeps_its_architecture(
    small_store: tuple[str, dict[str, int]],
) -> None:
    url, _ = small_store
    store = open_store(url)
    base = train(store, TrainConfig(epochs=1, **FAST))
    base_model = load_model(store, base.model_id)
    # the architecture asked for is replaced by the starting model's (SMALL)
    other = replace(FAST["net"], hidden=FAST["net"].hidden * 2)
    tuned = train(store, TrainConfig(epochs=2, **{**FAST, "net": other}, init_model_id=base.model_id))
    model = load_model(store, tuned.model_id)
    assert model.net.config == base_model.net.config
    assert model.metadata["init_model_id"] == base.model_id
    assert tuned.metrics["init_model_id"] == base.model_id
    with store.session() as session:
        run = session.get(TrainingRun, tuned.training_run_id)
        history = run.metrics["history"]
        assert run.parameters["init_model_id"] == base.model_id
    # the starting weights are scored first, on the same validation samples as the epochs
    assert [h["epoch"] for h in history] == [-1, 0, 1]
    assert history[0]["val_loss"] == pytest.approx(base.metrics["val_loss"], rel=1e-5)
    best = min(history, key=lambda h: h["val_loss"])
    assert tuned.metrics["best_epoch"] == best["epoch"]
    assert tuned.metrics["val_loss"] == pytest.approx(best["val_loss"], rel=1e-5)
    # the first epoch moved on from the starting weights, not from a fresh initialisation
    fresh = train(store, TrainConfig(epochs=1, **FAST))
    assert history[1]["val_loss"] != pytest.approx(fresh.metrics["val_loss"], rel=1e-6)
    # a fine-tuning that never improves stores the starting weights unchanged
    still = train(store, TrainConfig(epochs=1, **{**FAST, "lr": 0.0}, init_model_id=base.model_id))
    assert still.metrics["best_epoch"] == -1
    kept = load_model(store, still.model_id).net.state_dict()
    for name, tensor in base_model.net.state_dict().items():
        assert torch.equal(kept[name], tensor), name


def test_cli_fine_tuning_checks_its_starting_model_before_writing(
    small_store: tuple[str, dict[str, int]],
) -> None:
    url, _ = small_store
    runner = CliRunner()
    args = ["--db", url, "train", "--epochs", "1", "--batch-size", "32", "--seed", "4"]
    assert runner.invoke(app, [*args, "--hidden", "32"]).exit_code == 0
    store = open_store(url)
    with store.session() as session:
        runs_before = len(session.scalars(select(TrainingRun)).all())
    for extra, message in (
        (["--init-model", "7"], "--init-model 7: there is no model 7"),
        (["--init-model", "1", "--hidden", "64"], "--hidden: the architecture of a fine-tuning run"),
        (["--init-model", "1", "--no-move"], "--no-move"),
        (["--init-model", "1", "--resume"], "cannot go with --resume"),
        (["--init-model", "0"], "--init-model"),
    ):
        result = runner.invoke(app, [*args, *extra])
        assert result.exit_code == 2, (extra, result.output)
        assert message in result.output, (extra, result.output)
    with store.session() as session:
        assert len(session.scalars(select(TrainingRun)).all()) == runs_before
    result = runner.invoke(app, [*args, "--init-model", "1"])
    assert result.exit_code == 0, result.output
    assert "fine-tuned from model 1" in result.output
    result = runner.invoke(app, ["--db", url, "models", "--json"])
    assert result.exit_code == 0, result.output
    listed = {m["id"]: m for m in json.loads(result.output)}
    assert listed[2]["metrics"]["init_model_id"] == 1 and "init_model_id" not in listed[1]["metrics"]


def test_a_training_batch_stays_on_the_nets_device() -> None:
    """Training on a GPU (``--device cuda``) needs every tensor a batch makes on the net's device. The
    ``meta`` device stands in for one here: a tensor left on the CPU makes PyTorch refuse the mix, as
    CUDA does (a constant built without ``device=`` once broke ``improve --device cuda``)."""
    from twisted.model.data import transitions_from_samples
    from twisted.model.encoding import preprocess
    from twisted.model.train import batch_condition, batch_losses
    from twisted.topology import parse_p_data

    net = InverseNet(SMALL).to("meta")
    points = np.stack([random_rope(i) for i in range(2)]).astype(np.float32)
    curves = np.array([[3, 0.05, 0.1, 0.1], [5, 0.05, -0.1, 0.1]], np.float32)
    p0, p1 = parse_p_data("[]"), parse_p_data('[[1,"O",2,"+"],[2,"U",1,"+"]]')
    data = transitions_from_samples(points, curves, [p0, p0], [p1, p1]).to("meta")
    index = torch.arange(2, device="meta")
    for variant in (torch.zeros(2, dtype=torch.long, device="meta"), torch.tensor([1, 3], device="meta")):
        losses = batch_losses(net, data, index, variant)
        assert losses["loss"].device.type == "meta" and losses["loss"].shape == (2,)
        logits = net.link_logits(preprocess(data.points[index]), batch_condition(data, index, variant))
        assert logits.device.type == "meta"
        losses["loss"].mean().backward()
