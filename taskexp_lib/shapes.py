"""taskexp_lib/shapes.py -- the held-out shapes of sec 5 and their fixed evaluation scenes (the
2D analogues of the paper's test structures; taskexp.evaluate builds them zero-shot)."""
import numpy as np

from .geometry import BLOCK_W

# Held-out shapes: (offset from the centre in block widths, layer). None of them can occur among
# the base tasks (at most 3 goals, at most one block moved), and each has >= 4 goals with >= 3
# above the ground. Drawings are in the README.
SHAPES = {
    "I": [(0, 0), (0, 1), (0, 2), (0, 3)],                         # a tower of four
    "Y": [(-0.75, 0), (0.75, 0), (0, 1), (0, 2), (0, 3)],          # upside down: stem on two legs
    "3T": [(-1, 0), (0, 0), (1, 0), (-0.5, 1), (0.5, 1), (0, 2)],  # three tiers, 3-2-1
}


def shape_goals(name, env, rng):
    """Goals for a held-out shape at a random place, with randomly assigned blocks.

    Returns {block: (x, y)}; the shape's centre lies on the x grid so every goal is reachable.
    """
    cells = SHAPES[name]
    if len(cells) > env.n_blocks:
        raise ValueError(f"shape {name!r} needs {len(cells)} blocks, the world has {env.n_blocks}")
    reach = max(abs(dx) for dx, _ in cells) * BLOCK_W
    x = env.x_bins
    fits = (x - reach >= x[0] - 1e-9) & (x + reach <= x[-1] + 1e-9)
    cx = x[fits][rng.integers(fits.sum())]
    blocks = rng.permutation(env.n_blocks)[: len(cells)]
    return {int(b): (float(cx + dx * BLOCK_W), float(env.y_bins[k]))
            for b, (dx, k) in zip(blocks, cells)}


def start_state(env, goals, rng):
    """A random scattered scene for these goals (the env keeps goal footprints clear)."""
    env.reset(seed=int(rng.integers(2**31)), options={"goals": goals})
    return env.get_state()


def eval_tasks(cfg, env):
    """Fixed evaluation tasks per shape: the same scenes after every round (own Generator)."""
    rng = np.random.default_rng([cfg.seed, cfg.eval_salt])
    out = {}
    for name in cfg.shapes:
        out[name] = []
        for _ in range(cfg.eval_episodes):
            goals = shape_goals(name, env, rng)
            out[name].append((start_state(env, goals, rng), goals))
    return out
