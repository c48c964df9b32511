"""Wall time of one curve action on one core, from reached configurations (a random walk's, or the planner's).

    python bench/bench_curve.py --curves 200 [--timestep-s 0.005] [--seed 0]
    python bench/bench_curve.py --curves 1000 --starts 200 --dense     # the rope's sparse constraint
                                                                       # Jacobian against a dense one
    python bench/bench_curve.py --curves 1000 --db sqlite:///tune.db --dense   # the planner's curves
    python bench/bench_curve.py --curves 400 --db sqlite:///tune.db --label L --against-timestep-s 0.01

First a short random walk (not timed) collects reached configurations; then each timed curve
starts from one of them, drawn at random. Prints the median and p90 wall time per action, the mean
number of steps, the cost per step and the rejections by reason. The CPU may be shared with other
processes: compare figures from the same machine and load only.

``--db URL`` takes the curves of stored search trees instead (``twisted plan`` / ``eval`` runs): each
timed curve is the curve of a tree edge, drawn at random, from its parent's configuration, so the
starts are the planner's (knotted ropes, fewer links on the table) and so are the curves; ``--label L``
(repeatable) keeps the trees of the evaluation runs under those labels, so that other runs joining the
store later do not change the draw.

``--dense`` also applies every curve with MuJoCo's dense constraint Jacobian (``jacobian="dense"``,
the model's option before 2026-12-05) and prints its CPU time, how many curves ended in the same
outcome (both rejected, or both in the same P-data) and how far the two end configurations lie apart.
``--against-timestep-s S`` does the same with a time step of S seconds (the sparse Jacobian), and
``--against-settle-speed V`` with the rope counted at rest once every link is slower than V m/s over two
windows (``SETTLE_SPEED_M_S``, 0.01, otherwise). The steps per action are split into the carry and the
settling after the release.
"""

from __future__ import annotations

import argparse
import collections
import os
import time

import mujoco
import numpy as np

from twisted.sim import Curve, RopeSim, sample_curve
from twisted.sim.simulator import DEFAULT_TIMESTEP_S


def reached_configurations(sim: RopeSim, rng: np.random.Generator, n: int) -> list[np.ndarray]:
    """``n`` configurations reached by random curves from the straight rope (and from each other)."""
    sim.reset()
    reached = [sim.state()]
    while len(reached) < n:
        sim.set_state(reached[int(rng.integers(len(reached)))])
        if sim.apply(sample_curve(rng)).ok:
            reached.append(sim.state())
    return reached


