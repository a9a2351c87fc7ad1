"""The held-out shapes in worlds of more blocks, scene by scene: where a crowded table left the
shape's site free, and where it did not, with the weights a run learnt in its own world.

    python lab/bench/more_blocks.py runs/ours-seed0                    # its last round, 6-8 blocks
    python lab/bench/more_blocks.py runs/ours-seed0 --round 1 --blocks 7
    python lab/bench/more_blocks.py runs/ours-seed0 --record   # a run made before eval_blocks

--record tries every round's checkpoint of a run made before Config.eval_blocks in those worlds,
as taskexp.train does after every round, and writes the figures into its results.json.

The scenes are the run's own (those taskexp.train tries after every round, shapes.eval_tasks),
so "success" matches results.json; the split by shapes.site_free says whether a shortfall is the
policy's or the table's: it never moves a block that no goal names out of the way.
"""
import argparse
import json
import os
import warnings

import numpy as np

import taskexp
from agent import GREEDY, Agent, OtherWorldWarning
from env2d import physics_pool
from taskexp_lib import one_blas_thread
from taskexp_lib.checkpoint import save_json
from taskexp_lib.config import saved_config
from taskexp_lib.rollout import run_episodes
from taskexp_lib.shapes import site_free


def split_by_site(agent, tasks, worlds):
    """{shape: (success, site free, success where free, success where not)} as "%" texts."""
    out = {}
    for shape, scenes in tasks.items():
        won = np.array([t.success for t in run_episodes(agent, scenes, worlds,
                                                        deterministic=True, values=False)])
        free = np.array([site_free(s0, goals) for s0, goals in scenes])
        rate = lambda m: f"{100 * won[m].mean():.0f}%" if m.any() else "-"     # no such scene
        out[shape] = (f"{100 * won.mean():.0f}%", f"{100 * free.mean():.0f}%", rate(free),
                      rate(~free))
    return out


def record(run, workers=2):
    """Each round's success in the worlds of cfg.eval_blocks, into the run's results.json, where
    and as taskexp.train records it (rounds[k]["blocks"], after "families")."""
    path = os.path.join(run, "results.json")
    with open(path) as f:
        results = json.load(f)
    cfg = saved_config(results["config"])              # a run made before: Config's eval_blocks
    with physics_pool(workers, cfg.action == "drop") as pool:
        tests = {str(n): taskexp.shapes_in_world(cfg, n, pool)               # once, every round
                 for n in cfg.eval_blocks}
        for k, rnd in enumerate(results["rounds"]):
            agent = Agent.load(os.path.join(run, f"round{k}.npz"))
            agent.greedy = cfg.greedy                   # the run's rule, as train tries it
            blocks = taskexp.zero_shot(agent, tests)
            first = {key: rnd.pop(key) for key in ("round", "eval", "families") if key in rnd}
            results["rounds"][k] = {**first, "blocks": blocks, **rnd}
            print(f"round {k}: " + "; ".join(f"{n} blocks " + ", ".join(
                f"{s} {v:.0%}" for s, v in rates.items()) for n, rates in blocks.items()))
    results["config"]["eval_blocks"] = list(cfg.eval_blocks)
    save_json(path, results)
    print("wrote", path)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("run", help="a run directory (results.json, round{k}.npz)")
    p.add_argument("--round", type=int, default=None, help="default: the run's last")
    p.add_argument("--blocks", type=int, nargs="+", default=None,
                   help="block counts (default: the run's own and its eval_blocks)")
    p.add_argument("--record", action="store_true",
                   help="write every round's figures in cfg.eval_blocks into results.json")
    p.add_argument("--greedy", choices=GREEDY,
                   help="the greedy action's rule (Config.greedy); default: the run's own")
    a = p.parse_args()
    if a.record:
        return record(a.run)
    with open(os.path.join(a.run, "results.json")) as f:
        results = json.load(f)
    cfg = saved_config(results["config"])
    k = results["rounds"][-1]["round"] if a.round is None else a.round
    agent = Agent.load(os.path.join(a.run, f"round{k}.npz"))
    agent.greedy = a.greedy or cfg.greedy
    counts = a.blocks or [cfg.n_blocks, *cfg.eval_blocks]
    print(f"{a.run} round {k}, the weights learnt with {cfg.n_blocks} blocks")
    print("| blocks | shape | success | site free | success where free | where not |")
    print("|---|---|---|---|---|---|")
    warnings.simplefilter("ignore", OtherWorldWarning)            # the table says so
    for n in counts:                                # the run's own world the same way
        tasks, worlds = taskexp.shapes_in_world(cfg, n)
        for shape, (won, free, on_free, on_busy) in split_by_site(agent, tasks, worlds).items():
            print(f"| {n} | {shape} | {won} | {free} | {on_free} | {on_busy} |")


if __name__ == "__main__":
    with one_blas_thread():
        main()
