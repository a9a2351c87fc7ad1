"""taskexp_lib/geometry.py -- the block world's geometry: the one place it is written.

Block and table sizes, the x grid of the actions, the layers, the success threshold, and the
pure functions of them that the world (env2d.py), the agent's features (features.py), the
checkpoints (which record GEOMETRY and refuse another) and the exercises share. numpy only, so
reading it needs no physics engine.
"""
import numpy as np

BLOCK_W, BLOCK_H = 0.10, 0.05               # metres; width twice the height
TABLE_X = (-0.5, 0.5)                       # ten block widths
THRESHOLD = 0.02                            # a goal holds within 2 cm (euclidean, block centre)
MAX_BLOCKS = 8                              # the most blocks a world holds (2..8)
N_X = 37
# spacing BLOCK_W / 4; a block on any bin lies on the table
X_BINS = np.linspace(-0.45, 0.45, N_X)
GEOMETRY = {"block_w": BLOCK_W, "block_h": BLOCK_H, "table_lo": TABLE_X[0], "table_hi": TABLE_X[1],
            "threshold": THRESHOLD, "x_lo": X_BINS[0], "x_hi": X_BINS[-1]}


def block_count(n, least=2, name="n_blocks"):
    """n as an int when a world of n blocks can be made and used: least..MAX_BLOCKS (the table
    holds MAX_BLOCKS; a run's own world needs its held-out shapes' blocks). Anything else is a
    ValueError whose message is one line and names `name`. Every layer that takes a block count
    checks it here: the world, the agent, the command line and `try`."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not least <= n <= MAX_BLOCKS:
        raise ValueError(f"{name} must be in {least}..{MAX_BLOCKS}, got {n!r}")
    return int(n)


def nearest_x_bin(x):
    """The index of the x grid's bin nearest to x."""
    return int(np.abs(X_BINS - x).argmin())


def layer(y):
    """Layer index of a height y (layer 0 rests on the table): an int, or an int array."""
    k = np.round(np.asarray(y) / BLOCK_H - 0.5).astype(np.int64)
    return int(k) if k.ndim == 0 else k


def layer_y(k):
    """Height of the centre of a block resting flat in layer k (an int or an array)."""
    return (np.asarray(k) + 0.5) * BLOCK_H


def max_goal_y(n_blocks):
    """The highest a block's centre can be: all n blocks stacked on end, one on the other. A goal
    above it can never be met."""
    return n_blocks * BLOCK_W - BLOCK_W / 2


# Two blocks' centres are at least BLOCK_H apart (each holds a disc of radius BLOCK_H / 2), so two
# goals closer than this can never both hold within THRESHOLD: they name the same spot.
SAME_SPOT = BLOCK_H - 2 * THRESHOLD


def on_same_spot(p, q):
    """True when goal positions p and q, (x, y) each, are less than SAME_SPOT apart."""
    return bool(np.hypot(p[0] - q[0], p[1] - q[1]) < SAME_SPOT)


def same_spot(goals):
    """The first pair of blocks (a, b) whose goals {block: (x, y)} name the same spot, or None."""
    items = list(goals.items())
    for i, (a, p) in enumerate(items):
        for b, q in items[i + 1:]:
            if on_same_spot(p, q):
                return a, b
    return None


def observation(state, goals):
    """Observation (n, 6) float32 of a state (n, 6) and goals {block: (x, y)}:
    columns x, y, angle, goal_x, goal_y, has_goal (goal columns 0 for blocks without a goal)."""
    obs = np.zeros((len(state), 6), np.float32)
    obs[:, :3] = state[:, :3]
    for b, (x, y) in goals.items():
        obs[b, 3:] = (x, y, 1.0)
    return obs


def is_success(state, goals, threshold=THRESHOLD):
    """True iff every goal block's centre is within `threshold` of its target (state (n, 6))."""
    return all(np.hypot(state[b, 0] - x, state[b, 1] - y) < threshold
               for b, (x, y) in goals.items())
