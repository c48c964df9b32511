"""The polynomial invariants of a closed diagram: Alexander (Fox calculus), Kauffman bracket, Jones.

Computed here, no dependency. :func:`alexander_polynomial` is normalised to be symmetric with
``Delta(1) = 1``; :func:`jones_polynomial` comes from :func:`kauffman_bracket` and tells a knot from
its mirror. Naming a diagram by them is :func:`twisted.knots.catalogue.invariants`.
"""

from __future__ import annotations

from collections.abc import Sequence

from twisted.knots.gauss import GaussCode

__all__ = ["alexander_polynomial", "jones_polynomial", "kauffman_bracket"]


def _int_det(rows: list[list[int]]) -> int:
    """Exact determinant of an integer matrix (fraction-free Bareiss elimination)."""
    a = [row[:] for row in rows]
    n = len(a)
    if n == 0:
        return 1
    sign, prev = 1, 1
    for k in range(n - 1):
        if a[k][k] == 0:
            swap = next((r for r in range(k + 1, n) if a[r][k] != 0), None)
            if swap is None:
                return 0
            a[k], a[swap] = a[swap], a[k]
            sign = -sign
        for i in range(k + 1, n):
            for j in range(k + 1, n):
                a[i][j] = (a[i][j] * a[k][k] - a[i][k] * a[k][j]) // prev
        prev = a[k][k]
    return sign * a[n - 1][n - 1]


