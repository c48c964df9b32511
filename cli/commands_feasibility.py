"""`twisted train-feasibility`: learn which plan steps the rope allows from the stored searches."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from cli.app import app, console, fail, open_db, seed_option, unwritable
from cli.options import json_option, print_json


@app.command("train-feasibility")
def train_feasibility_command(
    ctx: typer.Context,
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            metavar="FILE",
            help="Write the model here (twisted/data/default_feasibility.pt is the one the planner ships).",
        ),
    ],
    sources: Annotated[
        list[str] | None,
        typer.Option(
            "--from",
            metavar="URL",
            help="Also read the searches of this database (read-only; repeatable).",
        ),
    ] = None,
    exclude_sets: Annotated[
        list[str] | None,
        typer.Option(
            "--exclude-set",
            metavar="NAME",
            help="Leave out the runs toward this stored set's goals (an evaluation set; repeatable).",
        ),
    ] = None,
    epochs: int = typer.Option(
        14, "--epochs", min=1, max=10_000, help="Epochs; the best by validation is kept."
    ),
    hidden: int = typer.Option(64, "--hidden", min=4, max=4096, help="Width of the first layer."),
    seed: int = seed_option(0, "Seed of the run split, the batch order and the weights."),
    as_json: bool = json_option("the figures"),
) -> None:
    """Train the feasibility model (DESIGN 8) on the pair statistics of the stored searches: per node and
    requested next state, the plan steps tried and those that reached it. The planner weighs its node,
    plan and state choices by it with --feasibility."""
    from twisted.model.feasibility import pair_samples, train_feasibility
    from twisted.store import open_store

    problem = unwritable(out)
    if problem is not None:
        fail(f"--out {out}: {problem}")
    stores: list[tuple[str, Any]] = [("--db", open_db(ctx, readonly=True, needed_by="train-feasibility"))]
    for url in sources or []:
        try:
            stores.append((url, open_store(url, create=False, readonly=True)))
        except Exception as exc:  # noqa: BLE001 - any refusal of the database is the user's input
            fail(f"--from {url}: {exc}")
    import numpy as np
    import torch

    from twisted.model.feasibility import PairSamples

    parts: list[PairSamples] = []
    for name, store in stores:
        try:
            part = pair_samples(store, exclude_sets=exclude_sets or ())
        except ValueError as exc:
            fail(f"{name}: {exc}")
        if len(part):
            part.run = part.run + (len(parts) << 32)  # runs of two stores never share an id
            parts.append(part)
        if not as_json:
            console.print(f"{name}: {len(part):,} pairs")
    if not parts:
        fail("no stored search has pair statistics to learn from: run `twisted plan` or `twisted eval` first")
    samples = PairSamples(
        points=np.concatenate([p.points for p in parts]),
        steps=torch.cat([p.steps for p in parts]),
        tried=np.concatenate([p.tried for p in parts]),
        reached=np.concatenate([p.reached for p in parts]),
        run=np.concatenate([p.run for p in parts]),
        group=[g for p in parts for g in p.group],
    )
    torch.manual_seed(seed)
    model, figures = train_feasibility(samples, hidden=hidden, epochs=epochs, seed=seed)
    model.metadata["sources"] = [name for name, _ in stores]
    model.metadata["excluded_sets"] = list(exclude_sets or [])
    try:
        out.write_bytes(model.to_bytes())
    except OSError as exc:
        fail(f"--out {out}: {exc}")
    if as_json:
        print_json({"out": str(out), **figures})
        return
    console.print(
        f"{figures['pairs']:,} pairs ({figures['val_runs']} runs held out for validation); best epoch "
        f"{figures['best_epoch']}: validation loss {figures['val_loss']:.4f} against "
        f"{figures['baseline_val_loss']:.4f} for the rate of each move kind and crossing count"
    )
    for g in figures["groups"]:
        auc = "-" if g["auc"] is None else f"{g['auc']:.3f}"
        reached = f"{g['reached']:,} of {g['tried']:,} steps reached"
        console.print(f"  {g['group']:>8}: {g['pairs']:,} pairs, {reached}, AUC {auc}")
    console.print(f"written to {out}")
