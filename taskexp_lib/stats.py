"""taskexp_lib/stats.py -- what a round's generated tasks look like (Table 1, Figures 1-2 of the
paper) and the order in which their demonstrations move blocks (sec 4.2's compositional tasks need
the supports first)."""
import numpy as np

from .geometry import THRESHOLD, is_success, layer, nearest_x_bin


def task_stats(goals, lengths, n_blocks):
    """Figures 1 and 2 and Table 1 of the paper for one round's tasks.

    goals: list of goal dicts; lengths: the episode length of each task's demonstration.
    A goal is "high" when it lies above the ground layer.
    """
    counts = [len(g) for g in goals]
    heights = [max(layer(y) for _, y in g.values()) for g in goals]
    high = [sum(layer(y) >= 1 for _, y in g.values()) >= 3 for g in goals]
    return dict(tasks=len(goals),
                goal_count_hist=np.bincount(counts, minlength=n_blocks + 1)[1:].tolist(),
                max_height_hist=np.bincount(heights, minlength=n_blocks)[:n_blocks].tolist(),
                high_goal_tasks=int(np.sum(high)),
                mean_episode_length=float(np.mean(lengths)) if goals else 0.0)


# What one move does for a task whose goals lie on several layers (move_kind). A block's goal is
# "pending" while the block is not within THRESHOLD of it; a goal in the air needs the pending
# goals under it first, so the move a builder makes is one of the lowest pending layer.
MOVE_KINDS = ("right", "right block, other x", "higher goal", "placed block", "free block")


def pending_layers(state, goals, threshold=THRESHOLD):
    """{block: goal layer} of the goal blocks not yet within `threshold` of their goals."""
    return {b: layer(y) for b, (x, y) in goals.items()
            if not is_success(state, {b: (x, y)}, threshold)}


def move_kind(state, goals, action, threshold=THRESHOLD):
    """What the move `action` (block, x-bin, ...) makes of the goals, one of MOVE_KINDS:

      right                 a pending block of the lowest pending layer, to its goal's x-bin
      right block, other x  that block, to another x
      higher goal           a pending block whose goal is above the lowest pending layer
      placed block          a goal block that already is at its goal
      free block            a block without a goal
    None when no goal is pending (the task is solved)."""
    pending = pending_layers(state, goals, threshold)
    if not pending:
        return None
    b, ix = int(action[0]), int(action[1])
    if b not in goals:
        return "free block"
    if b not in pending:
        return "placed block"
    if pending[b] > min(pending.values()):
        return "higher goal"
    return "right" if ix == nearest_x_bin(goals[b][0]) else "right block, other x"


def order_stats(demos, threshold=THRESHOLD):
    """How the demonstrations order their moves: among their steps taken while pending goals lie
    on two or more layers (multi_layer_steps), the share that move a block of a higher one
    (higher_first; None without such steps). Only such a step says whether the data teach to
    build the support first."""
    kinds = [move_kind(s, d.goals, a, threshold) for d in demos
             for s, a in zip(d.states, d.actions)
             if len(set(pending_layers(s, d.goals, threshold).values())) > 1]
    return dict(multi_layer_steps=len(kinds),
                higher_first=kinds.count("higher goal") / len(kinds) if kinds else None)


def unnamed_moves(demos):
    """The share of the demonstrations' steps that move a block no goal names (None without
    steps): the leading indicator of whether the data teach to clear a site or build a support."""
    moved = [int(a[0]) in d.goals for d in demos for a in d.actions]
    return 1 - sum(moved) / len(moved) if moved else None
