"""Does the policy build supports first? The leading indicator of the actor, in seconds.

    python lab/bench/build_order.py runs/ours-seed0/round1.npz
    python lab/bench/build_order.py runs/ours-seed0/round*.npz      # one table row per checkpoint
    python lab/bench/build_order.py runs/ours-seed0/round1.npz --json order.json --plot order.png

Runs each checkpoint's greedy policy on the evaluation scenes of the held-out shapes (the run's
own: the seed comes from the run's results.json beside the checkpoint, else --seed; the greedy
rule from --greedy, else the run's own) and sorts its moves as report.move_kind does: "right"
moves a block of the lowest layer whose goals are not met yet to its goal's x; "higher goal"
moves a block whose goal lies above a pending one, before its support stands. Prints, per shape,
  - the first move of the episodes, by kind;
  - the first move of each episode that is wrong, by kind, and the mean step it came at: not
    "right", and not a higher goal put on its support ("all right": none, the episode built the
    shape in an order physics allows, or ran out of steps);
  - the zero-shot success.
The first moves of a round-1 checkpoint say within seconds whether the data of the run teach the
order supports need, before any 3-seed run is paid for.
"""
import argparse
import glob
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
import taskexp  # noqa: E402
from agent import GREEDY, Agent  # noqa: E402
from env2d import run_worlds  # noqa: E402
from taskexp_lib import one_blas_thread  # noqa: E402
from taskexp_lib.geometry import is_success  # noqa: E402
from taskexp_lib.rollout import replay, run_episodes  # noqa: E402
from taskexp_lib.shapes import eval_tasks  # noqa: E402
from taskexp_lib.stats import MOVE_KINDS, move_kind  # noqa: E402

FIRST_WRONG = MOVE_KINDS[1:] + ("all right",)    # "higher goal" there: before its support


def run_settings(checkpoint):
    """The saved settings of the run the checkpoint belongs to (its results.json beside it), as
    a dict; {} when there is none."""
    path = os.path.join(os.path.dirname(os.path.abspath(checkpoint)), "results.json")
    if not os.path.exists(path):
        return {}
    with open(path) as f:
        return json.load(f)["config"]


def run_seed(checkpoint, default):
    """The seed of the run the checkpoint belongs to (its results.json), else `default`."""
    return run_settings(checkpoint).get("seed", default)


def greedy_rule(checkpoint, given=None):
    """The rule of the greedy action (Config.greedy) to try a checkpoint with: `given`, else the
    run's own (its results.json), else the joint mode. A checkpoint does not carry it."""
    return given or run_settings(checkpoint).get("greedy", "joint")


def first_wrong(traj):
    """(kind, step) of the first move of the episode that is neither "right" nor a higher goal
    that came to rest at its goal (its support complete under it, as when a tier of "3T" stands
    before the row below is done), counting from 1; ("all right", None) when there is none."""
    for t, (s, a) in enumerate(zip(traj.states, traj.actions)):
        kind, b = move_kind(s, traj.goals, a), int(a[0])
        if kind == "higher goal" and is_success(traj.states[t + 1], {b: traj.goals[b]}):
            continue
        if kind not in ("right", None):
            return kind, t + 1
    return "all right", None


def measure(checkpoint, seed=0, episodes=100, greedy=None):
    """The indicator for one checkpoint -> {shape: {first_move: {kind: share}, first_wrong:
    {kind: share}, first_wrong_step: mean step, success: share}}."""
    agent = Agent.load(checkpoint)
    agent.greedy = greedy_rule(checkpoint, greedy)
    cfg = taskexp.Config(seed=run_seed(checkpoint, seed), eval_episodes=episodes,
                         action="drop" if agent.drops else "place")
    envs, _ = run_worlds(cfg)
    out = {}
    for shape, tasks in eval_tasks(cfg, envs[0]).items():
        trajs = run_episodes(agent, tasks, envs, deterministic=True)
        firsts = [move_kind(t.states[0], t.goals, t.actions[0]) for t in trajs]
        wrong = [first_wrong(t) for t in trajs]
        share = lambda kinds, of: {k: of.count(k) / len(of) for k in kinds}
        steps = [step for _, step in wrong if step is not None]
        out[shape] = dict(first_move=share(MOVE_KINDS, firsts),
                          first_wrong=share(FIRST_WRONG, [kind for kind, _ in wrong]),
                          first_wrong_step=float(np.mean(steps)) if steps else None,
                          success=float(np.mean([t.success for t in trajs])))
    return out


