"""Which greedy action does the evaluation take? A run's checkpoints tried with both rules of
Config.greedy, on every test the run makes after a round, in seconds (no training).

    python lab/bench/greedy.py runs/ours-seed0/round3.npz
    python lab/bench/greedy.py "runs/ours-seed[0-4]/round3.npz" --salt 777 --json greedy.json

The policy is factorised, pi(b, x) = pi(b) pi(x | b) (agent.ActionDist). Its greedy action can be
the most likely pair (b, x) ("joint", ActionDist.mode: the block that maximises log pi(b) +
max_x log pi(x | b)), or the most likely block and then its most likely x ("block",
ActionDist.block_mode: each head's argmax, as the authors' code takes it). They differ where the
most likely block has a spread destination: a block that stands on another block's goal spot may
go anywhere out of the way, so its best x is unlikely, and the joint rule moves a goal block
with a sure x instead, onto the block that should have left (lab/notes.md, 2026-12-07).

For each checkpoint it prints, per rule, the success on the held-out shapes, the families
(shapes.FAMILIES) and the worlds of other block counts (Config.eval_blocks), on the scenes the run
itself is tried on (its results.json beside the checkpoint gives the settings), or on other
scenes of the same kinds with --salt (Config.eval_salt): scenes no one has looked at.
"""
import json
import os
import sys
from dataclasses import replace

import numpy as np

sys.path.insert(0, os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
from build_order import checkpoint_parser, expand, run_settings  # noqa: E402

import taskexp  # noqa: E402
from agent import GREEDY, Agent  # noqa: E402
from env2d import physics_pool, run_worlds  # noqa: E402
from taskexp_lib import one_blas_thread  # noqa: E402
from taskexp_lib.config import saved_config  # noqa: E402


def run_config(checkpoint, seed=0):
    """The settings of the run a checkpoint belongs to (its results.json), else the defaults
    with `seed` for the checkpoint's world."""
    settings = run_settings(checkpoint)
    return saved_config(settings) if settings else taskexp.Config(seed=seed)


def measure(checkpoint, seed=0, episodes=100, salt=None, workers=1):
    """-> {rule: zero_shot's {"eval": {shape: rate}, "families": {...}, "blocks": {...}}} for one
    checkpoint, each rule of GREEDY on the same scenes; the physics in `workers` processes."""
    agent = Agent.load(checkpoint)
    cfg = replace(run_config(checkpoint, seed), eval_episodes=episodes, n_blocks=agent.n_blocks)
    if salt is not None:
        cfg = replace(cfg, eval_salt=salt)
    out = {}
    with physics_pool(workers, cfg.action == "drop") as pool:
        envs, _ = run_worlds(cfg, pool)
        tests = taskexp.zero_shot_tests(cfg, envs, pool)
        for rule in GREEDY:
            agent.greedy = rule
            out[rule] = taskexp.zero_shot(agent, tests)
    return out


def summary(r):
    """One rule's figures as the columns of the table: [(name, text)]."""
    pc = lambda rates: f"{100 * np.mean(list(rates.values())):3.0f}%"
    cols = [("I/Y/3T", pc(r["eval"]))]
    for family, tasks in r["families"].items():
        low = min(tasks, key=tasks.get)
        cols.append((family, f"{pc(tasks)} (lowest {low} {100 * tasks[low]:.0f}%)"))
    cols += [(f"{n} blocks", pc(shapes)) for n, shapes in r["blocks"].items()]
    return cols


def main():
    p = checkpoint_parser(__doc__.split("\n")[0], greedy=False)     # both rules, always
    p.add_argument("--salt", type=int, help="other evaluation scenes: this Config.eval_salt")
    p.add_argument("--json", help="also write the figures to this file")
    p.add_argument("--workers", type=int, default=1, help="processes for the physics")
    a = p.parse_args()
    found = {}
    for path in expand(a.checkpoints):
        found[path] = by_rule = measure(path, a.seed, a.episodes, a.salt, a.workers)
        print(path)
        for rule, r in by_rule.items():
            print(f"  {rule:6s} " + "  ".join(f"{name} {text}" for name, text in summary(r)))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(found, f, indent=1)


if __name__ == "__main__":
    with one_blas_thread():
        main()
