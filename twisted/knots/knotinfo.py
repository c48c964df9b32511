"""The prime knots of the table as KnotInfo gives them (docs/DESIGN.md section 9.3).

KnotInfo (C. Livingston and A. H. Moore, https://knotinfo.org), packaged as ``database-knotinfo``,
lists every prime knot up to 13 crossings with its PD code, polynomials and symmetry type. The
rows are ordered by crossing number, so the knots up to :data:`MAX_TABLE_CROSSINGS` are the first
few lines of its file: they are read once, at import (a few milliseconds; the package's own
``link_list()`` parses all 12,966 rows, about 2 s).

Each row becomes a :class:`KnotInfoKnot`: the name (``"6_1"``), the PD code, the Alexander and
Jones polynomials as KnotInfo lists them, the determinant and the symmetry type. KnotInfo's PD
code lists per crossing its four edges starting from the incoming under edge, counter-clockwise,
the edges numbered along the knot's orientation (the convention of
:meth:`twisted.knots.gauss.GaussCode.pd_code`).
"""

from __future__ import annotations

import csv
import json
import os
from dataclasses import dataclass

import database_knotinfo

__all__ = ["KNOTINFO", "MAX_TABLE_CROSSINGS", "KnotInfoKnot", "KnotInfoError"]

# The table stops here: every prime knot up to 7 crossings (issue 65).
MAX_TABLE_CROSSINGS = 7


class KnotInfoError(RuntimeError):
    """The installed KnotInfo data does not read as expected (a changed file format)."""


@dataclass(frozen=True, slots=True)
class KnotInfoKnot:
    """One KnotInfo row: a prime knot as KnotInfo gives it (its own chirality, the ``+`` of our names)."""

    name: str
    crossing_number: int
    pd: tuple[tuple[int, int, int, int], ...]
    alexander: tuple[int, ...]  # coefficients of t^0 .. t^d, as KnotInfo lists them (not normalised)
    jones: tuple[tuple[int, int], ...]  # ((exponent of t, coefficient), ...), increasing exponent
    determinant: int
    signature: int
    symmetry_type: str

    @property
    def chiral(self) -> bool:
        """True unless KnotInfo calls the knot amphicheiral (it is then its own mirror image)."""
        return "amphicheiral" not in self.symmetry_type


def _vector(text: str, what: str) -> list[int]:
    try:
        values = json.loads(text)
    except json.JSONDecodeError as exc:
        raise KnotInfoError(f"KnotInfo {what} {text!r} is not a list: {exc}") from None
    if not isinstance(values, list) or not all(isinstance(v, int) for v in values) or len(values) < 3:
        raise KnotInfoError(f"KnotInfo {what} {text!r} is not a list of integers")
    return values


def _jones(text: str) -> tuple[tuple[int, int], ...]:
    """``[min exponent, max exponent, coefficients...]`` -> ``((exponent, coefficient), ...)``."""
    lo, hi, *coeffs = _vector(text, "Jones vector")
    if len(coeffs) != hi - lo + 1:
        raise KnotInfoError(f"KnotInfo Jones vector {text!r}: {len(coeffs)} coefficients for {lo}..{hi}")
    return tuple((lo + i, c) for i, c in enumerate(coeffs) if c)


def _alexander(text: str) -> tuple[int, ...]:
    lo, hi, *coeffs = _vector(text, "Alexander vector")
    if lo != 0 or len(coeffs) != hi + 1:
        raise KnotInfoError(f"KnotInfo Alexander vector {text!r} is not t^0..t^{hi}")
    return tuple(coeffs)


def _pd(text: str) -> tuple[tuple[int, int, int, int], ...]:
    rows = _vector(text.replace("[[", "[").replace("]]", "]").replace("],[", ","), "PD code")
    if len(rows) % 4:
        raise KnotInfoError(f"KnotInfo PD code {text!r} does not have four edges per crossing")
    return tuple((rows[i], rows[i + 1], rows[i + 2], rows[i + 3]) for i in range(0, len(rows), 4))


def _read() -> dict[str, KnotInfoKnot]:
    names = database_knotinfo.Names
    path = os.path.join(database_knotinfo.__path__[0], names.csv_path.value, names.file_knot.value + ".csv")
    out: dict[str, KnotInfoKnot] = {}
    with open(path, newline="") as f:
        rows = csv.DictReader(f, delimiter=names.delimiter.value)
        next(rows)  # the second line holds the columns' descriptions
        for row in rows:
            crossings = int(row["crossing_number"])
            if crossings > MAX_TABLE_CROSSINGS:
                break  # the rows are ordered by crossing number
            if crossings == 0:
                continue  # the unknot has no PD code; the catalogue writes it itself
            out[row["name"]] = KnotInfoKnot(
                name=row["name"],
                crossing_number=crossings,
                pd=_pd(row["pd_notation"]),
                alexander=_alexander(row["alexander_polynomial_vector"]),
                jones=_jones(row["jones_polynomial_vector"]),
                determinant=int(row["determinant"]),
                signature=int(row["signature"]),
                symmetry_type=row["symmetry_type"].strip(),
            )
    if not out or any(len(k.pd) != k.crossing_number for k in out.values()):
        raise KnotInfoError(f"KnotInfo data in {path} do not read as prime knots with PD codes")
    return out


# KnotInfo name ("3_1") -> the knot as KnotInfo gives it; the order of KnotInfo's table.
KNOTINFO: dict[str, KnotInfoKnot] = _read()
