"""`twisted train` and `twisted models`: train the inverse model into the database, list stored models."""

from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from cli.app import EXIT_BAD_INPUT, app, console, fail, open_db, seed_option, shown_name, unwritable
from cli.options import (
    DEFAULT_LINK_HEAD,
    DEFAULT_SOURCES,
    LinkHead,
    Sources,
    json_option,
    parse_device,
    parse_sources,
    print_json,
    value,
)
from twisted.model.config import DEVICES, SOURCES, NetConfig, TrainConfig

EXIT_FAILED = 1


def _fmt(value: Any, spec: str = ".3f") -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else format(value, spec)


def _by_source(metrics: dict[str, Any], sides: str = "train,val") -> str:
    """``collect 3,126 / 324, search 812 / 90`` (training / validation samples per source); models from
    before sources were counted saw collected transitions only."""
    wanted = sides.split(",")
    parts = []
    for source in SOURCES:
        counts = [metrics.get(f"n_{side}_{source}") for side in wanted]
        if source == "collect" and all(c is None for c in counts):
            counts = [metrics.get(f"n_{side}") for side in wanted]  # older models: collected data only
        if any(c for c in counts):
            parts.append(f"{source} " + " / ".join("-" if c is None else f"{c:,}" for c in counts))
    return ", ".join(parts) or "-"


Device = Annotated[str, typer.Option("--device", parser=parse_device, metavar="DEVICE", help="cpu or cuda.")]
LinkHeadOption = Annotated[
    LinkHead, typer.Option("--link-head", help="pointer (shared per-link scorer) or dense.")
]
SourcesOption = Annotated[
    Sources,
    typer.Option(
        "--from",
        parser=parse_sources,
        metavar="SOURCES",
        help="Samples: collect (collected transitions), search (planner tree edges), or collect,search.",
    ),
]
HoldOutSets = Annotated[
    list[str] | None,
    typer.Option(
        "--hold-out-set",
        metavar="SET",
        help="Leave out what would show the model this problem set's goals (the sets it is then "
        "evaluated on): the planner trees of runs towards them, and every transition or tree edge "
        "that reaches one of their states; repeatable.",
    ),
]
InitModel = Annotated[
    int | None,
    typer.Option(
        "--init-model",
        min=1,
        metavar="MODEL_ID",
        help="Fine-tune: start from this stored model's weights and architecture (`twisted models`; "
        "`models --import` stores a file such as the shipped default).",
    ),
]

Threads = Annotated[
    int | None,
    typer.Option(
        "--threads",
        min=1,
        max=1024,
        help="torch CPU threads (default: torch's choice; 1 is best on a busy machine).",
    ),
]
Removing = Annotated[
    bool,
    typer.Option(
        "--removing/--no-removing",
        help="Also train on the collected transitions that remove crossings (`collect --remove-share`), "
        "each conditioned on its removing move.",
    ),
]


def _check_fine_tuning(ctx: typer.Context, resume: bool) -> None:
    """``--init-model``: a new run (no --resume) whose architecture is the model's (no --hidden, ...)."""
    if resume:
        fail("--init-model starts a new training run: it cannot go with --resume")
    given = [NET_OPTIONS[name] for name in NET_OPTIONS if _given(ctx, name)]
    if given:
        fail(f"{', '.join(given)}: the architecture of a fine-tuning run is --init-model's; leave these out")


