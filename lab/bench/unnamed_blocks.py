"""Does the policy move blocks that no goal names? The leading indicator of the families, in
seconds.

    python lab/bench/unnamed_blocks.py runs/ours-seed0/round1.npz
    python lab/bench/unnamed_blocks.py runs/ours-seed0/round*.npz --episodes 40
    python lab/bench/unnamed_blocks.py --data runs/ours-seed0/state.npz

A blocked site and a goal in the air (taskexp_lib/shapes.py, FAMILIES) are solved only by moving a
block that no goal names: away from the site, or under the goal. For each checkpoint it runs the
greedy policy on the run's own family scenes (the seed from the run's results.json beside it,
else --seed; the greedy rule --greedy, else the run's own) and prints, per task, the zero-shot
success and the share of first moves, and of all moves, that move a block no goal names; for
the blocked family also where the policy would send the blocker at the start (the mass of its
x-head a block width or more from the site, and how often its most likely x is there): a block
picked to clear the site and sent back onto it clears nothing; for the air family how often a
support is undone (supports_undone). With --data it reads a run's state.npz and prints the share
of the BC buffer's steps that do (the data must show such moves before a policy makes them).
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
from build_order import checkpoint_parser, expand, greedy_rule, run_seed  # noqa: E402

import taskexp  # noqa: E402
from agent import Agent  # noqa: E402
from env2d import run_worlds  # noqa: E402
from taskexp_lib import one_blas_thread  # noqa: E402
from taskexp_lib.checkpoint import load_npz  # noqa: E402
from taskexp_lib.geometry import BLOCK_H, BLOCK_W, observation  # noqa: E402
from taskexp_lib.rollout import run_episodes  # noqa: E402
from taskexp_lib.shapes import FAMILIES, family_tasks  # noqa: E402


def blocker_sent_off(agent, tasks, x_bins):
    """For blocked scenes [(s0, goals)]: the blocker's x-head at s0 -> (its mean mass on the x-bins
    a block width or more from the site, the share of scenes whose most likely x is among them).
    The blocker is the block no goal names that stands on a ground goal's spot
    (shapes.blocked_state sets it down there)."""
    mass, best = [], []
    for s0, goals in tasks:
        sites = [x for x, y in goals.values() if y < BLOCK_H]
        b = next(i for i in range(len(s0)) if i not in goals and s0[i, 1] < BLOCK_H
                 and min(abs(s0[i, 0] - x) for x in sites) < 1e-6)
        p_x = np.exp(agent.policy(agent.features(observation(s0, goals)[None])).lx[0, b])
        off = np.abs(np.asarray(x_bins) - s0[b, 0]) >= BLOCK_W
        mass.append(p_x[off].sum())
        best.append(off[p_x.argmax()])
    return float(np.mean(mass)), float(np.mean(best))


def supports_undone(trajs):
    """The share of the episodes `trajs` in which a move takes a block that no goal names from
    right under a goal (its centre within half a block width of the goal's x) and it comes to
    rest right under a goal again: a support moved within its column, which builds nothing (a
    block pulled from under a stack lands on top of it)."""
    undone = []
    for t in trajs:
        xs = [x for x, _ in t.goals.values()]
        under = lambda state, b: min(abs(state[b, 0] - x) for x in xs) < BLOCK_W / 2
        undone.append(any(b not in t.goals and under(t.states[i], b) and under(t.states[i + 1], b)
                          for i, b in enumerate(int(a[0]) for a in t.actions)))
    return float(np.mean(undone))


def measure(checkpoint, seed=0, episodes=100, greedy=None):
    """-> {family: {task: {success, first_unnamed, unnamed[, x_off_site, best_x_off_site]
    [, supports_undone]}}} for one checkpoint (x_off_site and best_x_off_site for the blocked
    family: blocker_sent_off; supports_undone for the air family)."""
    agent = Agent.load(checkpoint)
    agent.greedy = greedy_rule(checkpoint, greedy)
    cfg = taskexp.Config(seed=run_seed(checkpoint, seed), eval_episodes=episodes,
                         families=tuple(FAMILIES), n_blocks=agent.n_blocks)
    envs, _ = run_worlds(cfg)
    out = {}
    for family, tasks_by_name in family_tasks(cfg, envs[0]).items():
        out[family] = {}
        for name, tasks in tasks_by_name.items():
            trajs = run_episodes(agent, tasks, envs, deterministic=True)
            unnamed = [[int(a[0]) not in t.goals for a in t.actions] for t in trajs]
            out[family][name] = dict(
                success=float(np.mean([t.success for t in trajs])),
                first_unnamed=float(np.mean([u[0] for u in unnamed])),
                unnamed=float(np.mean([x for u in unnamed for x in u])))
            if family == "blocked":
                off = blocker_sent_off(agent, tasks, envs[0].x_bins)
                out[family][name].update(x_off_site=off[0], best_x_off_site=off[1])
            if family == "air":
                out[family][name].update(supports_undone=supports_undone(trajs))
    return out


def buffer_share(state_path):
    """The share of the BC buffer's steps in a run's state.npz that move a block no goal names
    (the observation's has_goal column is 0 for the moved block) -> (share, steps)."""
    data = load_npz(state_path)
    obs, act = data["buffer_obs"], data["buffer_act"]
    has_goal = obs[np.arange(len(act)), act[:, 0].astype(int), 5] > 0.5
    return float(1 - has_goal.mean()), len(act)


def main():
    p = checkpoint_parser(__doc__.split("\n")[0], nargs="*")
    p.add_argument("--data", nargs="*", default=[], help="state.npz files: the BC buffer's share")
    a = p.parse_args()
    if not a.checkpoints and not a.data:
        p.error("name a checkpoint or --data state.npz")
    for path in a.data:
        share, steps = buffer_share(path)
        print(f"{path}: {100 * share:.2f}% of {steps} buffer steps move a block no goal names")
    pc = lambda share: f"{100 * share:4.0f}%"
    for path in expand(a.checkpoints):
        print(path)
        print("  family   task        success  first move unnamed  all moves unnamed  "
              "blocker's x off its site: mass / most likely, or supports undone")
        for family, tasks in measure(path, a.seed, a.episodes, a.greedy).items():
            for name, r in tasks.items():
                off = (f"       {pc(r['x_off_site'])} / {pc(r['best_x_off_site'])}"
                       if "x_off_site" in r else
                       f"       {pc(r['supports_undone'])}" if "supports_undone" in r else "")
                print(f"  {family:8s} {name:10s}  {pc(r['success'])}    {pc(r['first_unnamed'])}"
                      f"               {pc(r['unnamed'])}{off}")


if __name__ == "__main__":
    with one_blas_thread():
        main()
