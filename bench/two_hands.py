"""Would a second hand make the plan steps that stored searches failed? One-hand curves against two-hand ones.

    python bench/two_hands.py --db sqlite:///tune.db --set tune-u5 --set tune-u4 --label gate \
        [--from 3 --from 4] [--pairs 40] [--k 12] [--workers 1] [--seed 0] [--model-id N] \
        [--json out.json] [--pictures docs/img]

Issue 61 item 2, the gate before a second hand enters the search. For each ``--from`` crossing count it
draws ``--pairs`` (node, requested next state) pairs that the stored runs tried and never reached
(``bench/step_ceiling.py``'s pairs, adding moves only), and simulates from each node's configuration
``--k`` curves of each family:

- ``one-hand``: the planner's own curves (``StepCurves`` with the default options: for a Cross step the
  scripted share, the rest from the model; any other step all from the model);
- ``random-pin``: the same one-hand curves, each with a second hand holding a uniformly drawn other link
  where it lies;
- ``near-pin``: the same one-hand curves with the second hand holding a link 2-4 links from the carried one;
- ``scripted-pin``: for R1, pin and loop: the second hand holds a link of the curled segment, and a link
  2-5 links away is carried around it (200-320 degrees about it, either way, ending 0.4-1 times as far
  from it), lifted, so that it comes down across the rope beside the held link; for Cross, the
  planner's scripted Cross carry with the second hand holding the crossed segment's link nearest the
  carry's target, or the link at the tip piece's first crossing (the knot), half each; none for R2;
- ``place-hold``: pick, place, hold: for R1 the second hand carries a link 3-6 links from a link of the
  curled segment across the rope just beside that link (the loop's crossing point) and holds it there
  while the active hand pulls the loop open (the link half-way between them, 3-8 cm away from the
  crossing point); for other steps the second hand makes the planner's curve as the place and holds it
  while the active hand pulls a link 2-4 links away 2-6 cm;
- ``both-carry``: both hands carry at once: for R1 the pin-and-loop carry with the held link carried
  2-6 cm itself, turned up to 1 rad; for other steps the planner's curve with the second hand carrying a
  neighbour 1-2 links away by 0.5-1 times the same displacement, lower, so that the short piece between
  them is lifted and turned together.

Prints, per crossing count, class of move (``bench/step_moves.py``'s ``move_class``, and all R1 / all
Cross) and family, the curves that reached the step's next state (k of n), the pairs reached by any, the
rate against the one-hand family's, and what the other curves did (fewer crossings than the start, the
start's state, another state, rejected by the simulator) and, of all curves, those whose rope had more
crossings than the start when the hands let go, and those that were in the next state then (a step made
by the carry and lost while the rope settled). ``--pictures DIR`` draws, from the highest
crossing count, one typical outcome per two-hand family (the start with the carry, the rope when the
hands let go, the settled rope) as ``DIR/two_hands_FAMILY.png``.
"""

from __future__ import annotations

import argparse
import json
import math
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from lib.steps import choose, move_class, pairs_from, pool_map, segment_link, step_curves

from twisted.proposals import cross_move_curve, segment_bounds
from twisted.rope import N_LINKS
from twisted.sim import Curve, RopeSim
from twisted.sim.simulator import Pin
from twisted.topology import top

FAMILIES = ("one-hand", "random-pin", "near-pin", "scripted-pin", "place-hold", "both-carry")
OUTCOMES = ("reached", "fewer", "same", "other", "rejected")
RELEASE = ("more at release", "next at release")


def centres(points: Any) -> np.ndarray:
    pts = np.asarray(points, dtype=np.float64)
    return 0.5 * (pts[1:, :2] + pts[:-1, :2])


