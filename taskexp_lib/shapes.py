"""taskexp_lib/shapes.py -- the held-out shapes of sec 5 and their fixed evaluation scenes (the
2D analogues of the paper's test structures; taskexp.evaluate builds them zero-shot), and two
families of tasks beside them in which blocks that no goal names must move (FAMILIES)."""
import numpy as np

from .geometry import BLOCK_H, BLOCK_W, X_BINS, is_success, layer_y

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


# A structure a person writes (taskexp_cli's `try`): cells like SHAPES' as text, "dx,layer" each,
# separated by spaces, e.g. "0,0 0,1 1.5,0 1.5,1 0.75,2" (two towers and a block across). dx
# is in block widths from the structure's centre, on the action grid (a multiple of GRID); layer 0
# rests on the table. A goal may be in the air: blocks that no goal names must go under it.
GRID = (X_BINS[1] - X_BINS[0]) / BLOCK_W            # 0.25: the x grid's spacing in block widths
SPAN = (X_BINS[-1] - X_BINS[0]) / BLOCK_W           # 9: the widest a structure's centres may lie
WRITE = 'write cells as dx,layer separated by spaces, e.g. "0,0 0,1 0,2"'


def read_structure(text, n_blocks=8):
    """The cells [(dx, layer)] of a structure written as text (or a name in SHAPES) that a world
    of n_blocks can hold; anything else is a ValueError whose message is one line."""
    if text.strip() in SHAPES:
        cells = SHAPES[text.strip()]
    else:
        cells = [read_cell(word) for word in text.replace(";", " ").split()]
    if not cells:
        raise ValueError(f"no cells: {WRITE}")
    for i, (dx, k) in enumerate(cells):
        for dx2, k2 in cells[i + 1:]:
            if k == k2 and abs(dx - dx2) < 1:
                raise ValueError(f"cells {dx:g},{k} and {dx2:g},{k2} overlap: blocks in one layer "
                                 "lie at least 1 (a block width) apart")
    width = max(dx for dx, _ in cells) - min(dx for dx, _ in cells)
    if width > SPAN + 1e-9:
        raise ValueError(f"the cells lie {width:g} block widths apart; the action grid spans "
                         f"{SPAN:g}")
    need = blocks_needed(cells)
    if need > n_blocks:
        raise ValueError(f"the structure needs {need} blocks ({len(cells)} with goals, "
                         f"{need - len(cells)} under goals in the air); the world has {n_blocks}")
    return cells


def read_cell(word):
    """(dx, layer) of one cell written "dx,layer"; a one-line ValueError otherwise."""
    try:
        dx, k = (float(v) for v in word.split(","))
    except ValueError:
        raise ValueError(f"cell {word!r}: {WRITE}") from None
    if not np.isfinite([dx, k]).all():
        raise ValueError(f"cell {word!r}: dx and the layer must be finite numbers")
    if not abs(dx / GRID - round(dx / GRID)) < 1e-9:
        raise ValueError(f"cell {word!r}: dx must be a multiple of {GRID:g} (the action grid)")
    if not (k == int(k) and k >= 0):
        raise ValueError(f"cell {word!r}: the layer must be a whole number >= 0 (0: the table)")
    return dx, int(k)


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


def shape_goals(name, env, rng):
    """Goals for the held-out shape `name` at a random place, with randomly assigned blocks."""
    return place_cells(SHAPES[name], env, rng, name=f"shape {name!r}")


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
        out[family] = {}
        for name, cells in FAMILIES[family].items():
            if blocks_needed(cells) + (family == "blocked") > env.n_blocks:     # + the blocker
                continue
            out[family][name] = []
            for _ in range(cfg.eval_episodes):
                goals = place_cells(cells, env, rng)
                out[family][name].append((scene(env, goals, rng), goals))
    return out


def scripted_build(env, state, goals):
    """A scripted builder, to check that a scene can be built (tests; lab/bench): clear every
    block off the columns the goals and their supports need, then fill those spots bottom-up,
    goal blocks at their goals and blocks that no goal names at the supports. env: a world that
    drops (BlockWorld(drop=True)) with room for the moves. Returns True when the goals hold."""
    spots = [(xy, b) for b, xy in goals.items()] + [(xy, None) for xy in supports(goals)]
    columns = [x for (x, _), _ in spots]
    env.reset(options={"state": state, "goals": goals})

    def drop(b, x):
        env.step(env.encode_action(b, x, env.y_bins[0]))

    def apart(x, others):                                  # no overlap, touching allowed
        return all(abs(x - o) > BLOCK_W - 1e-6 for o in others)

    away = [x for x in env.x_bins if apart(x, columns)]
    if not away:
        return False
    for b in [b for b in np.argsort(-state[:, 1]) if not apart(state[b, 0], columns)]:
        others = np.delete(env.get_state(), b, axis=0)[:, 0]      # the highest in the way first
        on_table = [x for x in away if apart(x, others)]        # else onto a block out of the way
        drop(int(b), (on_table or away)[0])
    spare = sorted(set(range(env.n_blocks)) - set(goals))         # for the supports
    for (x, y), b in sorted(spots, key=lambda spot: spot[0][1]):
        if b is None:
            if not spare:
                return False
            b = spare.pop()
        drop(b, x)
    return is_success(env.get_state(), goals, env.threshold)
