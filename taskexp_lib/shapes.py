"""taskexp_lib/shapes.py -- the held-out shapes of sec 5 and their fixed evaluation scenes (the
2D analogues of the paper's test structures; taskexp.evaluate builds them zero-shot), and two
families of tasks beside them in which blocks that no goal names must move (FAMILIES): cells,
goals placed from them, scenes, and the supports that goals in the air need."""
import numpy as np

from .geometry import BLOCK_H, BLOCK_W, is_success, layer_y

# Held-out shapes: (offset from the centre in block widths, layer). None of them can occur among
# the base tasks (at most 3 goals, at most one block moved), and each has >= 4 goals with >= 3
# above the ground. Drawings are in the README.
SHAPES = {
    "I": [(0, 0), (0, 1), (0, 2), (0, 3)],                         # a tower of four
    "Y": [(-0.75, 0), (0.75, 0), (0, 1), (0, 2), (0, 3)],          # upside down: stem on two legs
    "3T": [(-1, 0), (0, 0), (1, 0), (-0.5, 1), (0.5, 1), (0, 2)],  # three tiers, 3-2-1
}

# Not in the paper: tasks that no goal-named block can solve alone, as cells like SHAPES'.
# "blocked": a held-out shape whose scene has a block that no goal names standing on the spot of
# a ground goal (it must be moved away first). "air": goals whose supports no goal names, over an
# empty spot (free blocks must be stacked under them).
FAMILIES = {
    "blocked": {"I": SHAPES["I"], "Y": SHAPES["Y"]},
    "air": {"1 up": [(0, 1)], "2 up": [(0, 2)], "3 up": [(0, 3)],
            "two apart": [(-1.5, 1), (1.5, 1)],                    # one storey up, each
            "tower top": [(0, 2), (0, 3)]},                        # a tower's top, base free
}


def blocks_needed(cells):
    """Blocks that building cells [(dx, layer)] takes: one per cell, and the supports that blocks
    no goal names must give the cells in the air."""
    spots = {i: (dx * BLOCK_W, float(layer_y(k))) for i, (dx, k) in enumerate(cells)}
    return len(cells) + len(supports(spots))


def place_cells(cells, env, rng, name="the cells"):
    """Goals for cells [(dx, layer)] at a random place, with randomly assigned blocks.

    Returns {block: (x, y)}; the centre lies on the x grid so every goal is reachable.
    """
    if len(cells) > env.n_blocks:
        raise ValueError(f"{name} needs {len(cells)} blocks, the world has {env.n_blocks}")
    left, right = (f(dx for dx, _ in cells) * BLOCK_W for f in (min, max))
    x = env.x_bins
    fits = (x + left >= x[0] - 1e-9) & (x + right <= x[-1] + 1e-9)
    cx = x[fits][rng.integers(fits.sum())]
    blocks = rng.permutation(env.n_blocks)[: len(cells)]
    return {int(b): (float(cx + dx * BLOCK_W), float(env.y_bins[k]))
            for b, (dx, k) in zip(blocks, cells)}


def start_state(env, goals, rng):
    """A random scattered scene for these goals (the env keeps goal footprints clear)."""
    env.reset(seed=int(rng.integers(2**31)), options={"goals": goals})
    return env.get_state()


def blocked_state(env, goals, rng):
    """A scattered scene for these goals, then a block that no goal names set down on the spot of
    a random ground goal (the scene kept that spot free, so it touches no other block)."""
    state = start_state(env, goals, rng)
    free = sorted(set(range(env.n_blocks)) - set(goals))          # blocks no goal names
    ground = [xy for xy in goals.values() if xy[1] < BLOCK_H]
    if not free or not ground:
        raise ValueError("a blocked scene needs a block without a goal and a goal on the ground")
    b, (x, _) = int(rng.choice(free)), ground[rng.integers(len(ground))]
    state[b, :3] = (x, BLOCK_H / 2, 0.0)
    return state


def tasks_of(cells, env, rng, count, scene=start_state, name="the cells"):
    """`count` tasks [(s0, goals)] of the cells, each placed at random (place_cells) in a scene
    of its own: scattered (start_state), or with a block on the site (blocked_state)."""
    tasks = []
    for _ in range(count):
        goals = place_cells(cells, env, rng, name)
        tasks.append((scene(env, goals, rng), goals))
    return tasks


def eval_tasks(cfg, env):
    """Fixed evaluation tasks per shape: the same scenes after every round (own Generator)."""
    rng = np.random.default_rng([cfg.seed, cfg.eval_salt])
    return {name: tasks_of(SHAPES[name], env, rng, cfg.eval_episodes, name=f"shape {name!r}")
            for name in cfg.shapes}


def supports(goals):
    """The spots [(x, y)] that blocks no goal names must fill under goals {block: (x, y)} in the
    air: under every goal, down to the table, each layer where no goal or support overlaps it."""
    filled = list(goals.values())
    for x, y in sorted(goals.values(), key=lambda xy: -xy[1]):
        for y_below in np.arange(y - BLOCK_H, 0, -BLOCK_H):
            if not any(abs(fx - x) < BLOCK_W and abs(fy - y_below) < BLOCK_H / 2
                       for fx, fy in filled):
                filled.append((float(x), float(y_below)))
    return filled[len(goals):]


def site_free(state, goals):
    """True when no block stands on the table where the goals or their supports need the ground
    (a goal block at its own goal aside): in a crowded scene some block must first move away."""
    ground = [x for x, y in [*goals.values(), *supports(goals)] if y < BLOCK_H]
    placed = {b for b, xy in goals.items() if is_success(state, {b: xy})}
    return not any(abs(state[b, 0] - x) < BLOCK_W - 1e-6 and state[b, 1] < BLOCK_H
                   for b in range(len(state)) if b not in placed for x in ground)


def family_tasks(cfg, env):
    """Fixed evaluation tasks of the families cfg.families: {family: {task: [(s0, goals)]}},
    cfg.eval_episodes each, from a Generator of their own (so the held-out shapes' scenes do not
    change with them). A task that needs more blocks than the world has is left out."""
    rng = np.random.default_rng([cfg.seed, cfg.eval_salt, 1])
    out = {}
    for family in cfg.families:
        scene = blocked_state if family == "blocked" else start_state
        out[family] = {name: tasks_of(cells, env, rng, cfg.eval_episodes, scene)
                       for name, cells in FAMILIES[family].items()
                       if blocks_needed(cells) + (family == "blocked") <= env.n_blocks}  # blocker
    return out
