"""How many labelled outcomes does a later round's critic need? One labelling budget, measured.

    python taskexp.py --rounds 1 --out runs/round1                 # once: the state after round 1
    python lab/bench/label_budget.py runs/round1 --tasks 1000 --epochs 6
    python lab/bench/label_budget.py runs/round1 --tasks 0             # no labelling before round 2

Loads the run's resume state (state.npz, after its last round), labels outcomes of the tasks the
next expansion starts from as expansion_round does (taskexp_lib/labels.py, with --tasks tasks and
--epochs epochs in place of label_later_tasks and label_later_epochs), then runs a task expansion
of --attempts attempts and prints the labelling's wall time and the share of equation (1)'s picks
that verification reaches (the leading indicator of selection). Every budget starts from the
same state and seed, so budgets compare on the same tasks.
"""
import argparse
import os
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
import taskexp  # noqa: E402
from env2d import physics_pool, run_worlds  # noqa: E402
from taskexp_lib import one_blas_thread  # noqa: E402
from taskexp_lib.checkpoint import load_state, saved_results  # noqa: E402
from taskexp_lib.config import saved_config  # noqa: E402
from taskexp_lib.labels import labelled  # noqa: E402
from taskexp_lib.shards import SHARDS  # noqa: E402


def load(run_dir):
    """A run's settings, agent and RunState fields -> (cfg, agent, run); ValueError or OSError
    naming what is wrong when the run cannot be read."""
    results, why = saved_results(run_dir)
    if results is None:
        raise ValueError(why)
    cfg = saved_config(results["config"])
    agent, run = load_state(os.path.join(run_dir, "state.npz"), cfg, np.random.default_rng(),
                            taskexp.make_agent(cfg))
    return cfg, agent, run


def measure(loaded, tasks, epochs, attempts=1000, seed=1, workers=2, log=print):
    """Label with this budget the run `loaded` (load's triple), then expand -> dict with label_s,
    picks_reached and the counts."""
    cfg, agent, run = loaded
    agent.threads = min(workers, SHARDS)
    rng, cfg = np.random.default_rng(seed), replace(cfg, expand_episodes=attempts)
    with one_blas_thread(), physics_pool(workers, cfg.n_blocks, cfg.action == "drop") as pool:
        envs, short = run_worlds(cfg, pool)
        start = time.time()
        if tasks:
            labelled(agent, run["prev_tasks"], cfg, envs, short, rng, taskexp.Pieces(),
                     taskexp.candidates, taskexp.silent, log, tasks, epochs)
        label_s = time.time() - start
        _, info = taskexp.task_expansion(agent, run["prev_tasks"], cfg, envs, short, rng)
    return dict(tasks=tasks, epochs=epochs, label_s=round(label_s, 1), **info)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("run", help="a run's directory (results.json and state.npz)")
    p.add_argument("--tasks", type=int, default=taskexp.Config.label_later_tasks)
    p.add_argument("--epochs", type=int, default=taskexp.Config.label_later_epochs)
    p.add_argument("--attempts", type=int, default=1000, help="task expansion attempts")
    p.add_argument("--seed", type=int, default=1)
    a = p.parse_args()
    if a.tasks < 0 or a.epochs < 1 or a.attempts < 1:
        p.error("--tasks must be >= 0, --epochs and --attempts >= 1")
    if not os.path.isfile(os.path.join(a.run, "state.npz")):
        p.error(f"{a.run} holds no state.npz: make a run there first (taskexp.py --out {a.run})")
    try:
        loaded = load(a.run)
    except (OSError, ValueError) as e:                 # unreadable, or other settings
        p.error(f"{a.run}: cannot load this run ({type(e).__name__}: {e})")
    m = measure(loaded, a.tasks, a.epochs, a.attempts, a.seed)
    print(f"{a.run}: {a.tasks} tasks labelled, {a.epochs} epochs: {m['label_s']:.0f} s; "
          f"{m['picks_reached']:.0%} of {m['successful']} picks reached")


if __name__ == "__main__":
    main()
