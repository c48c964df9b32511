"""The catalogue of named knot types, naming a diagram by its invariants, and the names a user may type.

:class:`KnotType` is a knot with the invariants that named it; :func:`invariants` computes them for a
closed diagram and looks the pair ``(alexander, jones)`` up in :data:`CATALOGUE` (the knots up to five
crossings and the granny and square knots, docs/DESIGN.md section 9.3). :data:`KNOT_NAMES` and
:func:`resolve_knot` map what a user types (``overhand``, ``figure-eight``, ``square``, ...) to
catalogue types.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from twisted.knots.gauss import GaussCode, _walking_order, simplify
from twisted.knots.polynomials import _loop_poly, alexander_polynomial, jones_polynomial

__all__ = [
    "CATALOGUE",
    "COMPOSITE_NOTE",
    "KNOT_NAMES",
    "UNKNOWN",
    "KnotNameError",
    "KnotType",
    "crossing_number",
    "invariants",
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
    reduced = _walking_order(simplify(code))
    alexander = alexander_polynomial(reduced)
    determinant = abs(sum(c * (-1) ** i for i, c in enumerate(alexander)))
    jones = jones_polynomial(reduced)
    name = _BY_INVARIANTS.get((alexander, jones), UNKNOWN)
    return KnotType(name, alexander, determinant, jones, code.writhe)


# ---------------------------------------------------------------------------------------------
# Catalogue of knots up to five crossings


def _entry(name: str, alexander: tuple[int, ...], jones: dict[int, int]) -> KnotType:
    det = abs(sum(c * (-1) ** i for i, c in enumerate(alexander)))
    return KnotType(name, alexander, det, tuple(sorted(jones.items())))


def _mirror_jones(jones: dict[int, int]) -> dict[int, int]:
    return {-e: c for e, c in jones.items()}


def _times(a: dict[int, int], b: dict[int, int]) -> dict[int, int]:
    """Product of two Laurent polynomials (exponent -> coefficient)."""
    return _loop_poly(a, b)


def _alexander_times(a: tuple[int, ...], b: tuple[int, ...]) -> tuple[int, ...]:
    out = [0] * (len(a) + len(b) - 1)
    for i, x in enumerate(a):
        for j, y in enumerate(b):
            out[i + j] += x * y
    return tuple(out)


# Jones polynomials of the positive (right-handed) versions; the "-" ones are their mirrors.
_J31 = {1: 1, 3: 1, 4: -1}
_J51 = {2: 1, 4: 1, 5: -1, 6: 1, 7: -1}
_J52 = {1: 1, 2: -1, 3: 2, 4: -1, 5: 1, 6: -1}
_A31 = (1, -1, 1)
# Composite knots: the Alexander and Jones polynomials of a connected sum are the products of the
# summands' (docs/DESIGN.md section 9.3). Granny and square share Alexander polynomial and determinant
# (9); the Jones polynomial tells them apart (the square knot's is symmetric: it is its own mirror).
CATALOGUE: dict[str, KnotType] = {
    k.name: k
    for k in (
        _entry("0_1", (1,), {0: 1}),
        _entry("3_1+", _A31, _J31),
        _entry("3_1-", _A31, _mirror_jones(_J31)),
        _entry("4_1", (-1, 3, -1), {-2: 1, -1: -1, 0: 1, 1: -1, 2: 1}),
        _entry("5_1+", (1, -1, 1, -1, 1), _J51),
        _entry("5_1-", (1, -1, 1, -1, 1), _mirror_jones(_J51)),
        _entry("5_2+", (2, -3, 2), _J52),
        _entry("5_2-", (2, -3, 2), _mirror_jones(_J52)),
        _entry("3_1+#3_1+", _alexander_times(_A31, _A31), _times(_J31, _J31)),
        _entry("3_1-#3_1-", _alexander_times(_A31, _A31), _mirror_jones(_times(_J31, _J31))),
        _entry("3_1+#3_1-", _alexander_times(_A31, _A31), _times(_J31, _mirror_jones(_J31))),
    )
}
_BY_INVARIANTS = {(k.alexander, k.jones): k.name for k in CATALOGUE.values()}
assert len(_BY_INVARIANTS) == len(CATALOGUE), "the catalogue's invariants must separate its entries"


def crossing_number(knot_type: str) -> int:
    """The minimal crossing number of a catalogue type: ``3_1+`` -> 3, ``3_1+#3_1-`` -> 6.

    (Additivity of the crossing number under connected sum holds for these alternating summands.)
    """
    if knot_type not in CATALOGUE:
        raise ValueError(f"{knot_type!r} is not a catalogue knot type")
    return sum(int(part.split("_")[0]) for part in knot_type.split("#"))


def mirror_type(knot: KnotType) -> KnotType:
    """The mirror image: the Jones polynomial at ``1/t``, the name's chirality signs swapped."""
    jones = tuple(sorted((-e, c) for e, c in knot.jones))
    name = _BY_INVARIANTS.get((knot.alexander, jones), UNKNOWN)
    writhe = None if knot.writhe is None else -knot.writhe
    return KnotType(name, knot.alexander, knot.determinant, jones, writhe)


# ---------------------------------------------------------------------------------------------
# Names a user may type


class KnotNameError(ValueError):
    """A knot name that is not in :data:`KNOT_NAMES`; the message lists the valid names."""


KNOT_NAMES: dict[str, frozenset[str]] = {
    "unknot": frozenset({"0_1"}),
    "0_1": frozenset({"0_1"}),
    "overhand": frozenset({"3_1+", "3_1-"}),
    "trefoil": frozenset({"3_1+", "3_1-"}),
    "3_1": frozenset({"3_1+", "3_1-"}),
    "overhand+": frozenset({"3_1+"}),
    "trefoil+": frozenset({"3_1+"}),
    "3_1+": frozenset({"3_1+"}),
    "overhand-": frozenset({"3_1-"}),
    "trefoil-": frozenset({"3_1-"}),
    "3_1-": frozenset({"3_1-"}),
    "figure-eight": frozenset({"4_1"}),
    "figure-8": frozenset({"4_1"}),
    "4_1": frozenset({"4_1"}),
    "5_1": frozenset({"5_1+", "5_1-"}),
    "5_1+": frozenset({"5_1+"}),
    "5_1-": frozenset({"5_1-"}),
    "5_2": frozenset({"5_2+", "5_2-"}),
    "5_2+": frozenset({"5_2+"}),
    "5_2-": frozenset({"5_2-"}),
    "granny": frozenset({"3_1+#3_1+", "3_1-#3_1-"}),
    "granny+": frozenset({"3_1+#3_1+"}),
    "granny-": frozenset({"3_1-#3_1-"}),
    "3_1+#3_1+": frozenset({"3_1+#3_1+"}),
    "3_1-#3_1-": frozenset({"3_1-#3_1-"}),
    "square": frozenset({"3_1+#3_1-"}),
    "reef": frozenset({"3_1+#3_1-"}),
    "3_1+#3_1-": frozenset({"3_1+#3_1-"}),
    "3_1-#3_1+": frozenset({"3_1+#3_1-"}),
}


def resolve_knot(name: str) -> frozenset[str]:
    """The canonical knot types a user's name stands for (``"overhand"`` -> ``{"3_1+", "3_1-"}``)."""
    key = name.strip().lower()
    if key in KNOT_NAMES:
        return KNOT_NAMES[key]
    raise KnotNameError(f"unknown knot name {name!r}; valid names: {', '.join(KNOT_NAMES)}")
