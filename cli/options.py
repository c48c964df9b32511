"""The types of the options that are choices or lists, the planner's options, and the shared ``--json``.

Choices are Enums built from the domain's own tuples (nothing is listed twice): typer offers them as
choices in --help and refuses anything else with exit 2 ("Invalid value for '--heuristic'") while
the command line is parsed, before any command runs. Lists (``--seeds``, ``--from``,
``--goal-crossings``) and ``--device`` are parsed by their option the same way. The planner's options
(``--heuristic``, ``--k``, ...) come from their one declaration (``twisted.planner.options``) through
:func:`with_planner_options`.
"""

from __future__ import annotations

import functools
import inspect
import json
from collections.abc import Callable
from enum import Enum
from typing import Any, TypeVar

import typer

from cli.app import MAX_SEED, shorten
from twisted.model.config import DEVICES, LINK_HEADS, SOURCES, NetConfig, TrainConfig
from twisted.planner.options import OptionSpec, result_options, specs

F = TypeVar("F", bound=Callable[..., Any])

MAX_SEEDS = 10_000  # planner seeds per goal in one evaluation
PLANNER_PANEL = "Search options"  # the help panel of the planner's options (with_planner_options)

# mypy cannot see members made from a tuple; the members are the tuple's strings (Planner("sac")).
# The planner options' choices come from their declaration (PlannerOptions).
CHOICES: dict[str, Any] = {
    spec.name: Enum(spec.name.title(), [(c, c) for c in spec.choices], type=str)  # type: ignore[misc]
    for spec in specs()
    if spec.choices
}
Planner = CHOICES["planner"]  # for a command that takes --planner alone (untie)
LinkHead = Enum("LinkHead", [(name, name) for name in LINK_HEADS], type=str)  # type: ignore[misc]
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


def _planner_parameter(spec: OptionSpec) -> inspect.Parameter:
    """The Typer parameter of one declared planner option: ``--NAME``, None when not given (a flag:
    False), its bounds checked (NaN included; click's ranges let NaN through), its choices offered."""
    shown = f"{spec.default:g}" if isinstance(spec.default, float) else str(spec.default)
    help = spec.help if spec.type is bool else spec.help.rstrip(".") + f" (default {shown})."
    if spec.type is bool and spec.default:  # on unless --no-NAME: a pair of flags, None when neither
        flags = f"{spec.flag}/--no-{spec.flag[2:]}"
        pair = typer.Option(None, flags, help=help, rich_help_panel=PLANNER_PANEL)
        kind = inspect.Parameter.KEYWORD_ONLY
        return inspect.Parameter(spec.name, kind, default=pair, annotation=bool | None)
    if spec.type is bool:
        flag = typer.Option(False, spec.flag, help=help, rich_help_panel=PLANNER_PANEL)
        return inspect.Parameter(spec.name, inspect.Parameter.KEYWORD_ONLY, default=flag, annotation=bool)
    annotation: Any = CHOICES[spec.name] if spec.choices else spec.type

    def check(value: Any) -> Any:
        problem = None if value is None or spec.choices else spec.check(value)
        if problem is not None:
            raise _bad(f"{spec.flag} {value}: {problem}")
        return value

    # a choice is named by its option (the help lists the values): a list of them would be cut mid-word
    metavar = spec.name.upper() if spec.choices else None
    option = typer.Option(
        None, spec.flag, callback=check, help=help, metavar=metavar, rich_help_panel=PLANNER_PANEL
    )
    return inspect.Parameter(
        spec.name, inspect.Parameter.KEYWORD_ONLY, default=option, annotation=annotation | None
    )


def _plain(spec: OptionSpec, given: Any) -> Any:
    """A planner option as the planner takes it: a choice's string; None for a flag not given (an
    option that is off by default and was not turned on)."""
    if given is False and not spec.default:
        return None
    return given.value if isinstance(given, Enum) else given


def with_planner_options(command: str) -> Callable[[F], F]:
    """Give a Typer command the planner options that ``command`` takes (``PlannerOptions``' declaration,
    :func:`twisted.planner.options.specs`): each is a ``--NAME`` option, and the command function gets
    them in one keyword argument ``search_options`` (name -> value; None: not given, the planner's
    default). Put it below ``@app.command``."""
    chosen = [spec for spec in specs() if command in spec.commands]

    def decorate(func: F) -> F:
        signature = inspect.signature(func, eval_str=True)
        kept = [p for name, p in signature.parameters.items() if name != "search_options"]
        added = [_planner_parameter(spec) for spec in chosen]

        @functools.wraps(func)
        def command_function(*args: Any, **kwargs: Any) -> Any:
            search_options = {spec.name: _plain(spec, kwargs.pop(spec.name)) for spec in chosen}
            return func(*args, search_options=search_options, **kwargs)

        parameters = kept + added
        command_function.__signature__ = signature.replace(parameters=parameters)  # type: ignore[attr-defined]
        command_function.__annotations__ = {p.name: p.annotation for p in parameters}
        return command_function  # type: ignore[return-value]

    return decorate


def result_flags() -> str:
    """The options results under one evaluation label must share, as flags (``eval --label``'s help)."""
    return ", ".join("--" + name.replace("_", "-") for name in result_options())


def json_option(what: str, panel: str | None = None) -> Any:
    """The ``--json`` option of every command that lists or reports something (``panel``: its help panel)."""
    return typer.Option(False, "--json", help=f"Print {what} as JSON.", rich_help_panel=panel)


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