def other_link(rng: np.random.Generator, link: int, lo: int, hi: int) -> int:
    """A link ``lo..hi`` links from ``link`` on either side (the other side where one runs off the rope)."""
    d = int(rng.integers(lo, hi + 1))
    sides = [s for s in (-1, 1) if 0 <= link + s * d < N_LINKS]
    return link + int(rng.choice(sides)) * d if sides else (0 if link > 0 else N_LINKS - 1)


def with_pin(curve: Curve, pin: Pin) -> Curve:
    return Curve(curve.link, curve.z_max_m, curve.x_m, curve.y_m, pin)


def loop_curve(rng: np.random.Generator, points: Any, p: int, carry_pin: bool = False) -> Curve:
    """Pin and loop: hold link ``p``, carry a link 2-5 away around it (the family ``scripted-pin``)."""
    c = centres(points)
    a = other_link(rng, p, 2, 5)
    around = int(rng.choice([-1, 1]))
    v0 = c[a] - c[p]
    a0 = math.atan2(v0[1], v0[0])
    sweep = around * math.radians(rng.uniform(200, 320))
    r1 = float(np.hypot(*v0)) * rng.uniform(0.4, 1.0)
    target = c[p] + r1 * np.array([math.cos(a0 + sweep), math.sin(a0 + sweep)])
    dx, dy = target - c[a]
    pin = Pin(p, around=around)
    if carry_pin:
        angle, dist = rng.uniform(0, 2 * math.pi), rng.uniform(0.02, 0.06)
        pin = Pin(p, "carry", 0.0, dist * math.cos(angle), dist * math.sin(angle), rng.uniform(-1, 1), around)
    return Curve(a, rng.uniform(0.02, 0.07), float(dx), float(dy), pin)


def place_loop_curve(rng: np.random.Generator, points: Any, p: int) -> Curve:
    """Pick, place, hold for a curl: the second hand lays a link 3-6 from ``p`` across the rope beside
    ``p``; the active hand pulls the loop between them open."""
    pts = np.asarray(points, dtype=np.float64)
    c = centres(pts)
    a = other_link(rng, p, 3, 6)
    along = pts[p + 1, :2] - pts[p, :2]
    normal = np.array([-along[1], along[0]]) / max(float(np.hypot(*along)), 1e-9)
    side = 1.0 if float(np.dot(c[a] - c[p], normal)) >= 0 else -1.0
    # across the strand at p: to the far side from where a lies now
    target = c[p] - side * rng.uniform(0.02, 0.05) * normal + rng.uniform(-0.02, 0.02) * along
    place = target - c[a]
    m = (p + a) // 2
    out = c[m] - c[p]
    out = out / max(float(np.hypot(*out)), 1e-9) * rng.uniform(0.03, 0.08)
    pin = Pin(a, "place", rng.uniform(0.02, 0.05), float(place[0]), float(place[1]))
    return Curve(m, rng.uniform(0.0, 0.02), float(out[0]), float(out[1]), pin)


def pinned_cross(rng: np.random.Generator, points: Any, move: Any, base: Curve) -> Curve:
    """The scripted Cross carry with the crossed segment held near its target, or the tip piece's knot."""
    c = centres(points)
    target = c[base.link] + np.array([base.x_m, base.y_m])
    bounds = segment_bounds(points)
    if rng.random() < 0.5:
        lo, hi = bounds[move.other_segment], bounds[move.other_segment + 1]
        links = [i for i in range(N_LINKS) if lo <= i + 0.5 <= hi and abs(i - base.link) >= 2]
        if links:
            p = min(links, key=lambda i: float(np.hypot(*(c[i] - target))))
            return with_pin(base, Pin(p))
    knot = int(np.clip(bounds[1] if move.segment == 0 else bounds[-2], 0, N_LINKS - 1))
    if abs(knot - base.link) < 1:
        knot = other_link(rng, base.link, 2, 4)
    return with_pin(base, Pin(knot))


