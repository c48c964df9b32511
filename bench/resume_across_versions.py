"""Runs stored by one version of the planner, resumed by another: the same tree as one uninterrupted run?

    git archive 7aaa230 | tar -x -C /tmp/old                                     # the old code
    PYTHONPATH=/tmp/old python bench/resume_across_versions.py old sqlite:////tmp/x.db /tmp/x.ids
    python bench/resume_across_versions.py new sqlite:////tmp/x.db /tmp/x.ids      # this checkout

Phase ``old`` (run with the old code) stores, per case, a whole run of 12 iterations and a run stopped
at 6; phase ``new`` resumes the stopped one to 12 with this code and compares its tree (every node's
parent, state, curve, iteration, simulator call) and statistics with the old code's whole run.
"""

import json
import sys

from twisted.goals import make_goal
from twisted.planner import PlannerOptions, curve_sampler, resume_search, start_search
from twisted.sim.pool import SimPool
from twisted.store import open_store
from twisted.store.search import load_run

if len(sys.argv) != 4 or sys.argv[1] not in ("old", "new"):
    sys.exit("usage: resume_across_versions.py old|new DB_URL IDS_FILE (see the docstring)")
phase, db, ids_file = sys.argv[1], sys.argv[2], sys.argv[3]
THREE = '[[1,"O",4,"+"],[2,"U",5,"+"],[3,"O",6,"+"],[4,"U",1,"+"],[5,"O",2,"+"],[6,"U",3,"+"]]'
TWO = '[[1,"O",4,"+"],[2,"O",3,"+"],[3,"U",2,"+"],[4,"U",1,"+"]]'
cases = [
    (TWO, {"seed": 3}),
    (THREE, {"seed": 2, "heuristic": "rnd"}),
    (THREE, {"seed": 4, "planner": "random-low", "p_expand": 0.3, "k_expand": 6}),
]


def sig(store: object, run_id: int) -> tuple[list[tuple], dict]:
    info = load_run(store, run_id)
    return [
        (n.seq, n.parent_seq, n.p_data.key, n.curve, n.iteration, n.sim_call) for n in info.nodes
    ], info.checkpoint.stats


differ = 0
with open_store(db) as store, SimPool(1) as pool:
    out = {}
    for i, (goal, opts) in enumerate(cases):
        options = PlannerOptions(**opts)
        sampler, _ = curve_sampler(store, options.planner)
        if phase == "old":
            whole = start_search(store, make_goal(goal), options, pool, sampler)
            whole.run(max_iterations=12)
            half = start_search(store, make_goal(goal), options, pool, sampler)
            half.run(max_iterations=6)
            out[i] = (whole.run_id, half.run_id)
        else:
            ids = json.load(open(ids_file))[str(i)]
            resumed = resume_search(store, ids[1], pool, sampler)
            r = resumed.run(max_iterations=12)
            a, b = sig(store, ids[0]), sig(store, ids[1])
            same = a == b
            differ += not same
            print(
                f"case {i}: old whole run {len(a[0])} nodes, old half + new resume {len(b[0])} nodes, ",
                end="",
            )
            print(f"same tree and statistics: {same}; {r.sim_calls} simulator calls")
    if phase == "old":
        json.dump(out, open(ids_file, "w"))
sys.exit(1 if differ else 0)