def chance(cfg, orders=10, seed=0):
    """Each shape's chance level: the base skill done perfectly in a random order. Every goal block
    is dropped at its goal's x once, in one of `orders` random orders per evaluation scene of
    cfg, played in the world -> {shape: success rate}. Only the orders that build every support
    before what it carries succeed: 1 in 24 for a tower of four ("I")."""
    rng = np.random.default_rng(seed)
    envs, _ = run_worlds(cfg)
    out = {}
    for shape, tasks in eval_tasks(cfg, envs[0]).items():
        tried = [task for task in tasks for _ in range(orders)]
        plans = [[envs[0].encode_action(b, goals[b][0], envs[0].y_bins[0])
                  for b in rng.permutation(list(goals))] for _, goals in tried]
        played = replay(tried, plans, envs)
        out[shape] = float(np.mean([t.success for t in played]))
    return out


def plot(by_checkpoint, path):
    """One panel per shape: the share of first moves that are right, and that move a higher goal,
    for each checkpoint (the x axis, in the order given)."""
    from matplotlib.figure import Figure
    shapes = list(next(iter(by_checkpoint.values())))
    fig = Figure(figsize=(3.2 * len(shapes), 3.0))
    names = [os.path.relpath(c) for c in by_checkpoint]
    for i, shape in enumerate(shapes):
        ax = fig.add_subplot(1, len(shapes), i + 1)
        for kind, style in (("right", "o-"), ("higher goal", "s--")):
            ax.plot(range(len(names)), [100 * m[shape]["first_move"][kind]
                                        for m in by_checkpoint.values()], style, label=kind)
        ax.set_xticks(range(len(names)), [os.path.basename(n) for n in names], rotation=30,
                      fontsize=8)
        ax.set_ylim(-5, 105)
        ax.set_title(f'"{shape}": first move')
        ax.set_ylabel("% of the scenes" if i == 0 else "")
    fig.axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def checkpoint_parser(description, nargs="+", greedy=True):
    """The command line of a script that measures checkpoints on a run's evaluation scenes
    (greedy: and runs their greedy policy, by the rule --greedy names)."""
    p = argparse.ArgumentParser(description=description)
    p.add_argument("checkpoints", nargs=nargs, help="round{k}.npz files (a glob is expanded)")
    p.add_argument("--episodes", type=int, default=100, help="evaluation scenes per task")
    p.add_argument("--seed", type=int, default=0,
                   help="the evaluation scenes' seed when no results.json lies beside a checkpoint")
    if greedy:
        p.add_argument("--greedy", choices=GREEDY,
                       help="the greedy action's rule (Config.greedy); default: the run's own")
    return p


def expand(checkpoints):
    """The checkpoints named, each glob expanded, in order."""
    return [f for c in checkpoints for f in (sorted(glob.glob(c)) or [c])]


def main():
    p = checkpoint_parser(__doc__.split("\n")[0])
    p.add_argument("--json", help="also write the figures to this file")
    p.add_argument("--plot", help="draw the first moves per checkpoint into this PNG")
    a = p.parse_args()
    paths = expand(a.checkpoints)
    by_checkpoint = {}
    for path in paths:
        m = by_checkpoint[path] = measure(path, a.seed, a.episodes, a.greedy)
        pc = lambda share: f"{100 * share:3.0f}%"
        print(f"{path}")
        print("  shape  success  first move: " + " / ".join(MOVE_KINDS))
        for shape, r in m.items():
            print(f"  {shape:5s}  {pc(r['success'])}     "
                  + " / ".join(pc(r["first_move"][k]) for k in MOVE_KINDS))
        print("  shape  first wrong move: " + " / ".join(FIRST_WRONG) + "  (mean step)")
        for shape, r in m.items():
            step = r["first_wrong_step"]
            print(f"  {shape:5s}  " + " / ".join(pc(r["first_wrong"][k]) for k in FIRST_WRONG)
                  + (f"  ({step:.1f})" if step is not None else ""))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(by_checkpoint, f, indent=1)
    if a.plot:
        plot(by_checkpoint, a.plot)
        print("wrote", a.plot)


if __name__ == "__main__":
    with one_blas_thread():
        main()