@app.command("train")
def train_command(
    ctx: typer.Context,
    epochs: int = typer.Option(
        TrainConfig.epochs, "--epochs", min=1, help="Epochs over the training transitions."
    ),
    hours: float | None = typer.Option(
        None, "--hours", min=0.0, help="Stop (and store the model) after this time."
    ),
    device: Device = DEVICES[0],
    resume: bool = typer.Option(False, "--resume", help="Continue the newest unfinished training run."),
    seed: int = seed_option(TrainConfig.seed, "Seed of the split, batch order, augmentation and weights."),
    batch_size: int = typer.Option(TrainConfig.batch_size, "--batch-size", min=1, max=1_000_000),
    lr: float = typer.Option(TrainConfig.lr, "--lr", min=0.0, help="Adam learning rate."),
    weight_decay: float = typer.Option(
        TrainConfig.weight_decay, "--weight-decay", min=0.0, help="AdamW weight decay (0: Adam)."
    ),
    hidden: int = typer.Option(
        NetConfig.hidden, "--hidden", min=8, max=8192, help="Width of the shared trunk."
    ),
    layers: int = typer.Option(
        NetConfig.layers, "--layers", min=1, max=64, help="Layers of the shared trunk."
    ),
    components: int = typer.Option(
        NetConfig.components, "--components", min=1, max=256, help="Gaussians per continuous head."
    ),
    link_head: LinkHeadOption = DEFAULT_LINK_HEAD,
    new_visits: bool = typer.Option(
        NetConfig.new_visits,
        "--new-visits/--no-new-visits",
        help="Condition on where the next state's new crossings land.",
    ),
    move: bool = typer.Option(
        NetConfig.move,
        "--move/--no-move",
        help="Condition on the abstract move (R1/R2/Cross, segments, sides).",
    ),
    sources: SourcesOption = DEFAULT_SOURCES,
    hold_out_sets: HoldOutSets = None,
    removing: Removing = TrainConfig.removing,
    val_fraction: float = typer.Option(TrainConfig.val_fraction, "--val-fraction", min=0.0, max=0.9),
    augment: bool = typer.Option(
        TrainConfig.augment, "--augment/--no-augment", help="Mirror/Reverse augmentation."
    ),
    threads: Threads = None,
    checkpoint_every_s: float = typer.Option(
        TrainConfig.checkpoint_every_s, "--checkpoint-every", min=1.0, help="Seconds between checkpoints."
    ),
    init_model: InitModel = None,
) -> None:
    """Train the inverse model on the collected transitions; checkpoints go to the database."""
    if init_model is not None:
        _check_fine_tuning(ctx, resume)
    config = TrainConfig(
        epochs=epochs,
        hours=hours,
        batch_size=batch_size,
        lr=lr,
        weight_decay=weight_decay,
        seed=seed,
        val_fraction=val_fraction,
        augment=augment,
        checkpoint_every_s=checkpoint_every_s,
        net=NetConfig(
            hidden=hidden,
            layers=layers,
            components=components,
            link_head=value(link_head),
            new_visits=new_visits,
            move=move,
        ),
        sources=tuple(sources),
        hold_out_sets=tuple(dict.fromkeys(hold_out_sets or [])),
        init_model_id=init_model,
        removing=removing,
    )
    store = open_db(ctx, create=False)  # training needs collected data: a new database has none
    _train(store, config, resume, device, threads)


# the options that set the architecture (NetConfig); a fine-tuning run takes its model's
NET_OPTIONS = {
    "hidden": "--hidden",
    "layers": "--layers",
    "components": "--components",
    "link_head": "--link-head",
    "new_visits": "--new-visits/--no-new-visits",
    "move": "--move/--no-move",
}


def _given(ctx: typer.Context, name: str) -> bool:
    """Whether option ``name`` was given on the command line (not left at its default)."""
    source = ctx.get_parameter_source(name)  # an enum of the click that typer runs on
    return source is not None and source.name in ("COMMANDLINE", "ENVIRONMENT", "PROMPT")


