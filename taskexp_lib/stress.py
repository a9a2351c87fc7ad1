"""taskexp_lib/stress.py -- stress actions for the world's physics: shared by the property test
(tests/test_env2d.py, drawing through hypothesis) and lab/bench/bench_settle.py (drawing from a
numpy Generator), so both drive the same distribution."""
import numpy as np

from .geometry import BLOCK_H, N_X, nearest_x_bin


def stack_tower(env):
    """Stack every block on block 0, one layer each: a tower as tall as the world allows."""
    for k, b in enumerate(range(1, env.n_blocks)):
        env.step([b, nearest_x_bin(env.get_state()[0, 0]), k + 1])


def adversarial_action(state, integers, choice):
    """An action (block, x-bin, layer) aimed where physics is most likely to break, given the
    current state (n, 6). integers(lo, hi) draws an int in [lo, hi]; choice(seq) draws an element
    of seq."""
    n = len(state)
    b = integers(0, n - 1)
    kind = choice(["uniform", "into", "onto", "air", "edge"])
    if kind == "uniform":
        return b, integers(0, N_X - 1), integers(0, n - 1)
    if kind == "edge":                                     # half over the table's edge, any height
        return b, choice([0, 1, N_X - 2, N_X - 1]), integers(0, n - 1)
    if kind == "air":                                      # the top layer: a long fall
        return b, integers(0, N_X - 1), n - 1
    j = integers(0, n - 1)                                 # another block, maybe on a tall stack
    ix = nearest_x_bin(state[j, 0]) + integers(-3, 3)
    k = int(np.clip(np.floor(state[j, 1] / BLOCK_H), 0, n - 1)) + (kind == "onto")
    return b, int(np.clip(ix, 0, N_X - 1)), int(np.clip(k, 0, n - 1))

