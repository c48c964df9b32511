"""The types of the options that are choices or lists, and the shared ``--json`` option.

Choices are Enums built from the domain's own tuples (nothing is listed twice): typer offers them as
choices in --help and refuses anything else with exit 2 ("Invalid value for '--heuristic'") while
the command line is parsed, before any command runs. Lists (``--seeds``, ``--from``,
``--goal-crossings``) and ``--device`` are parsed by their option the same way.
"""

from __future__ import annotations

import json
from enum import Enum
from typing import Any

import typer

from cli.app import MAX_SEED, shorten
from twisted.model.config import DEVICES, LINK_HEADS, SOURCES, NetConfig, TrainConfig
from twisted.planner import HEURISTICS, PLANNERS, PlannerOptions
from twisted.planner.search import N_LINKS

MAX_SEEDS = 10_000  # planner seeds per goal in one evaluation

# mypy cannot see members made from a tuple; the members are the tuple's strings (Planner("sac"))
Planner = Enum("Planner", [(name, name) for name in PLANNERS], type=str)  # type: ignore[misc]
Heuristic = Enum("Heuristic", [(name, name) for name in HEURISTICS], type=str)  # type: ignore[misc]
LinkHead = Enum("LinkHead", [(name, name) for name in LINK_HEADS], type=str)  # type: ignore[misc]
DEFAULT_PLANNER = Planner(PlannerOptions.planner)
DEFAULT_LINK_HEAD = LinkHead(NetConfig.link_head)


def value(choice: Enum | None) -> Any:
    """The plain value of a choice (None stays None), as the domain takes it."""
    return None if choice is None else choice.value


def _bad(message: str) -> typer.BadParameter:
    return typer.BadParameter(shorten(message))


class Seeds(tuple[int, ...]):
    """Sorted distinct seeds, from '0 1 2', '0,1,2', '0-4' or a mix (``--seeds``)."""


def parse_seeds(text: str | Seeds) -> Seeds:
    if isinstance(text, Seeds):
        return text
    seeds: set[int] = set()
    for part in text.replace(",", " ").split():
        try:
            if "-" in part[1:]:
                lo, hi = part.split("-", 1)
                first, last = int(lo), int(hi)
                if last < first:
                    raise ValueError
            else:
                first = last = int(part)
        except ValueError:
            raise _bad(f"{part!r} is not a seed or a range like 0-4 (give e.g. '0 1 2' or '0-4')") from None
        if first < 0 or last > MAX_SEED:
            raise _bad(f"{part!r}: seeds are 0 to 2**63-1")
        if last - first + 1 + len(seeds) > MAX_SEEDS:
            raise _bad(f"at most {MAX_SEEDS:,} seeds per goal")
        seeds.update(range(first, last + 1))
    if not seeds:
        raise _bad("give at least one seed")
    return Seeds(sorted(seeds))


def seeds_option() -> Any:
    """``--seeds``, for ``Annotated[Seeds, seeds_option()] = DEFAULT_SEEDS``."""
    return typer.Option(
        "--seeds",
        parser=parse_seeds,
        metavar="SEEDS",
        help="Planner seeds: '0 1 2', '0,1,2' or a range '0-4'.",
    )


DEFAULT_SEEDS = Seeds((0,))


class Sources(tuple[str, ...]):
    """Training sample sources, a comma-separated list of ``twisted.model.config.SOURCES`` (``--from``)."""


DEFAULT_SOURCES = Sources(TrainConfig.sources)


def parse_sources(text: str | Sources) -> Sources:
    if isinstance(text, Sources):
        return text
    chosen = tuple(dict.fromkeys(s.strip() for s in text.split(",") if s.strip()))
    if not chosen or any(s not in SOURCES for s in chosen):
        raise _bad(f"give a comma-separated list of {', '.join(SOURCES)}, got {text!r}")
    return Sources(chosen)


class CrossingCounts(tuple[int, ...]):
    """Sorted distinct crossing counts from '1,2,3' (``--goal-crossings``)."""


def parse_crossing_counts(text: str | CrossingCounts) -> CrossingCounts:
    if isinstance(text, CrossingCounts):
        return text
    try:
        counts = sorted({int(part) for part in text.split(",") if part.strip()})
    except ValueError:
        raise _bad(f"give comma-separated integers like 1,2,3, got {text!r}") from None
    if not counts:
        raise _bad("is empty: give counts like 1,2,3")
    return CrossingCounts(counts)


