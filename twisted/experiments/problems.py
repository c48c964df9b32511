"""Problem sets (paper sections 5.2, 5.4): goals drawn from our data by frequency, or imported.

The 3-crossing states our data visited are ranked by frequency, the number of kept transitions that
reached the state (``transitions.to_state_id``, what "how often the random data visits it" means for a
dataset of transitions), most frequent first, ties broken by key. The ranking is cut into thirds by
rank (``numpy.array_split``: sizes differ by at most one, the first thirds take the extra): ``easy``
(top), ``medium``, ``hard`` (bottom). ``unseen-3`` holds 3-crossing states the high level reaches from
the empty rope (``moves.enumerate_states(3)``) that the data never visited. ``4`` holds 4-crossing
states: those our data visited first (a rope has reached them, so they are physically feasible),
topped up with states the high level reaches but the data never visited when fewer than ``per_set``
were visited; each goal's tag says which. ``5`` holds 5-crossing states likewise: those our data
visited, topped up with states one move beyond the goals of ``4``. From every pool ``per_set`` goals
(10 in the paper) are drawn without replacement by one seeded generator, in the fixed order easy,
medium, hard, unseen-3, 4, 5, so a seed reproduces every set.

Sets drawn the way people name goals (:data:`NAMED_SETS`, ``docs/goals.md``): ``u4`` and ``u5`` draw
states uniformly from every state of 4 and 5 crossings (the enumeration), ``u6`` from the 6-crossing
states by the head-tree sampler of :mod:`twisted.experiments.goalsets` (close to uniform, measured by
``bench/sampler_tv.py``), and ``catalogue`` holds every named knot up to 6 crossings in both
chiralities as knot goals (its parameters say that the pull test is required). Each of these sets is
drawn by its own generator ``default_rng([seed, n])`` (n: its crossing count, 0 for the catalogue),
so a seed gives the same set whichever others are asked for.

Imported sets come from a goal file (:func:`parse_goal_file`: P-data or knots) or a list of goals
(:func:`save_goal_sets`), stored in one transaction or not at all.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from sqlalchemy import func, select

from twisted.goals import Goal, state_goal
from twisted.moves import parse_state, successors
from twisted.runtime import name_problem
from twisted.store.experiments import (
    ProblemRecord,
    ProblemSet,
    ProblemSetRecord,
    count_results,
    delete_problem_set,
    load_problem_set,
    save_problem_set,
)
from twisted.store.models import TopologicalState, Transition
from twisted.topology import PData, PDataError, json_int, parse_p_data

__all__ = [
    "ALL_MADE_SETS",
    "CATALOGUE_KNOTS",
    "GOAL_SET_FORMAT",
    "MAKEABLE_SETS",
    "NAMED_SETS",
    "draw_named_set",
    "goal_set_file",
    "DIFFICULTY_SETS",
    "FIVE_SET",
    "FOUR_SET",
    "UNSEEN_SET",
    "EvalInputError",
    "GoalFile",
    "decode_goal_file",
    "goal_problems",
    "import_problem_sets",
    "make_problem_sets",
    "make_problem_sets_in_store",
    "parse_goal_file",
    "rank_by_frequency",
    "read_goal_file",
    "save_goal_sets",
    "split_thirds",
    "state_frequencies",
]

DIFFICULTY_SETS = ("easy", "medium", "hard")
UNSEEN_SET = "unseen-3"
FOUR_SET = "4"
FIVE_SET = "5"
ALL_MADE_SETS = (*DIFFICULTY_SETS, UNSEEN_SET, FOUR_SET, FIVE_SET)
# Sets drawn the way people name goals (not from our data): crossing count per uniform set
NAMED_SETS = {"u4": 4, "u5": 5, "u6": 6, "catalogue": 0, "knots": 0}
MAKEABLE_SETS = (*ALL_MADE_SETS, *NAMED_SETS)
# The catalogue set: every named knot up to 6 crossings, each chirality apart (square is its own mirror)
CATALOGUE_KNOTS = ("3_1+", "3_1-", "4_1", "5_1+", "5_1-", "5_2+", "5_2-", "granny+", "granny-", "square")
# The knots set: the catalogue's knots by the names a person asks for (`twisted plan --knot NAME`), each
# reached in either hand
KNOT_NAMES = ("overhand", "figure-eight", "5_1", "5_2", "granny", "square")
# Marks a goal file that carries one set with how it was drawn (``goal_set_file``)
GOAL_SET_FORMAT = "twisted-goal-set/1"


class EvalInputError(ValueError):
    """A set name, goal file, planner or option the experiments cannot take; the message says why."""


def state_frequencies(session: Any) -> dict[str, tuple[PData, int]]:
    """Every state our data reached: key -> (P-data, number of kept transitions reaching it)."""
    reached = (
        select(Transition.to_state_id.label("state_id"), func.count().label("n"))
        .group_by(Transition.to_state_id)
        .subquery()
    )
    rows = session.execute(
        select(TopologicalState.p_data, reached.c.n).join(reached, reached.c.state_id == TopologicalState.id)
    )
    out = {}
    for p_list, n in rows:
        p = parse_p_data(p_list)
        out[p.key] = (p, int(n))
    return out


def rank_by_frequency(frequencies: Mapping[str, int]) -> list[str]:
    """Keys, most frequent first; equal frequencies in key order (deterministic)."""
    return sorted(frequencies, key=lambda k: (-frequencies[k], k))


def split_thirds(frequencies: Mapping[str, int]) -> tuple[list[str], list[str], list[str]]:
    """Easy / medium / hard: the top, middle and bottom thirds of the ranking by frequency."""
    ranked = rank_by_frequency(frequencies)
    parts = np.array_split(np.arange(len(ranked)), 3)
    easy, medium, hard = ([ranked[i] for i in part] for part in parts)
    return easy, medium, hard


def _constant(tag: str) -> Callable[[str], str]:
    return lambda _key: tag


def _sample(pool: Sequence[str], n: int, rng: np.random.Generator) -> list[str]:
    if len(pool) <= n:
        return list(pool)
    picked = rng.choice(len(pool), size=n, replace=False)
    return [pool[i] for i in picked]


def make_problem_sets(
    frequencies: Mapping[str, tuple[PData, int]],
    reachable: Callable[[int], Sequence[PData]],
    *,
    per_set: int = 10,
    seed: int = 0,
    sets: Iterable[str] = ALL_MADE_SETS,
) -> dict[str, list[ProblemRecord]]:
    """Draw the goal sets from our data (pure: no store).

    ``frequencies``: key -> (state, transitions reaching it) for the visited states;
    ``reachable(c)``: the c-crossing states the high level reaches (c = 3, and 4 when needed).
    Goals of a set are listed most frequent first.
    """
    if per_set < 1:
        raise EvalInputError(f"--per-set must be at least 1, got {per_set}")
    wanted = set(sets)
    unknown = wanted - set(ALL_MADE_SETS)
    if unknown:
        raise EvalInputError(f"unknown set {sorted(unknown)[0]!r}: choose from {', '.join(ALL_MADE_SETS)}")
    visited = {k: (p, n) for k, (p, n) in frequencies.items() if n > 0}
    three = {k: n for k, (p, n) in visited.items() if p.cross == 3}
    rng = np.random.default_rng(seed)
    out: dict[str, list[ProblemRecord]] = {}

    def records(
        keys: Iterable[str], tag_of: Callable[[str], str], pool: Mapping[str, PData]
    ) -> list[ProblemRecord]:
        chosen = sorted(keys, key=lambda k: (-visited.get(k, (None, 0))[1], k))
        return [
            ProblemRecord(None, i, pool[k], visited.get(k, (None, 0))[1], tag_of(k))
            for i, k in enumerate(chosen)
        ]

    # Always draw in the same order so that a seed gives the same sets whichever subset is asked for.
    for name, third in zip(DIFFICULTY_SETS, split_thirds(three), strict=True):
        picked = _sample(third, per_set, rng)
        if name in wanted:
            out[name] = records(picked, _constant(name), {k: visited[k][0] for k in picked})
    all3 = {p.key: p for p in reachable(3)}
    unseen = sorted(k for k in all3 if k not in visited)
    picked = _sample(unseen, per_set, rng)
    if UNSEEN_SET in wanted:
        out[UNSEEN_SET] = records(picked, _constant("unseen"), all3)
    if FOUR_SET in wanted or FIVE_SET in wanted:  # 5 is drawn after 4, so 4 is drawn for it too
        four_visited = sorted(k for k, (p, _) in visited.items() if p.cross == 4)
        picked = _sample(four_visited, per_set, rng)
        pool = {k: visited[k][0] for k in picked}
        if len(picked) < per_set:
            all4 = {p.key: p for p in reachable(4)}
            extra = _sample(sorted(k for k in all4 if k not in visited), per_set - len(picked), rng)
            pool.update({k: all4[k] for k in extra})
            picked += extra
        four = records(picked, lambda k: "4-visited" if k in visited else "4-unseen", pool)
        if FOUR_SET in wanted:
            out[FOUR_SET] = four
    if FIVE_SET in wanted:
        # visited 5-crossing states first, topped up with states one move beyond the 4-crossing goals
        # (enumerating all 130,304 five-crossing states takes half a minute)
        five_visited = sorted(k for k, (p, _) in visited.items() if p.cross == 5)
        picked = _sample(five_visited, per_set, rng)
        pool = {k: visited[k][0] for k in picked}
        if len(picked) < per_set:
            beyond = {s.state.key: s.state for r in four for s in successors(r.p_data) if s.state.cross == 5}
            extra = _sample(sorted(k for k in beyond if k not in visited), per_set - len(picked), rng)
            pool.update({k: beyond[k] for k in extra})
            picked += extra
        out[FIVE_SET] = records(picked, lambda k: "5-visited" if k in visited else "5-unseen", pool)
    return out


def draw_named_set(
    kind: str, per_set: int, seed: int, exclude: frozenset[str] = frozenset()
) -> list[ProblemRecord]:
    """The goals of a named set (:data:`NAMED_SETS`), drawn by ``default_rng([seed, n])``; pure.

    Uniform sets list their states in draw order; ``exclude`` holds goal keys never drawn (e.g. the
    goals of evaluation sets). The catalogue and the knots set ignore ``per_set`` and ``seed``.
    """
    from twisted.experiments.goalsets import MAX_UNIFORM_ENUMERATED, sample_states, uniform_states

    if kind not in NAMED_SETS:
        raise EvalInputError(f"unknown set {kind!r}: choose from {', '.join(MAKEABLE_SETS)}")
    if per_set < 1:
        raise EvalInputError(f"--per-set must be at least 1, got {per_set}")
    n = NAMED_SETS[kind]
    if n == 0:
        from twisted.goals import knot_goal

        goals = [knot_goal(name) for name in (CATALOGUE_KNOTS if kind == "catalogue" else KNOT_NAMES)]
        return [ProblemRecord(None, i, g.representative, 0, kind, spec=g.spec) for i, g in enumerate(goals)]
    rng = np.random.default_rng([seed, n])
    if n <= MAX_UNIFORM_ENUMERATED:
        states, tag = uniform_states(n, per_set, rng, exclude=exclude), f"uniform-{n}"
    else:
        states, tag = sample_states(n, per_set, rng, exclude=exclude), f"sampled-{n}"
    return [ProblemRecord(None, i, p, 0, tag) for i, p in enumerate(states)]


def _named_parameters(kind: str, per_set: int) -> dict[str, Any]:
    if kind in ("catalogue", "knots"):
        knots = CATALOGUE_KNOTS if kind == "catalogue" else KNOT_NAMES
        return {"kind": kind, "knots": list(knots), "tighten": True, "pull_test": "required"}
    n = NAMED_SETS[kind]
    how = "uniform over the enumeration" if n <= 5 else "head-tree walks, importance-resampled toward uniform"
    return {"kind": kind, "per_set": per_set, "crossings": n, "draw": how}


def _enumerated(c: int) -> list[PData]:
    from twisted.moves import enumerate_states

    return enumerate_states(c)[c]


def make_problem_sets_in_store(
    store: Any,
    *,
    per_set: int = 10,
    seed: int = 0,
    prefix: str = "",
    replace: bool = False,
    sets: Iterable[str] = ALL_MADE_SETS,
    reachable: Callable[[int], Sequence[PData]] = _enumerated,
) -> list[ProblemSetRecord]:
    """Make the sets from the store's data and save them (names ``prefix + easy`` etc.).

    An existing set of the same name is an error unless ``replace`` (allowed only while no
    evaluation result refers to it).
    """
    asked = set(sets)
    unknown = asked - set(MAKEABLE_SETS)
    if unknown:
        raise EvalInputError(f"unknown set {sorted(unknown)[0]!r}: choose from {', '.join(MAKEABLE_SETS)}")
    sets = [s for s in ALL_MADE_SETS if s in asked]
    named = [s for s in NAMED_SETS if s in asked]
    with store.session() as session:
        frequencies = state_frequencies(session)
    three_visited = sum(1 for p, n in frequencies.values() if p.cross == 3 and n > 0)
    if three_visited < 3 and any(s in DIFFICULTY_SETS for s in sets):
        raise EvalInputError(
            f"the data visited {three_visited} three-crossing states; easy/medium/hard need at least 3 "
            "(collect data first: `twisted collect`)"
        )
    drawn = make_problem_sets(frequencies, reachable, per_set=per_set, seed=seed, sets=sets) if sets else {}
    parameters = {
        "per_set": per_set,
        "frequency": "kept transitions reaching the state",
        "three_crossing_states_visited": three_visited,
        "transitions": sum(n for _, n in frequencies.values()),
    }
    set_parameters = {name: parameters for name in drawn}
    for kind in named:
        drawn[kind] = draw_named_set(kind, per_set, seed)
        set_parameters[kind] = _named_parameters(kind, per_set)
    with store.session(write=True) as session:
        for name in drawn:
            full = f"{prefix}{name}"
            existing = session.scalar(select(ProblemSet).where(ProblemSet.name == full))
            if existing is not None:
                n_results = count_results(session, existing.id)
                if not replace:
                    raise EvalInputError(f"problem set {full!r} exists: use --replace or --prefix")
                if n_results:
                    raise EvalInputError(
                        f"problem set {full!r} has {n_results} evaluation results; it cannot be replaced "
                        "(use --prefix to make new sets)"
                    )
                delete_problem_set(session, existing.id)
                session.flush()
            save_problem_set(
                session, full, drawn[name], source="made", seed=seed, parameters=set_parameters[name]
            )
    with store.session() as session:
        return [r for name in drawn if (r := load_problem_set(session, f"{prefix}{name}")) is not None]


def decode_goal_file(data: bytes) -> str:
    """The text of a goal file, which must be UTF-8 (JSON's encoding; a UTF-8 byte-order mark is allowed).

    Raises :class:`EvalInputError` saying what the bytes are instead: UTF-16/32 (by their byte-order
    mark), binary (NUL bytes), or where the first byte that is not UTF-8 sits.
    """
    for mark, encoding in _BYTE_ORDER_MARKS:
        if data.startswith(mark):
            raise EvalInputError(
                f"goal file is {encoding} text (it starts with a {encoding} byte-order mark); goal files are "
                "UTF-8 JSON: convert it, e.g. `iconv -f UTF-16 -t UTF-8`"
            )
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        kind = "binary data, not text" if b"\x00" in data[:4096] else "not UTF-8 text"
        raise EvalInputError(
            f"goal file is {kind} (byte 0x{data[exc.start]:02x} at offset {exc.start:,} is not UTF-8); goal "
            "files are UTF-8 JSON"
        ) from None
    if "\x00" in text:
        raise EvalInputError("goal file holds NUL characters (binary data, not text); goal files are UTF-8")
    return text


# Byte-order marks of the encodings a goal file is not in (UTF-32 first: its mark starts like UTF-16's).
_BYTE_ORDER_MARKS = (
    (b"\xff\xfe\x00\x00", "UTF-32"),
    (b"\x00\x00\xfe\xff", "UTF-32"),
    (b"\xff\xfe", "UTF-16"),
    (b"\xfe\xff", "UTF-16"),
)


def parse_goal_file(text: str, name: str | None = None) -> dict[str, list[Goal]]:
    """Goals from JSON: a list of goals (one set called ``name``) or an object of named lists.

    A goal is P-data, or a knot (``"overhand"``, ``"figure-eight@4"``: any state of that many crossings,
    default the knot's crossing number, that ties it). For an object the sets are called by their
    keys, prefixed ``name-`` when a name is given. Every goal is checked; the first bad one raises
    :class:`EvalInputError` naming set and index.
    """
    return _goals_of(_load_goal_json(text), name)


def _load_goal_json(text: str) -> Any:
    """The JSON of a goal file (64-bit integers only); EvalInputError when it is not JSON."""
    try:
        return json.loads(text, parse_int=json_int)
    except json.JSONDecodeError as exc:
        raise EvalInputError(
            f"goal file is not valid JSON ({exc.msg} at line {exc.lineno} column {exc.colno})"
        ) from None
    except RecursionError:
        message = "goal file nests lists or objects far too deeply (a goal is a list of lists)"
        raise EvalInputError(message) from None
    except PDataError as exc:  # an integer beyond 64 bits
        raise EvalInputError(f"goal file: {exc}") from None


def _goals_of(data: Any, name: str | None) -> dict[str, list[Goal]]:
    """The sets of a goal file's JSON, every goal checked (:func:`parse_goal_file`)."""
    from twisted.goals import GoalError, goal_from_spec

    if isinstance(data, dict) and data.get("format") == GOAL_SET_FORMAT:
        if not isinstance(data.get("name"), str) or not isinstance(data.get("goals"), list):
            raise EvalInputError(
                f"a {GOAL_SET_FORMAT} file needs 'name' (text) and 'goals' (a list of goals)"
            )
        named = {name or data["name"]: data["goals"]}
    elif isinstance(data, list):
        if not name:
            raise EvalInputError("a goal file holding one list needs a set name (--name)")
        named = {name: data}
    elif isinstance(data, dict):
        if not data:
            raise EvalInputError("the goal file holds an empty object: no set to import")
        joint = "" if not name or name.endswith(("-", "_", ".", "/")) else "-"  # --name t- -> t-one
        named = {(f"{name}{joint}{k}" if name else str(k)): v for k, v in data.items()}
    else:
        raise EvalInputError(
            f"goal file must hold a JSON list of goals or an object of named lists, got {type(data).__name__}"
        )
    out: dict[str, list[Goal]] = {}
    for set_name, goals in named.items():
        if not set_name or len(set_name) > 64:
            shown = set_name if len(set_name) <= 80 else f"{set_name[:80]}... ({len(set_name):,} characters)"
            raise EvalInputError(f"set name {shown!r} must have 1 to 64 characters")
        problem = name_problem(set_name)
        if problem is not None:  # it is printed, written to report.md and to file names
            raise EvalInputError(f"set name {set_name!r} {problem}")
        if not isinstance(goals, list) or not goals:
            raise EvalInputError(f"set {set_name!r}: expected a non-empty list of goals (P-data or knots)")
        seen: dict[str, int] = {}
        parsed = []
        for i, entry in enumerate(goals):
            where = f"set {set_name!r} entry {i}"
            # A list of entries that all are lists is a state; anything else is reported as malformed.
            try:
                if isinstance(entry, str):
                    goal = goal_from_spec(entry)
                else:
                    goal = state_goal(parse_state(entry, where))
            except GoalError as exc:
                raise EvalInputError(f"{where}: {exc}") from None
            except PDataError as exc:
                raise EvalInputError(str(exc)) from None
            if goal.cross == 0:
                raise EvalInputError(f"{where}: the empty rope [] is not a goal")
            if goal.spec in seen:
                raise EvalInputError(f"{where}: same goal as entry {seen[goal.spec]} ({goal.spec})")
            seen[goal.spec] = i
            parsed.append(goal)
        out[set_name] = parsed
    return out


def goal_problems(
    goals: Sequence[Goal], frequencies: Mapping[str, tuple[PData, int]], tag: str
) -> list[ProblemRecord]:
    """Problem records for ``goals``; a goal's frequency counts the transitions reaching any of its states."""
    return [
        ProblemRecord(
            None,
            i,
            goal.representative,
            sum(frequencies.get(p.key, (p, 0))[1] for p in goal.states),
            tag,
            spec=goal.spec if goal.knot is not None else None,
        )
        for i, goal in enumerate(goals)
    ]


@dataclass(frozen=True)
class GoalFile:
    """A goal file read and checked (:func:`read_goal_file`), ready to store."""

    goals: dict[str, list[Goal]]
    seed: int | None
    parameters: dict[str, Any]


def read_goal_file(text: str, name: str | None = None) -> GoalFile:
    """Check a goal file completely (its goals and, for a goal-set file, its header); nothing is stored.

    A goal-set file (:func:`goal_set_file`) keeps its seed and how it was drawn for the set's row."""
    data = _load_goal_json(text)
    goals = _goals_of(data, name)
    header = goal_file_header(data)
    return GoalFile(goals, header.get("seed"), drawn_parameters(header))


def import_problem_sets(store: Any, text: str | GoalFile, name: str | None = None) -> list[ProblemSetRecord]:
    """Store all the sets of a goal file (its text, or as :func:`read_goal_file` read it) in one
    transaction, or none."""
    read = read_goal_file(text, name) if isinstance(text, str) else text
    return save_goal_sets(store, read.goals, "imported", seed=read.seed, parameters=read.parameters)


def drawn_parameters(header: Mapping[str, Any]) -> dict[str, Any]:
    """How a goal-set file's sets were drawn, stored as a made set's parameters are: the file's
    ``parameters`` with its ``kind`` and the ``command`` that drew it (``problems export`` writes the
    file back from them: the same header). The file's format and name are not kept, its seed has a
    column of its own."""
    drawn = dict(header.get("parameters") or {})
    for key in ("kind", "command"):
        if header.get(key) is not None:
            drawn.setdefault(key, header[key])
    return drawn


def goal_file_header(data: Any) -> dict[str, Any]:
    """What a goal-set file's JSON (:func:`json.loads` of it) says besides its goals (kind, seed, command
    ...); {} for plain goal files."""
    if not isinstance(data, dict) or data.get("format") != GOAL_SET_FORMAT:
        return {}
    header = {k: v for k, v in data.items() if k != "goals"}
    seed = header.get("seed")
    if seed is not None and not (isinstance(seed, int) and not isinstance(seed, bool)):
        raise EvalInputError(f"a {GOAL_SET_FORMAT} file's seed must be an integer, got {seed!r}")
    parameters = header.get("parameters")
    if parameters is not None and not isinstance(parameters, dict):
        raise EvalInputError(f"a {GOAL_SET_FORMAT} file's parameters must be an object, got {parameters!r}")
    for key in ("kind", "command"):
        if header.get(key) is not None and not isinstance(header[key], str):
            raise EvalInputError(f"a {GOAL_SET_FORMAT} file's {key} must be a string, got {header[key]!r}")
    return header


def goal_set_file(
    record: ProblemSetRecord,
    *,
    kind: str,
    seed: int | None,
    command: str,
    parameters: Mapping[str, Any] | None = None,
) -> str:
    """A stored set as a goal-set file: JSON with its name, kind, seed, the command that drew it, goals.

    ``twisted problems import FILE`` reads it back (the same goals, in order, with the seed)."""
    goals: list[Any] = [
        p.goal_key.removeprefix("knot:") if p.spec is not None else p.p_data.to_list()
        for p in record.problems
    ]
    body = {
        "format": GOAL_SET_FORMAT,
        "name": record.name,
        "kind": kind,
        "seed": seed,
        "command": command,
        "parameters": dict(parameters or {}),
    }
    lines = ",\n".join("    " + json.dumps(g, separators=(",", ":")) for g in goals)
    head = json.dumps(body, indent=2)[:-2]  # without the closing brace
    return f'{head},\n  "goals": [\n{lines}\n  ]\n}}\n'


def save_goal_sets(
    store: Any,
    goals: Mapping[str, Sequence[Goal]],
    tag: str,
    *,
    seed: int | None = None,
    parameters: Mapping[str, Any] | None = None,
) -> list[ProblemSetRecord]:
    """Store new problem sets of the given goals (``source = 'imported'``) in one transaction, or none."""
    with store.session() as session:
        frequencies = state_frequencies(session)
    with store.session(write=True) as session:
        for set_name in goals:
            if session.scalar(select(ProblemSet.id).where(ProblemSet.name == set_name)) is not None:
                raise EvalInputError(f"problem set {set_name!r} exists already: import under another --name")
        for set_name, set_goals in goals.items():
            save_problem_set(
                session,
                set_name,
                goal_problems(set_goals, frequencies, tag),
                source="imported",
                seed=seed,
                parameters={**(parameters or {}), "goals": len(set_goals)},
            )
    with store.session() as session:
        return [r for set_name in goals if (r := load_problem_set(session, set_name)) is not None]