def _interpolate(x0: int, ys: Sequence[int]) -> list[int]:
    """Integer coefficients (constant first) of the polynomial with values ``ys`` at ``x0, x0 + 1, ...``.

    Newton's forward form: ``p(x) = sum_k (Delta^k y_0 / k!) (x - x0) (x - x0 - 1) ... (x - x0 - k + 1)``;
    for a polynomial with integer coefficients every ``Delta^k y_0`` is a multiple of ``k!``, so all of it
    stays in integers.
    """
    n = len(ys)
    diffs, row = [], list(ys)
    for _ in range(n):
        diffs.append(row[0])
        row = [b - a for a, b in zip(row, row[1:], strict=False)]
    coeffs = [0] * n
    basis = [1]  # (x - x0) ... (x - x0 - k + 1), constant first
    factorial = 1
    for k, d in enumerate(diffs):
        if k:
            factorial *= k
        if d % factorial:
            raise ArithmeticError("Alexander interpolation gave non-integer coefficients")
        for m, b in enumerate(basis):
            coeffs[m] += (d // factorial) * b
        root = x0 + k
        padded = [0, *basis, 0]
        basis = [padded[m] - root * padded[m + 1] for m in range(len(basis) + 1)]
    return coeffs


def alexander_polynomial(code: GaussCode) -> tuple[int, ...]:
    """Normalised Alexander polynomial (coefficients of ``t^-d .. t^d``, ``Delta(1) = 1``).

    Wirtinger arcs run from one under-passage to the next. Crossing ``c`` with over arc ``k``,
    incoming under arc ``i`` and outgoing ``j`` gives the relation ``x_j = x_k^s x_i x_k^-s``
    (``s`` its sign); its Fox derivatives, abelianised (every ``x -> t``) and multiplied by a unit,
    are the row ``(1 - t) at k, t at i, -1 at j`` for ``s = +1`` and ``(1 - t), -1, t`` for ``s = -1``.
    """
    n = code.n_crossings
    if n == 0:
        return (1,)
    # arc of each event: the arc index advances after each under-passage
    first_under = next(i for i, (_, over) in enumerate(code.events) if not over)
    m = len(code.events)
    arc_at: dict[int, int] = {}
    in_arc: dict[int, int] = {}
    out_arc: dict[int, int] = {}
    arc = n - 1  # walking from the first under-passage: the arc entering it is the last one
    for step in range(m):
        c, over = code.events[(first_under + step) % m]
        if over:
            arc_at[c] = arc
        else:
            in_arc[c] = arc
            arc = (arc + 1) % n
            out_arc[c] = arc

    def minor_at(t: int) -> int:
        rows = [[0] * n for _ in range(n)]
        for c in range(n):
            s = code.signs[c]
            row = rows[c]
            row[arc_at[c]] += 1 - t
            row[in_arc[c]] += t if s > 0 else -1
            row[out_arc[c]] += -1 if s > 0 else t
        return _int_det([r[:-1] for r in rows[:-1]])

    coeffs = _interpolate(2, [minor_at(x) for x in range(2, n + 2)])
    while coeffs and coeffs[-1] == 0:
        coeffs.pop()
    while coeffs and coeffs[0] == 0:
        coeffs.pop(0)
    if not coeffs:
        raise ArithmeticError("Alexander polynomial vanished: the diagram is not a knot")
    if sum(coeffs) < 0:
        coeffs = [-c for c in coeffs]
    if sum(coeffs) != 1 or coeffs != coeffs[::-1] or len(coeffs) % 2 == 0:
        raise ArithmeticError(f"Alexander polynomial {coeffs} is not a knot's (symmetric, Delta(1)=1)")
    return tuple(coeffs)


def _loop_poly(a: dict[int, int], b: dict[int, int]) -> dict[int, int]:
    out: dict[int, int] = {}
    for ea, ca in a.items():
        for eb, cb in b.items():
            out[ea + eb] = out.get(ea + eb, 0) + ca * cb
    return {e: c for e, c in out.items() if c}


_LOOP = {2: -1, -2: -1}  # d = -A^2 - A^-2, the value of a closed loop


def _greedy_order(pd: Sequence[tuple[int, int, int, int]]) -> list[tuple[int, int, int, int]]:
    """Crossings ordered so each one shares as many edges as possible with those before it."""
    left = list(pd)
    open_edges: set[int] = set()
    order = []
    while left:
        best = max(range(len(left)), key=lambda i: (sum(e in open_edges for e in left[i]), -i))
        x = left.pop(best)
        order.append(x)
        open_edges ^= {e for e in x if x.count(e) == 1}
    return order


def kauffman_bracket(pd: Sequence[tuple[int, int, int, int]]) -> dict[int, int]:
    """Kauffman bracket ``<K>`` in ``A`` (exponent -> coefficient), normalised so ``<O> = 1``.

    Crossings are smoothed one at a time (``<X[a,b,c,d]> = A <(ab)(cd)> + A^-1 <(ad)(bc)>``) while
    a table maps each matching of the still open edge ends to its polynomial. The table grows with
    the number of open ends, so the next crossing is always the one that closes the most of them.
    """
    if not pd:
        return {0: 1}
    states: dict[tuple[tuple[int, int], ...], dict[int, int]] = {(): {0: 1}}
    for a, b, c, dd in _greedy_order(pd):
        new_states: dict[tuple[tuple[int, int], ...], dict[int, int]] = {}
        for matching, poly in states.items():
            for weight, pairs in ((1, ((a, b), (c, dd))), (-1, ((a, dd), (b, c)))):
                ends = dict(matching)
                ends.update({y: x for x, y in matching})
                loops = 0
                for x, y in pairs:
                    # ends maps each open edge end to the other open end of its partial strand
                    ux, uy = ends.get(x), ends.get(y)
                    if x == y or (ux is not None and ux == y):
                        loops += 1  # the new arc closes a strand into a loop
                        ends.pop(x, None)
                        ends.pop(y, None)
                    elif ux is not None and uy is not None:
                        del ends[x], ends[y]
                        ends[ux], ends[uy] = uy, ux
                    elif ux is not None:
                        del ends[x]
                        ends[ux], ends[y] = y, ux
                    elif uy is not None:
                        del ends[y]
                        ends[uy], ends[x] = x, uy
                    else:
                        ends[x], ends[y] = y, x
                key = tuple(sorted((x, y) for x, y in ends.items() if x < y))
                term = {e + weight: cf for e, cf in poly.items()}
                for _ in range(loops):
                    term = _loop_poly(term, _LOOP)
                acc = new_states.setdefault(key, {})
                for e, cf in term.items():
                    acc[e] = acc.get(e, 0) + cf
        states = {k: {e: c for e, c in v.items() if c} for k, v in new_states.items()}
    total = states.get((), {})
    # every state ends in at least one loop, so <K> counted d once too many: divide by d
    return _divide_by_loop(total)


def _divide_by_loop(poly: dict[int, int]) -> dict[int, int]:
    """Exact division by ``d = -A^2 - A^-2 = -A^-2 (1 + A^4)``."""
    if not poly:
        raise ArithmeticError("Kauffman bracket vanished")
    lo = min(poly)
    coeffs = [0] * (max(poly) - lo + 1)
    for e, c in poly.items():
        coeffs[e - lo] = c
    # divide by (1 + A^4), lowest degree first
    q = [0] * max(len(coeffs) - 4, 0)
    rem = coeffs[:]
    for i in range(len(q)):
        q[i] = rem[i]
        rem[i] -= q[i]
        rem[i + 4] -= q[i]
    if any(rem):
        raise ArithmeticError("Kauffman bracket is not divisible by the loop value")
    # times -A^2 (the inverse of -A^-2)
    return {lo + i + 2: -c for i, c in enumerate(q) if c}


def jones_polynomial(code: GaussCode) -> tuple[tuple[int, int], ...]:
    """Jones polynomial ``V(t) = (-A^3)^(-w) <K>`` at ``A = t^(-1/4)``: ``((exponent, coeff), ...)``."""
    bracket = kauffman_bracket(code.pd_code())
    w = code.writhe
    factor_sign = -1 if w % 2 else 1
    out = {}
    for e, c in bracket.items():
        a_exp = e - 3 * w
        if a_exp % 4:
            raise ArithmeticError("Jones polynomial has fractional exponents: the diagram is not a knot")
        out[-a_exp // 4] = factor_sign * c
    return tuple(sorted((e, c) for e, c in out.items() if c))