def parse_device(text: str) -> str:
    """A torch device of ``twisted.model.config.DEVICES`` (``cuda:N`` for one GPU of several) that is
    there (``--device``)."""
    kind, _, index = text.partition(":")
    if kind not in DEVICES or (index and (kind == "cpu" or not index.isdigit())):
        raise _bad(f"must be {' or '.join(DEVICES)} (or cuda:N), got {text!r}")
    if kind == "cuda":
        import torch

        if not torch.cuda.is_available():
            raise _bad(f"{text}: no CUDA device is available to torch here; use --device cpu")
    return text


def k_option() -> Any:
    """``--k`` of the commands that run the planner (plan, eval); None: PlannerOptions.k."""
    return typer.Option(
        None, "--k", min=1, max=1000, help=f"Curves sampled per plan step (default {PlannerOptions.k})."
    )


def p_expand_option() -> Any:
    """``--p-expand`` of the commands that run the planner; None: PlannerOptions.p_expand."""
    return typer.Option(
        None,
        "--p-expand",
        min=0.0,
        max=1.0,
        help=f"RandomExpand probability after a failed iteration ({PlannerOptions.p_expand}).",
    )


def k_expand_option() -> Any:
    """``--k-expand`` of the commands that run the planner; None: PlannerOptions.k_expand."""
    return typer.Option(
        None, "--k-expand", min=1, max=100_000, help=f"Curves per RandomExpand ({PlannerOptions.k_expand})."
    )


def _bounded_option(
    flag: str, low: float, high: float, must: str, help: str, *, low_open: bool = False
) -> Any:
    """A float option of the commands that run the planner (None: the PlannerOptions default) whose
    callback refuses a value outside ``[low, high]`` (``(low, high]`` with ``low_open``), NaN
    included, saying it ``must`` be what the text names (click's ranges let NaN through)."""

    def check(value: float | None) -> float | None:
        if value is not None and not ((low < value if low_open else low <= value) and value <= high):
            raise _bad(f"{flag} {value}: must {must}")
        return value

    return typer.Option(None, flag, callback=check, help=help)


def retry_weight_option() -> Any:
    """``--retry-weight`` of the commands that run the planner; None: PlannerOptions.retry_weight."""
    return _bounded_option(
        "--retry-weight",
        0.0,
        1.0,
        "lie in (0, 1]",
        "Node choice: weight retry_weight**n for a node already asked n times for the plan's next "
        f"state (1: the paper's uniform choice; default {PlannerOptions.retry_weight}).",
        low_open=True,
    )


def state_prior_option() -> Any:
    """``--state-prior`` of the commands that run the planner; None: PlannerOptions.state_prior."""
    return _bounded_option(
        "--state-prior",
        0.0,
        1e6,
        "be a number of tries in [0, 1e6]",
        "State choice (crs): weight (1 + Cross(s)) * r(s), r(s) how the plan steps tried from s fare "
        "against its crossing level, shrunk by this many tries (0: the paper's crs; default "
        f"{PlannerOptions.state_prior:g}).",
    )


def cross_move_option() -> Any:
    """``--cross-move`` of the commands that run the planner; None: PlannerOptions.cross_move."""
    return _bounded_option(
        "--cross-move",
        0.0,
        1.0,
        "be a share of the K curves in [0, 1]",
        "Share of the K curves of a plan step toward a Cross move that are scripted (the tip, or "
        "the crossed strand, carried across; planner twisted) instead of drawn from the model "
        f"(0: all from the model; default {PlannerOptions.cross_move:g}).",
    )


def r1_room_option() -> Any:
    """``--r1-room`` of the commands that run the planner; None: PlannerOptions.r1_room."""
    return _bounded_option(
        "--r1-room",
        0.0,
        N_LINKS,
        f"be a number of links in [0, {N_LINKS}]",
        "Room for R1 curls: a node whose segment for the curl is shorter than this many links gets "
        "weight (length / r1_room)^2, and a plan that starts with a curl, and its state, the weight "
        f"of the best node for it (0: off; default {PlannerOptions.r1_room:g}).",
    )


def json_option(what: str) -> Any:
    """The ``--json`` option of every command that lists or reports something."""
    return typer.Option(False, "--json", help=f"Print {what} as JSON.")


def print_json(data: Any, *, indent: int | None = 2) -> None:
    """What ``--json`` prints: ``data`` as one JSON document on stdout (dates and paths as text)."""
    typer.echo(json.dumps(data, default=str, indent=indent))


def ray_address_argument() -> Any:
    """The optional ADDRESS argument of the commands that take ``--ray`` (collect, eval)."""
    return typer.Argument(
        None,
        metavar="ADDRESS",
        help="With --ray: the cluster (host:port, ray://host:10001, auto, local); default: the one "
        "`ray start` runs here, else a new local one.",
    )