def tree_edges(
    url: str, rng: np.random.Generator, n: int, labels: list[str] | None = None
) -> list[tuple[np.ndarray, Curve]]:
    """``n`` (parent configuration, curve) pairs drawn from the curve edges of the stored search trees (of
    the evaluation runs under ``labels`` only, when given)."""
    from sqlalchemy import select
    from sqlalchemy.orm import aliased

    from twisted.store import blob_to_array, open_store
    from twisted.store.experiments import EvalResult
    from twisted.store.search_tree import SearchNode

    parent = aliased(SearchNode)
    query = (
        select(parent.q, SearchNode.link, SearchNode.z_max_m, SearchNode.x_m, SearchNode.y_m)
        .join(parent, SearchNode.parent_id == parent.id)
        .where(SearchNode.link.is_not(None))
    )
    if labels:
        runs = select(EvalResult.plan_run_id).where(EvalResult.planner.in_(labels))
        query = query.where(SearchNode.run_id.in_(runs))
    query = query.order_by(SearchNode.id)  # the draw depends on the order: make it the store's
    with open_store(url, readonly=True) as store, store.session() as session:
        rows = session.execute(query).all()
    if len(rows) < n:
        raise SystemExit(f"{url}: {len(rows)} tree edges with a curve, fewer than --curves {n}")
    picked = rng.choice(len(rows), size=n, replace=False)
    return [
        (blob_to_array(rows[i].q), Curve(rows[i].link, rows[i].z_max_m, rows[i].x_m, rows[i].y_m))
        for i in picked
    ]


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--curves", type=int, default=200, help="timed curve actions")
    parser.add_argument("--starts", type=int, default=50, help="reached configurations to start from")
    parser.add_argument("--timestep-s", type=float, default=DEFAULT_TIMESTEP_S)
    parser.add_argument("--friction-scale", type=float, default=1.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--dense", action="store_true", help="also with a dense constraint Jacobian")
    parser.add_argument("--against-timestep-s", type=float, help="also with this time step (s)")
    parser.add_argument("--against-settle-speed", type=float, help="also with this settle speed (m/s)")
    parser.add_argument("--db", help="draw (start, curve) pairs from the edges of this store's search trees")
    parser.add_argument(
        "--label",
        action="append",
        dest="labels",
        help="with --db: only the trees of these eval labels (repeatable)",
    )
    args = parser.parse_args()

    rng = np.random.default_rng(args.seed)
    sim = RopeSim(args.friction_scale, args.timestep_s)
    jobs = tree_edges(args.db, rng, args.curves, args.labels) if args.db else None
    starts = reached_configurations(sim, rng, args.starts) if jobs is None else []
    against = [args.dense, args.against_timestep_s is not None, args.against_settle_speed is not None]
    if sum(against) > 1:
        parser.error("--dense, --against-timestep-s and --against-settle-speed compare one thing at a time")
    for flag, value in (("timestep-s", args.against_timestep_s), ("settle-speed", args.against_settle_speed)):
        if value is not None and not value > 0:
            parser.error(f"--against-{flag} must be positive, got {value}")
    other = None  # the simulator the curves are compared against
    if any(against):
        other = RopeSim(args.friction_scale, args.against_timestep_s or args.timestep_s)
    if args.dense and other is not None:
        other.model.opt.jacobian = int(mujoco.mjtJacobian.mjJAC_DENSE)
    if args.against_settle_speed is not None and other is not None:
        other.settle_speed_m_s = args.against_settle_speed
    wall, cpu, steps, settle, other_cpu, other_settle, apart = [], [], [], [], [], [], []
    same = 0
    rejected: collections.Counter[str] = collections.Counter()
    for i in range(args.curves):
        if jobs is None:
            start, curve = starts[int(rng.integers(len(starts)))], sample_curve(rng)
        else:
            start, curve = jobs[i]
        sim.set_state(start)
        w0, c0 = time.perf_counter(), time.thread_time()
        outcome = sim.apply(curve)
        cpu.append(time.thread_time() - c0)
        wall.append(time.perf_counter() - w0)
        steps.append(outcome.steps)
        settle.append(outcome.settle_steps)
        if not outcome.ok:
            rejected[(outcome.reason or "?").split(" (")[0]] += 1
        if other is not None:
            other.set_state(start)
            c0 = time.thread_time()
            compared = other.apply(curve)
            other_cpu.append(time.thread_time() - c0)
            other_settle.append(compared.settle_steps)
            same += outcome.ok == compared.ok and (not outcome.ok or sim.p_data() == other.p_data())
            apart.append(float(np.abs(sim.state() - other.state()).max()))
    w, c = np.array(wall), np.array(cpu)
    print(
        f"curve action, dt = {args.timestep_s * 1000:g} ms, {args.curves} curves from "
        + (f"{args.starts} reached configurations" if jobs is None else f"the search trees of {args.db}")
        + f", seed {args.seed}, load average {os.getloadavg()[0]:.2f} "
        f"on {os.cpu_count()} cores"
    )
    for name, t in (("wall", w), ("cpu ", c)):
        print(
            f"  {name} per action: median {np.median(t):.4f} s, p90 {np.quantile(t, 0.9):.4f} s, "
            f"mean {t.mean():.4f} s (reference 0.8 s, target <= 0.1 s)"
        )
    print(
        f"  steps per action: mean {np.mean(steps):.0f} (carry {np.mean(steps) - np.mean(settle):.0f}, "
        f"settling {np.mean(settle):.0f}), median {np.median(steps):.0f}; "
        f"{c.sum() / max(1, sum(steps)) * 1e6:.1f} us cpu per step"
    )
    print(
        f"  rejected: {sum(rejected.values())} of {args.curves}"
        + "".join(f"\n    {n:4d}  {reason}" for reason, n in rejected.most_common())
    )
    if other is not None:
        d, gap = np.array(other_cpu), np.array(apart)
        other_dt = other.model.opt.timestep * 1000
        name, base = ("dense Jacobian", "sparse one's") if args.dense else (f"dt = {other_dt:g} ms", "first")
        if args.against_settle_speed is not None:
            speed, settled = args.against_settle_speed, np.mean(other_settle)
            name = f"at rest under {speed:g} m/s ({settled:.0f} settling steps)"
        print(
            f"  {name}: cpu per action median {np.median(d):.4f} s, mean {d.mean():.4f} s "
            f"({d.sum() / c.sum():.2f}x the {base}); the same outcome in {same} of {args.curves}; "
            f"end configurations apart by median {np.median(gap):.1e}, max {gap.max():.1e} (qpos, qvel)"
        )


if __name__ == "__main__":
    main()
