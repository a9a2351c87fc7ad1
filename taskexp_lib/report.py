"""taskexp_lib/report.py -- what a run reports: the statistics of generated tasks, the order in
which their demonstrations move blocks, Tables 1 and 2 of the paper as markdown, and Figures 1 and
2 as PNG files."""
import os

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


def tables(results):
    """Table 1 (generated tasks per round) and Table 2 (zero-shot success) as markdown."""
    rounds = results["rounds"]
    shapes = list(rounds[0]["eval"])
    t1 = ["| round | generated tasks | # high goals (>= 3 above ground) | mean episode length "
          "| eq. (1) picks reached |", "|---|---|---|---|---|"]
    reached = lambda r: (f"{r['expansion']['picks_reached']:.0%}"
                         if "picks_reached" in r.get("expansion", {}) else "")
    t1 += [f"| {r['round']} | {r['tasks']} | {r['high_goal_tasks']} | "
           f"{r['mean_episode_length']:.2f} | {reached(r)} |" for r in rounds if "tasks" in r]
    t2 = ["| round | " + " | ".join(shapes) + " |", "|---" * (len(shapes) + 1) + "|"]
    t2 += [f"| {r['round']} | " + " | ".join(f"{100 * r['eval'][s]:.0f}%" for s in shapes) + " |"
           for r in rounds]
    return "\n".join(["Table 1: generated tasks", *t1, "", "Table 2: zero-shot success", *t2])


# (key in a round's record, file name, title, x label, first bin, log y axis); Figure 1 on a log
# axis, where the few tasks that reach layers 2 and 3 -- what task expansion is about -- show
FIGURES = (("max_height_hist", "fig1_max_goal_height.png",
            "Figure 1: highest goal of the generated tasks", "highest goal (layer, 0 = table)", 0,
            True),
           ("goal_count_hist", "fig2_goal_count.png",
            "Figure 2: goals per generated task", "number of goals", 1, False))
DPI = 120


def histogram_figure(per_round, title, xlabel, first_bin, log=False):
    """One figure of the paper: per round, the fraction of the generated tasks in each bin.

    per_round: [(round, histograms (seeds, bins))]; bars show the mean over the seeds and, for
    more than one seed, their standard deviation as error bars. log: a log y axis.
    Returns a matplotlib Figure (no pyplot: it works without a display).
    """
    from matplotlib.figure import Figure
    fig = Figure(figsize=(6.4, 3.4))
    ax = fig.add_subplot()
    width = 0.8 / max(len(per_round), 1)
    seeds = len(per_round[0][1]) if per_round else 1
    for i, (k, hists) in enumerate(per_round):
        h = np.asarray(hists, float)
        share = h / np.maximum(h.sum(1, keepdims=True), 1)
        x = np.arange(h.shape[1]) + first_bin + (i - (len(per_round) - 1) / 2) * width
        ax.bar(x, share.mean(0), width, yerr=share.std(0) if seeds > 1 else None,
               label=f"round {k}" + (" (base)" if k == 0 else ""))
    if log:
        ax.set_yscale("log")
    ax.set_xticks(np.arange(len(per_round[0][1][0])) + first_bin if per_round else [])
    ax.set_xlabel(xlabel)
    ax.set_ylabel("fraction of the round's tasks" + (" (log)" if log else ""))
    spread = f"mean over {seeds} seeds, error bars: std" if seeds > 1 else "one run"
    ax.set_title(f"{title}\n({spread})", fontsize=10)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))   # beside the bars
    fig.tight_layout()
    return fig


def figures(results, out_dir):
    """Figure 1 (highest goal) and Figure 2 (number of goals) of one run, per round, as PNG files
    in out_dir -> their paths."""
    rounds = [r for r in results["rounds"] if "tasks" in r]
    paths = []
    for key, fname, title, xlabel, first_bin, log in FIGURES:
        fig = histogram_figure([(r["round"], [r[key]]) for r in rounds], title, xlabel,
                               first_bin, log)
        paths.append(os.path.join(out_dir, fname))
        fig.savefig(paths[-1], dpi=DPI)
    return paths
