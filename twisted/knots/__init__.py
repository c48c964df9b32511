"""Knots by name: which knot a rope state really ties (issues 10 and 14; docs/DESIGN.md section 9).

Closing the rope. An open rope ties no knot in the strict sense; it needs a closure. Two are natural:
lower both ends below the table and join them there by an arc that passes *under* everything, or lift
them and join them above everything (*over*). Each is well defined: the rope lies in a slab, the arc
consists of two vertical pieces plus a simple arc in a plane outside the slab, and any two simple arcs
in that plane with the same end points are isotopic there, so any two closures of one kind are
isotopic knots. In a diagram: route the closing arc through any faces, passing under (over) the rope
wherever it must, and the invariants come out the same.

The two closures can differ: when an end lies inside a loop, passing under or over the loop's strand
on the way out decides whether a knot forms. Such a diagram is a knotoid (Turaev, "Knotoids", 2012),
and pulling the rope's ends apart does not give one answer. So a state ties knot K only when BOTH
closures are K (:class:`RopeKnot`; true, for example, whenever both ends lie in one face, since then the
closing arc crosses nothing); otherwise it ties no knot and is named ``"knotoid"``. Under this rule
each knot up to 5 crossings first appears at its crossing number (``bench/bench_knots.py``).

The two routes (they must agree, ``tests/test_knots.py`` checks it on collected data):

* from P-data (:func:`identify`): :func:`twisted.diagram.diagram` rebuilds the planar diagram of the
  open rope with its faces; the head tip lies in one face, the tail tip in another; a shortest path
  in the dual graph (faces joined across the segment sides that separate them) gives the closing
  arc. It crosses each segment at most once and enters each face once, so inside every face it is
  one chord and the closed diagram is planar.
* from link points (:func:`identify_points`): the ends are lowered below the table (lifted above the
  rope) and joined by a straight segment there; the closed polygon is projected to the table and its
  crossings read as in :func:`twisted.topology.top`.

Invariants (computed here, no dependency):

* ``alexander``: the Alexander polynomial from the Wirtinger presentation (Fox calculus), an
  ``(N-1) x (N-1)`` minor of the ``N x N`` Alexander matrix of a diagram with ``N`` crossings,
  normalised to be symmetric (``Delta(t) = Delta(1/t)``) with ``Delta(1) = +1`` (Conway's
  normalisation); stored as the coefficients of ``t^-d .. t^d``, e.g. the trefoil ``(1, -1, 1)``.
* ``determinant``: ``|Delta(-1)|``.
* ``jones``: the Jones polynomial from the Kauffman bracket, ``V(t) = (-A^3)^(-w) <K>`` at
  ``A = t^(-1/4)``, stored as ``((exponent of t, coefficient), ...)`` by increasing exponent. It
  tells a knot from its mirror (``V_mirror(t) = V(1/t)``).

Chirality. A crossing's sign is the P-data sign ``sign((d_over x d_under) . e_z)``, the usual
right-hand rule, which KnotInfo's PD codes follow as well. ``K+`` names a chiral knot as KnotInfo gives
it (its PD code has KnotInfo's Jones polynomial), ``K-`` its mirror image (``V_mirror(t) = V(1/t)``);
for ``3_1``, ``5_1``, ``5_2`` and ``7_1`` ... ``7_5`` that ``+`` is the positive knot: ``3_1+`` is the
right-handed trefoil, ``V = t + t^3 - t^4``, so the 3-crossing rope whose visits alternate O/U with one
common sign ``+`` ties ``3_1+``. ``4_1`` and ``6_3`` are their own mirror images.

Identification compares ``(alexander, jones)`` with the knot table (:data:`CATALOGUE`: KnotInfo's prime
knots up to 7 crossings, each chirality, and the sums of two with at most 7 crossings in all); a
diagram whose invariants match no entry is ``"unknown"`` (it still carries its invariants). Within the
table the pair separates every entry; a larger knot with the same pair would be misnamed, a risk that
does not arise for the small diagrams a rope of a few dozen links makes.

Modules:

* :mod:`twisted.knots.gauss`: closed diagrams as signed Gauss codes, their simplification, and the two
  closures of a rope state (P-data) or of a closed polygon (link points).
* :mod:`twisted.knots.polynomials`: the Alexander polynomial, the Kauffman bracket, the Jones polynomial.
* :mod:`twisted.knots.knotinfo`: KnotInfo's prime knots up to 7 crossings (PD codes, polynomials).
* :mod:`twisted.knots.catalogue`: :class:`KnotType`, :func:`invariants` (a diagram named from the
  table), the knot table with its crossing numbers and mirrors, and the names a user may type.
* :mod:`twisted.knots.rope`: what a rope ties (:class:`RopeKnot`, :func:`identify`,
  :func:`identify_points`).
* :mod:`twisted.knots.states`: the states that tie a named knot (:func:`states_tying`), cut from its
  KnotInfo diagram at its crossing number (:func:`minimal_states`).
"""

from twisted.knots.catalogue import (
    CATALOGUE,
    COMMON_NAMES,
    COMPOSITE_NOTE,
    KNOT_NAMES,
    UNKNOWN,
    KnotNameError,
    KnotType,
    crossing_number,
    invariants,
    knot_words,
    knotinfo_name,
    mirror_name,
    mirror_type,
    resolve_knot,
    shown_name,
)
from twisted.knots.gauss import (
    GaussCode,
    closed_gauss_code,
    gauss_code_from_pd,
    gauss_code_from_polygon,
    simplify,
)
from twisted.knots.knotinfo import KNOTINFO, MAX_TABLE_CROSSINGS, KnotInfoKnot
from twisted.knots.polynomials import alexander_polynomial, jones_polynomial, kauffman_bracket
from twisted.knots.rope import KNOTOID, RopeKnot, identify, identify_points, knot_type_name
from twisted.knots.states import (
    MAX_BUILT_CROSSINGS,
    MAX_ENUMERATED_CROSSINGS,
    least_crossings,
    minimal_states,
    prime_states_by_type,
    primed_states,
    rotations,
    states_by_type,
    states_tying,
)

__all__ = [
    "CATALOGUE",
    "COMMON_NAMES",
    "COMPOSITE_NOTE",
    "KNOTINFO",
    "KNOTOID",
    "KNOT_NAMES",
    "MAX_BUILT_CROSSINGS",
    "MAX_ENUMERATED_CROSSINGS",
    "MAX_TABLE_CROSSINGS",
    "UNKNOWN",
    "GaussCode",
    "KnotInfoKnot",
    "KnotNameError",
    "KnotType",
    "RopeKnot",
    "alexander_polynomial",
    "closed_gauss_code",
    "crossing_number",
    "gauss_code_from_pd",
    "gauss_code_from_polygon",
    "identify",
    "identify_points",
    "invariants",
    "jones_polynomial",
    "kauffman_bracket",
    "knot_type_name",
    "knot_words",
    "knotinfo_name",
    "least_crossings",
    "minimal_states",
    "mirror_name",
    "mirror_type",
    "prime_states_by_type",
    "primed_states",
    "resolve_knot",
    "rotations",
    "shown_name",
    "simplify",
    "states_by_type",
    "states_tying",
]