def _train(store: Any, config: TrainConfig, resume: bool, device: str, threads: int | None) -> None:
    """Train with a progress bar; print the stored model's figures."""
    import torch

    from twisted.model.data import NoTrainingDataError, UnknownProblemSetError
    from twisted.model.train import Progress as TrainProgress
    from twisted.model.train import train
    from twisted.store.training import NonFiniteModelError, mark_training_failed

    if threads is not None:
        torch.set_num_threads(threads)
    epochs = config.epochs

    columns = (
        TextColumn("[bold]epoch {task.fields[epoch]}/{task.total}"),
        BarColumn(),
        TextColumn("batch {task.fields[batch]}"),
        TextColumn("loss {task.fields[loss]}"),
        TextColumn("val {task.fields[val]}"),
        TimeElapsedColumn(),
    )
    with Progress(*columns, console=console, transient=False) as bar:
        task = bar.add_task("train", total=epochs, epoch=0, batch="-", loss="-", val="-")
        last_val = "-"

        def on_progress(p: TrainProgress) -> None:
            nonlocal last_val
            if p.val is not None:
                nll, acc = p.val.get("val_loss"), p.val.get("val_link_accuracy")
                last_val = f"nll {_fmt(nll)} link-acc {_fmt(acc, '.2f')}"
            bar.update(
                task,
                total=p.epochs,
                completed=p.epoch + p.batch_index / max(p.batches_per_epoch, 1),
                epoch=p.epoch,
                batch=f"{p.batch_index}/{p.batches_per_epoch}",
                loss=_fmt(p.loss),
                val=last_val,
            )

        try:
            outcome = train(
                store, config, resume=resume, device=device, progress=on_progress, log=console.print
            )
        except NoTrainingDataError as exc:
            fail(str(exc), EXIT_BAD_INPUT)
        except UnknownProblemSetError as exc:  # train() checks the sets before it stores a run
            fail(f"--hold-out-set: {exc}", EXIT_BAD_INPUT)
        except NonFiniteModelError as exc:
            if exc.training_run_id is not None:
                mark_training_failed(store, exc.training_run_id, str(exc))
            fail(str(exc), EXIT_FAILED)
        except ValueError as exc:
            fail(str(exc), EXIT_BAD_INPUT)
        except KeyboardInterrupt as exc:  # Ctrl-C or SIGTERM (twisted.runtime.install)
            from twisted import runtime

            console.print("interrupted: checkpoint saved; continue with `twisted train --resume`")
            raise typer.Exit(runtime.exit_code(exc) or 130) from None
    _print_trained(outcome)


def _print_trained(outcome: Any) -> None:
    m = outcome.metrics
    if outcome.status != "finished":
        console.print(
            f"training run {outcome.training_run_id} stopped; continue with `twisted train --resume`"
        )
        return
    start = m.get("init_model_id")
    best = m.get("best_epoch")
    console.print(
        f"model {outcome.model_id} stored (training run {outcome.training_run_id}"
        + ("" if start is None else f", fine-tuned from model {start}")
        + f", {outcome.n_train} training / {outcome.n_val} validation samples, "
        + (
            f"best epoch {best})"
            if start is None or best != -1
            else f"no epoch improved on model {start}: its weights are stored unchanged)"
        )
    )
    console.print("  samples by source: " + _by_source(m))
    for side in ("val", "train"):
        if f"{side}_loss" in m:
            console.print(
                f"  {side:5s} NLL {_fmt(m.get(f'{side}_loss'))} (link {_fmt(m.get(f'{side}_nll_link'))}, "
                f"z {_fmt(m.get(f'{side}_nll_z'))}, x {_fmt(m.get(f'{side}_nll_x'))}, "
                f"y {_fmt(m.get(f'{side}_nll_y'))}), link accuracy {_fmt(m.get(f'{side}_link_accuracy'))}, "
                f"top-3 {_fmt(m.get(f'{side}_link_top3'))}"
            )


@app.command("models")
def models_command(
    ctx: typer.Context,
    export: str | None = typer.Option(
        None,
        "--export",
        help="Write a model (newest, or --id) to this file, e.g. twisted/data/default_model.pt.",
    ),
    model_id: int | None = typer.Option(None, "--id", help="The model to export (default: the newest)."),
    import_file: Annotated[
        Path | None,
        typer.Option(
            "--import",
            metavar="FILE",
            help="Store the model in this file (written by --export, or a shipped default_model.pt); it "
            "becomes the newest, which the planner uses.",
        ),
    ] = None,
    name: str | None = typer.Option(None, "--name", help="Name of the imported model (default: file name)."),
    as_json: bool = json_option("the models"),
) -> None:
    """List the inverse models stored in the database (the planner uses the newest)."""
    from twisted.model.registry import list_models, shipped_model_path

    if export is not None:
        if import_file is not None:
            fail("--export and --import: give one of them")
        problem = unwritable(Path(export))
        if problem is not None:
            fail(f"--export {export}: {problem}")
    if import_file is not None:
        _import_model(ctx, import_file, name, model_id)
        return
    if name is not None:
        fail("--name names an imported model: give --import FILE too")
    store = open_db(ctx, readonly=True, needed_by=None if model_id is None else f"--id {model_id}")
    if export is not None:
        _export_model(store, model_id, Path(export))
        return
    models = list_models(store)
    if as_json:
        print_json([asdict(m) for m in models])
        return
    if not models:
        path = shipped_model_path()
        shipped = f"the shipped model {path}" if path.is_file() else "no model at all (run `twisted train`)"
        console.print(f"no models in the database; planning uses {shipped}")
        return
    _print_models(store, models)


