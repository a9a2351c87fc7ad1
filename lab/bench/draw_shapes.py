"""Draw the held-out shapes: the goals (dashed) over a scattered start, and the agent's result.

    python lab/bench/draw_shapes.py --agent runs/ours-seed0/round3.npz --out docs/shapes.png

Top row: a random start scene for each shape, made as the evaluation makes them. Bottom row:
where the greedy policy of the checkpoint left the blocks (title: success or not). Without --agent
the bottom row is the shape built by hand, bottom-up.
"""
import argparse
import os

import numpy as np
from matplotlib.figure import Figure

import taskexp
from agent import Agent
from env2d import BlockWorld
from taskexp_lib import one_blas_thread, shapes
from taskexp_lib.draw import draw_scene
from taskexp_lib.geometry import is_success


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--agent", help="a checkpoint written by taskexp.py (round{k}.npz)")
    p.add_argument("--out", default=os.path.join("docs", "shapes.png"))
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()
    agent = Agent.load(a.agent) if a.agent else None
    env = BlockWorld(6, drop=agent is not None and agent.drops)
    rng = np.random.default_rng(a.seed)
    names = list(shapes.SHAPES)
    fig = Figure(figsize=(4.2 * len(names), 4.6))
    for col, name in enumerate(names):
        (s0, goals), = shapes.tasks_of(shapes.SHAPES[name], env, rng, 1)
        draw_scene(fig.add_subplot(2, len(names), col + 1), s0, goals,
                   title=f'"{name}": start and goals')
        if agent:
            t = taskexp.run_episodes(agent, [(s0, goals)], [env], rng, deterministic=True)[0]
            end, title = t.states[-1], (f"agent: {'success' if t.success else 'failure'} "
                                        f"in {len(t.actions)} steps")
        else:
            env.reset(options={"state": s0, "goals": goals})
            for b, (x, y) in sorted(goals.items(), key=lambda kv: kv[1][1]):
                env.step(env.encode_action(b, x, y))
            end = env.get_state()
            title = f"built by hand: {'success' if is_success(end, goals) else 'failure'}"
        draw_scene(fig.add_subplot(2, len(names), len(names) + col + 1), end, goals, title=title)
    fig.tight_layout()
    os.makedirs(os.path.dirname(a.out) or ".", exist_ok=True)
    fig.savefig(a.out, dpi=80)
    print("wrote", a.out)


if __name__ == "__main__":
    with one_blas_thread():
        main()