def small_pull(rng: np.random.Generator, link: int, place: Curve) -> Curve:
    """Place-hold for other steps: the planner's curve made by the second hand as the place, and a link
    2-4 away pulled 2-6 cm while it holds."""
    a = other_link(rng, place.link, 2, 4)
    angle, dist = rng.uniform(0, 2 * math.pi), rng.uniform(0.02, 0.06)
    pin = Pin(place.link, "place", place.z_max_m, place.x_m, place.y_m)
    return Curve(a, rng.uniform(0.0, 0.02), dist * math.cos(angle), dist * math.sin(angle), pin)


def carry_neighbour(rng: np.random.Generator, base: Curve) -> Curve:
    """Both hands carry: the second a neighbour 1-2 links away, by 0.5-1 times the displacement, lower."""
    b = other_link(rng, base.link, 1, 2)
    f = rng.uniform(0.5, 1.0)
    return with_pin(base, Pin(b, "carry", 0.5 * base.z_max_m, f * base.x_m, f * base.y_m))


def family_curves(
    name: str, rng: np.random.Generator, pair: dict[str, Any], one_hand: list[Curve]
) -> list[Curve]:
    """The curves of family ``name`` for ``pair`` (``one_hand``: the planner's curves for it)."""
    node, move = pair["node"], pair["move"]
    pts = node.points
    if name == "one-hand":
        return one_hand
    if name == "random-pin":
        others = [[i for i in range(N_LINKS) if i != c.link] for c in one_hand]
        return [with_pin(c, Pin(int(rng.choice(o)))) for c, o in zip(one_hand, others, strict=True)]
    if name == "near-pin":
        return [with_pin(c, Pin(other_link(rng, c.link, 2, 4))) for c in one_hand]
    k = len(one_hand)
    if move.kind == "R1":
        bounds = segment_bounds(pts)
        pins = [segment_link(rng, pts, move.segment, bounds) for _ in range(k)]
        if name == "scripted-pin":
            return [loop_curve(rng, pts, p) for p in pins]
        if name == "place-hold":
            return [place_loop_curve(rng, pts, p) for p in pins]
        return [loop_curve(rng, pts, p, carry_pin=True) for p in pins]
    if name == "scripted-pin":
        if move.kind != "Cross":
            return []
        return [pinned_cross(rng, pts, move, cross_move_curve(rng, pts, move)) for _ in range(k)]
    if name == "place-hold":
        return [small_pull(rng, c.link, c) for c in one_hand]
    return [carry_neighbour(rng, c) for c in one_hand]


_sim: RopeSim | None = None


def simulate_job(job: tuple[np.ndarray, Curve]) -> tuple[bool, str | None, str | None, Any, Any]:
    """One curve from one configuration: ok, reason, the P-data key reached, the settled link points and
    those when the hands let go (None where rejected)."""
    global _sim
    if _sim is None:
        _sim = RopeSim()
    q, curve = job
    _sim.set_state(q)
    released: list[np.ndarray] = []

    def watch(points: np.ndarray, steps: int) -> None:
        if not released:
            released.append(points.copy())

    out = _sim.apply(curve, watch)
    if not out.ok:
        return False, out.reason, None, None, released[0] if released else None
    return True, None, _sim.p_data().key, _sim.link_points(), released[0] if released else None


def outcome(ok: bool, key: str | None, pair: dict[str, Any]) -> str:
    if not ok or key is None:
        return "rejected"
    if key == pair["next"].key:
        return "reached"
    cross = json.loads(key)
    n = len(cross) // 2
    start = pair["node"].p_data
    return "fewer" if n < start.cross else "same" if key == start.key else "other"