def _export_model(store: Any, model_id: int | None, target: Path) -> None:
    """``models --export``: write a stored model (the newest, or ``model_id``) to ``target``."""
    from twisted.model.registry import ModelError, load_model

    try:
        model = load_model(store, model_id)
    except ModelError as exc:
        fail(str(exc))
    if model.model_id is None:
        fail("the database holds no model to export: train one with `twisted train`")
    try:
        target.write_bytes(model.to_bytes())
    except OSError as exc:
        fail(f"--export {target}: cannot be written ({exc.strerror or exc})")
    console.print(f"model {model.model_id} written to {target} ({target.stat().st_size / 1e6:.1f} MB)")


def _print_models(store: Any, models: list[Any]) -> None:
    """The stored models as a table (with the improve generation each one is)."""
    from twisted.store.boundary import StoredValueError, shown, stored_object
    from twisted.store.improve import lineage_labels

    with store.session() as session:
        generations = lineage_labels(session)  # expert iteration (`twisted improve`)
    table = Table(
        "id",
        "name",
        "training run",
        "generation",
        "data size",
        "train samples by source",
        "val NLL",
        "link acc",
        "size",
        "created",
    )
    for m in models:
        metrics = stored_object(m.metrics, "models", m.id, "metrics")
        if isinstance(m.size_bytes, bool) or not isinstance(m.size_bytes, int | float):
            problem = f"must be a number, got {shown(m.size_bytes)}"
            raise StoredValueError("models", m.id, "size_bytes", problem)
        table.add_row(
            str(m.id),
            shown_name(m.name),
            ("-" if m.training_run_id is None else str(m.training_run_id))
            + ("" if metrics.get("init_model_id") is None else f" (from {metrics['init_model_id']})"),
            generations.get(m.id, "-"),
            str(m.data_size),
            _by_source(metrics, "train"),
            _fmt(metrics.get("val_loss")),
            _fmt(metrics.get("val_link_accuracy"), ".3f"),
            f"{m.size_bytes / 1e6:.1f} MB",
            m.created_at.strftime("%Y-%m-%d %H:%M"),
        )
    console.print(table)


def _import_model(ctx: typer.Context, path: Path, name: str | None, model_id: int | None) -> None:
    """Check that ``path`` holds a loadable model, then store it (before that, nothing is opened)."""
    from twisted.model.registry import ModelError, load_model_file, save_model
    from twisted.runtime import name_problem

    if model_id is not None:
        fail("--id chooses a model to export: it cannot go with --import")
    label = name if name is not None else path.stem
    problem = name_problem(label)  # a name from the file name is checked as --name is
    if problem is not None:
        fail(f"--import {path}: the model name {label!r} (from the file name) {problem}: give --name")
    try:
        model = load_model_file(path)
    except ModelError as exc:
        fail(f"--import {path}: {exc}")
    broken = model.unusable()  # checked as a trained model is, before the store is opened
    if broken:
        fail(f"--import {path}: this model cannot plan: {broken}")
    store = open_db(ctx)
    new_id = save_model(store, model, name=label)
    samples = model.metadata.get("data_size", "?")
    console.print(
        f"model {new_id} ({shown_name(label)}, trained on {samples} samples) stored from {shown_name(path)}; "
        "it is the newest, so `twisted plan` and `twisted eval` use it unless given --model"
    )
