"""The knot table, naming a diagram by its invariants, and the names a user may type.

:class:`KnotType` is a knot with the invariants that named it; :func:`invariants` computes them for a
closed diagram and looks the pair ``(alexander, jones)`` up in :data:`CATALOGUE`, the table: every
prime knot up to 7 crossings with KnotInfo's invariants (:mod:`twisted.knots.knotinfo`), each
chirality apart, and the connected sums of two of them with at most 7 crossings in all (granny,
square, ``3_1#4_1``), docs/DESIGN.md section 9.3. :data:`KNOT_NAMES` and :func:`resolve_knot` map what
a user types (``6_1``, ``overhand``, ``figure-eight``, ``square``, ...) to table types.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache

from twisted.knots.gauss import GaussCode, _walking_order, simplify
from twisted.knots.knotinfo import KNOTINFO, MAX_TABLE_CROSSINGS
from twisted.knots.polynomials import _loop_poly, alexander_polynomial, jones_polynomial

__all__ = [
    "CATALOGUE",
    "COMMON_NAMES",
    "COMPOSITE_NOTE",
    "KNOT_NAMES",
    "UNKNOWN",
    "shown_name",
    "KnotNameError",
    "KnotType",
    "crossing_number",
    "invariants",
    "knot_words",
    "knotinfo_name",
    "mirror_name",
    "mirror_type",
    "resolve_knot",
]

UNKNOWN = "unknown"

# What "granny" and "square" mean here (shown by `twisted knots list`, `--knot` help and docs/goals.md).
COMPOSITE_NOTE = (
    "granny and square are knot types, connected sums of two trefoils (granny: two of the same "
    "handedness, square: one of each), tied on the one open rope as two overhand knots in a row; not "
    "the sailor's reef knot, which joins two rope ends"
)


@dataclass(frozen=True, slots=True)
class KnotType:
    """The knot a (closed) rope ties: its catalogue name and the invariants that named it.

    ``alexander``: coefficients of ``t^-d .. t^d``, symmetric, ``Delta(1) = 1``. ``jones``:
    ``((exponent of t, coefficient), ...)``. ``writhe``: of the diagram the invariants were computed
    from (not an invariant; left out of equality). ``name`` is ``"unknown"`` outside the catalogue.
    """

    name: str
    alexander: tuple[int, ...]
    determinant: int
    jones: tuple[tuple[int, int], ...]
    writhe: int | None = field(default=None, compare=False)

    @property
    def crossing_number(self) -> int | None:
        """The minimal crossing number for catalogue knots (``3_1+`` -> 3), None when unknown."""
        if self.name not in CATALOGUE:
            return None
        return crossing_number(self.name)

    @property
    def is_unknot(self) -> bool:
        return self.name == "0_1"

    def alexander_text(self) -> str:
        """The Alexander polynomial as text, e.g. ``t^-1 - 1 + t``."""
        d = (len(self.alexander) - 1) // 2
        return _poly_text([(i - d, c) for i, c in enumerate(self.alexander)])

    def jones_text(self) -> str:
        """The Jones polynomial as text, e.g. ``t + t^3 - t^4``."""
        return _poly_text(list(self.jones))


def _poly_text(terms: Sequence[tuple[int, int]]) -> str:
    out = []
    for e, c in terms:
        if c == 0:
            continue
        mag = abs(c)
        mono = "" if e == 0 else ("t" if e == 1 else f"t^{e}")
        body = str(mag) if not mono else (mono if mag == 1 else f"{mag}{mono}")
        out.append(("- " if c < 0 else "+ ") + body)
    if not out:
        return "0"
    text = " ".join(out)
    return text[2:] if text.startswith("+ ") else "-" + text[2:]


def invariants(code: GaussCode) -> KnotType:
    """The invariants of a closed diagram, named from the catalogue (``"unknown"`` outside it)."""
    alexander, jones = _polynomials(_canonical(simplify(code)))
    determinant = abs(sum(c * (-1) ** i for i, c in enumerate(alexander)))
    name = _BY_INVARIANTS.get((alexander, jones), UNKNOWN)
    return KnotType(name, alexander, determinant, jones, code.writhe)


def _canonical(code: GaussCode) -> GaussCode:
    """One diagram for all its starting points: its least rotation, numbered by first passage.

    The cuts of one closed diagram (a knot goal's states) close to rotations of one code, so their
    polynomials are computed once (:func:`_polynomials` caches them). A rotation is compared by its word
    of (over, steps to the crossing's other passage, sign), which names no crossing.
    """
    m = len(code.events)
    if m == 0:
        return code
    passages: dict[int, list[int]] = {}
    for i, (c, _) in enumerate(code.events):
        passages.setdefault(c, []).append(i)
    word = []
    for i, (c, over) in enumerate(code.events):
        first, second = passages[c]
        word.append((over, ((second if i == first else first) - i) % m, code.signs[c]))
    doubled = word + word
    r = min(range(m), key=lambda r: doubled[r : r + m])
    return _walking_order(GaussCode(code.events[r:] + code.events[:r], code.signs))


@lru_cache(maxsize=1 << 14)
def _polynomials(code: GaussCode) -> tuple[tuple[int, ...], tuple[tuple[int, int], ...]]:
    return alexander_polynomial(code), jones_polynomial(code)


# ---------------------------------------------------------------------------------------------
# The table: KnotInfo's prime knots up to 7 crossings, their mirrors, and the composites up to 7


def _entry(name: str, alexander: Sequence[int], jones: Sequence[tuple[int, int]]) -> KnotType:
    """A table entry; the Alexander polynomial normalised as :func:`alexander_polynomial` does."""
    coeffs = tuple(alexander)
    if sum(coeffs) < 0:
        coeffs = tuple(-c for c in coeffs)
    det = abs(sum(c * (-1) ** i for i, c in enumerate(coeffs)))
    return KnotType(name, coeffs, det, tuple(sorted((e, c) for e, c in jones if c)))


def _mirror_jones(jones: Sequence[tuple[int, int]]) -> tuple[tuple[int, int], ...]:
    return tuple(sorted((-e, c) for e, c in jones))


def _alexander_times(a: tuple[int, ...], b: tuple[int, ...]) -> tuple[int, ...]:
    out = [0] * (len(a) + len(b) - 1)
    for i, x in enumerate(a):
        for j, y in enumerate(b):
            out[i + j] += x * y
    return tuple(out)


def _prime_entries() -> list[KnotType]:
    """Each KnotInfo knot as KnotInfo gives it (``+``; no sign when amphicheiral) and its mirror (``-``)."""
    out = []
    for k in KNOTINFO.values():
        if k.chiral:
            out.append(_entry(k.name + "+", k.alexander, k.jones))
            out.append(_entry(k.name + "-", k.alexander, _mirror_jones(k.jones)))
        else:
            out.append(_entry(k.name, k.alexander, k.jones))
    return out


def _composite_entries(primes: Sequence[KnotType]) -> list[KnotType]:
    """Connected sums of two table knots with at most :data:`MAX_TABLE_CROSSINGS` crossings in all.

    Both polynomials of a connected sum are the products of the summands' (docs/DESIGN.md section 9.3).
    Named ``A#B`` with A before B in the table's order, except that a sum of one knot with itself lists
    the ``+`` summand first (``3_1+#3_1-``, the square knot).
    """
    out = []
    for i, a in enumerate(primes):
        for b in primes[i:]:
            if _crossings_of_name(a.name) + _crossings_of_name(b.name) > MAX_TABLE_CROSSINGS:
                continue
            jones = _loop_poly(dict(a.jones), dict(b.jones))
            alexander = _alexander_times(a.alexander, b.alexander)
            out.append(_entry(f"{a.name}#{b.name}", alexander, list(jones.items())))
    return out


def _crossings_of_name(name: str) -> int:
    return sum(int(part.split("_")[0]) for part in name.split("#"))


_PRIMES = _prime_entries()
# The table in KnotInfo's order, each chirality apart, then the composites (granny and square among them).
CATALOGUE: dict[str, KnotType] = {
    k.name: k for k in (_entry("0_1", (1,), ((0, 1),)), *_PRIMES, *_composite_entries(_PRIMES))
}
_BY_INVARIANTS = {(k.alexander, k.jones): k.name for k in CATALOGUE.values()}
assert len(_BY_INVARIANTS) == len(CATALOGUE), "the table's invariants must separate its entries"


def crossing_number(knot_type: str) -> int:
    """The minimal crossing number of a table type: ``3_1+`` -> 3, ``3_1+#3_1-`` -> 6.

    (Additivity of the crossing number under connected sum holds for these alternating summands.)
    """
    if knot_type not in CATALOGUE:
        raise ValueError(f"{knot_type!r} is not a catalogue knot type")
    return _crossings_of_name(knot_type)


def mirror_type(knot: KnotType) -> KnotType:
    """The mirror image: the Jones polynomial at ``1/t``, the name's chirality signs swapped."""
    jones = _mirror_jones(knot.jones)
    name = _BY_INVARIANTS.get((knot.alexander, jones), UNKNOWN)
    writhe = None if knot.writhe is None else -knot.writhe
    return KnotType(name, knot.alexander, knot.determinant, jones, writhe)


def mirror_name(knot_type: str) -> str:
    """The table name of the mirror image: ``6_1+`` -> ``6_1-``, ``4_1`` -> ``4_1``, ``3_1+#4_1`` ->
    ``3_1-#4_1``."""
    return mirror_type(CATALOGUE[knot_type]).name


def knotinfo_name(knot_type: str) -> str:
    """KnotInfo's name of a table type, chirality left out: ``6_1-`` -> ``6_1``, ``3_1+#3_1-`` ->
    ``3_1#3_1``."""
    return "#".join(part.rstrip("+-") for part in knot_type.split("#"))


# ---------------------------------------------------------------------------------------------
# Names a user may type


class KnotNameError(ValueError):
    """A knot name that is not in :data:`KNOT_NAMES`; the message lists the valid names."""


# Common names, only where a published table gives the mapping (docs/knots.md cites them): the knot
# tables' names of the prime knots, and the knot books' overhand, granny and square knots.
COMMON_NAMES: dict[str, tuple[str, ...]] = {
    "3_1": ("overhand", "trefoil"),
    "4_1": ("figure-eight", "figure-8"),
    "5_1": ("cinquefoil",),
    "5_2": ("three-twist",),
    "6_1": ("stevedore",),
    "7_1": ("septafoil",),
}


def _names() -> dict[str, frozenset[str]]:
    """What a user may type -> the table types it stands for (lower case)."""
    names: dict[str, set[str]] = {"unknot": {"0_1"}}
    for t in CATALOGUE:
        names.setdefault(t.lower(), set()).add(t)
        bare = knotinfo_name(t)
        if "#" not in t:
            names.setdefault(bare.lower(), set()).add(t)  # "6_1": both chiralities
            for common in COMMON_NAMES.get(bare, ()):
                names.setdefault(common, set()).add(t)
                if t.endswith(("+", "-")):
                    names.setdefault(common + t[-1], set()).add(t)
        else:
            first, second = t.split("#")
            names.setdefault(f"{second}#{first}".lower(), set()).add(t)
            if first.rstrip("+-") != second.rstrip("+-"):
                names.setdefault(bare.lower(), set()).add(t)  # "3_1#4_1": both chiralities
                names.setdefault(f"{second.rstrip('+-')}#{first.rstrip('+-')}".lower(), set()).add(t)
    names["granny"] = {"3_1+#3_1+", "3_1-#3_1-"}
    names["granny+"], names["granny-"] = {"3_1+#3_1+"}, {"3_1-#3_1-"}
    names["square"] = names["reef"] = {"3_1+#3_1-"}
    return {name: frozenset(types) for name, types in names.items()}


KNOT_NAMES: dict[str, frozenset[str]] = _names()


def knot_words(knot_type: str) -> str:
    """A table type in words: ``3_1+`` -> ``overhand / trefoil, as KnotInfo gives it``."""
    if knot_type == "0_1":
        return "unknot"
    for name in ("granny", "square"):
        if knot_type in KNOT_NAMES[name]:
            words = {"granny": "granny knot (two trefoils of one handedness)", "square": "square (reef) knot"}
            return f"{words[name]}, {knot_type}"
    bare = knotinfo_name(knot_type)
    common = COMMON_NAMES.get(bare)
    what = " / ".join(common) if common else bare
    if "#" in knot_type:
        return f"connected sum {knot_type}"
    if bare == "3_1":  # KnotInfo's trefoil is the right-handed one (Jones t + t^3 - t^4)
        what = "trefoil (overhand knot), " + ("right-handed" if knot_type.endswith("+") else "left-handed")
    if knot_type.endswith("+"):
        return f"{what}, as KnotInfo gives it"
    if knot_type.endswith("-"):
        return f"{what}, KnotInfo's mirror image"
    return f"{what}, its own mirror image"


def resolve_knot(name: str) -> frozenset[str]:
    """The table types a user's name stands for (``"overhand"`` -> ``{"3_1+", "3_1-"}``).

    Raises :class:`KnotNameError` listing the table (a knot beyond it, e.g. ``8_1``, is named so).
    """
    key = name.strip().lower()
    if key in KNOT_NAMES:
        return KNOT_NAMES[key]
    also = ", ".join(n for n in KNOT_NAMES if n not in CATALOGUE)
    listed = f"the table: {', '.join(CATALOGUE)}; also {also}"
    shown = name if len(name) <= 40 else name[:40] + "..."
    if _beyond_table(key):
        raise KnotNameError(
            f"knot {shown!r} is beyond the table (prime knots up to {MAX_TABLE_CROSSINGS} crossings and sums "
            f"of two with at most {MAX_TABLE_CROSSINGS} in all); valid names: {listed}"
        )
    raise KnotNameError(f"unknown knot name {shown!r}; valid names: {listed}")


def _beyond_table(key: str) -> bool:
    """True for a knot-table name (``8_1``, ``5_1#3_1``) with more crossings than the table holds."""
    parts = key.split("#")
    if not all(re.fullmatch(r"\d{1,3}_\d{1,4}[+-]?", p) for p in parts):
        return False
    return sum(int(p.split("_")[0]) for p in parts) > MAX_TABLE_CROSSINGS


def shown_name(knot_type: str) -> str:
    """The name a listing shows: the common name with its chirality where one stands for exactly this
    type (``overhand+``, ``figure-eight``, ``square``), else the table type (``6_2+``)."""
    for name in ("granny+", "granny-", "square"):
        if KNOT_NAMES[name] == {knot_type}:
            return name
    bare = knotinfo_name(knot_type)
    if knot_type == "0_1":
        return "unknot"
    if "#" in knot_type or bare not in COMMON_NAMES:
        return knot_type
    return COMMON_NAMES[bare][0] + knot_type[len(bare) :]