def draw(out_dir: Path, name: str, pair: dict[str, Any], curve: Curve, result: Any, what: str) -> Path:
    """Three panels: the start with both hands' links and the carry, the rope when the hands let go, the
    settled rope."""
    import matplotlib.pyplot as plt

    from twisted.render.draw import draw_curve, draw_knot_diagram, save_png

    node = pair["node"]
    ok, reason, key, settled, released = result
    fig, axes = plt.subplots(1, 3, figsize=(15, 5))
    c = centres(node.points)
    title = f"start: {node.p_data.key}\nasked: {pair['next'].key}"
    draw_knot_diagram(axes[0], node.points, title=title, zoom=False)
    draw_curve(axes[0], node.points, [curve.link, curve.z_max_m, curve.x_m, curve.y_m])
    sim = RopeSim()
    sim.set_state(node.q)
    path = sim._hand_paths(curve)[0]  # the active hand's path (about the held link when around)
    axes[0].plot(path[:, 0], path[:, 1], color="#2166ac", lw=1, zorder=6)
    pin = curve.pin
    assert pin is not None
    axes[0].plot(*c[pin.link], "s", color="#1b7837", ms=11, zorder=8, label=f"second hand: link {pin.link}")
    if pin.mode != "hold":
        axes[0].annotate(
            "",
            xy=(c[pin.link][0] + pin.x_m, c[pin.link][1] + pin.y_m),
            xytext=tuple(c[pin.link]),
            arrowprops={"arrowstyle": "->", "color": "#1b7837", "lw": 1.6},
        )
    kind = f"{pin.mode}" + (f", around {'+' if pin.around > 0 else '-'}" if pin.around else "")
    axes[0].legend(loc="lower left", fontsize=7, title=f"{name} ({kind})", title_fontsize=7)
    if released is not None:
        draw_knot_diagram(axes[1], released, title="when both hands let go", zoom=False)
    else:
        axes[1].axis("off")
        axes[1].set_title("rejected before the hands let go", fontsize=9)
    if ok:
        draw_knot_diagram(axes[2], settled, title=f"settled: {what}\n{key}", zoom=False)
    else:
        axes[2].axis("off")
        axes[2].set_title(f"rejected: {reason}", fontsize=8, wrap=True)
    shown = [np.asarray(p)[:, :2] for p in (node.points, released, settled) if p is not None] + [path[:, :2]]
    lo, hi = np.min([p.min(axis=0) for p in shown], axis=0), np.max([p.max(axis=0) for p in shown], axis=0)
    pad = 0.05 * float(np.max(hi - lo)) + 0.02
    for ax in axes:
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_aspect("equal")
    return save_png(fig, out_dir / f"two_hands_{name}.png", dpi=90)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--db", required=True, help="store with the eval runs")
    ap.add_argument("--set", action="append", dest="sets", required=True, help="problem set (repeatable)")
    ap.add_argument("--label", action="append", dest="labels", required=True, help="eval label (repeatable)")
    ap.add_argument("--from", type=int, action="append", dest="levels", help="crossings of the start (3, 4)")
    ap.add_argument("--pairs", type=int, default=40, help="failed pairs drawn per crossing count")
    ap.add_argument("--k", type=int, default=12, help="curves per family and pair")
    ap.add_argument("--model-id", type=int, default=None, help="model in --db (default: the shipped one)")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", help="write the figures to this file")
    ap.add_argument("--pictures", help="draw one typical outcome per two-hand family into this folder")
    args = ap.parse_args()
    if args.pairs < 1 or args.k < 1:
        ap.error("--pairs and --k must be at least 1")
    levels = args.levels or [3, 4]

    rng = np.random.default_rng(args.seed)
    curves_of = step_curves(args.db, args.model_id)

    chosen: list[dict[str, Any]] = []
    for level in levels:
        failed = [
            p
            for p in pairs_from(args.db, args.sets, args.labels, level)
            if p["reached"] == 0 and not p["move"].remove
        ]
        drawn = choose(failed, args.pairs, rng)
        print(f"from {level}: {len(failed)} failed adding pairs in the runs, {len(drawn)} drawn")
        chosen += [dict(p, level=level) for p in drawn]

    jobs: list[tuple[np.ndarray, Curve]] = []
    owner: list[tuple[int, str]] = []
    for i, pair in enumerate(chosen):
        one_hand, _ = curves_of.propose(pair["node"], pair["next"], pair["move"], args.k, rng)
        for name in FAMILIES:
            for curve in family_curves(name, rng, pair, one_hand):
                jobs.append((pair["node"].q, curve))
                owner.append((i, name))
    print(f"{len(jobs)} curves ({args.k} per family and pair) on {args.workers} worker(s)", flush=True)
    results = pool_map(simulate_job, jobs, args.workers)

    counts: dict[tuple[int, str, str], Counter[str]] = defaultdict(Counter)
    hit_pairs: dict[tuple[int, str, str], set[int]] = defaultdict(set)
    all_pairs: dict[tuple[int, str, str], set[int]] = defaultdict(set)
    examples: dict[str, list[tuple[int, Curve, Any, str]]] = defaultdict(list)
    for (i, name), (_, curve), result in zip(owner, jobs, results, strict=True):
        pair = chosen[i]
        what = outcome(result[0], result[2], pair)
        at_release = top(result[4]) if result[4] is not None else None
        for group in (move_class(pair["move"], pair["node"].p_data), f"all {pair['move'].kind}"):
            key = (pair["level"], group, name)
            counts[key][what] += 1
            if at_release is not None:  # the rope when the hands let go
                counts[key]["more at release"] += at_release.cross > pair["node"].p_data.cross
                counts[key]["next at release"] += at_release == pair["next"]
            all_pairs[key].add(i)
            if what == "reached":
                hit_pairs[key].add(i)
        if pair["level"] == max(levels) and name != "one-hand":
            examples[name].append((i, curve, result, what))

    print(f"\nfailed pairs, {args.k} curves per family and pair; seed {args.seed}")
    print("| from | move | family | pairs | curves reached (k of n) | pairs reached | x one-hand | "
          + " | ".join(OUTCOMES[1:] + RELEASE) + " |")
    print("| --- | --- | --- | --- | --- | --- | --- |" + " --- |" * (len(OUTCOMES) + len(RELEASE) - 1))
    figures = []
    for level in levels:
        groups = sorted({g for (lv, g, _) in counts if lv == level}, key=lambda g: (g.startswith("all"), g))
        for group in groups:
            base = counts.get((level, group, "one-hand"), Counter())
            base_rate = base["reached"] / max(1, sum(base[o] for o in OUTCOMES))
            for name in FAMILIES:
                c = counts.get((level, group, name))
                if not c:
                    continue
                n = sum(c[o] for o in OUTCOMES)
                rate = c["reached"] / n
                ratio = "-"
                if name != "one-hand" and (rate or base_rate):
                    ratio = f"{rate / base_rate:.1f}" if base_rate else "inf"
                shares = " | ".join(f"{c[o] / n:.0%}" for o in OUTCOMES[1:] + RELEASE)
                npairs = len(all_pairs[(level, group, name)])
                print(
                    f"| {level} | {group} | {name} | {npairs} | {c['reached']} of {n} ({rate:.2%}) | "
                    f"{len(hit_pairs[(level, group, name)])} of {npairs} | {ratio} | {shares} |"
                )
                figures.append(
                    {"from": level, "move": group, "family": name, "pairs": npairs, "curves": n,
                     "outcomes": dict(c), "pairs_reached": len(hit_pairs[(level, group, name)])}
                )
    if args.json:
        Path(args.json).write_text(json.dumps({"args": vars(args), "rows": figures}, indent=1))
    if args.pictures:
        for name, found in examples.items():
            typical = Counter(what for *_, what in found).most_common(1)[0][0]
            i, curve, result, what = next(e for e in found if e[3] == typical)
            path = draw(Path(args.pictures), name, chosen[i], curve, result, what)
            share = f"{sum(e[3] == typical for e in found)} of {len(found)}"
            print(f"{name}: a typical outcome ({typical}, {share}) drawn in {path}")


if __name__ == "__main__":
    main()
