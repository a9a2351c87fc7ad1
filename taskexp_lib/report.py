"""taskexp_lib/report.py -- what a run reports: the statistics of generated tasks, Tables 1 and 2
of the paper as markdown, and Figures 1 and 2 as PNG files."""
import os

import numpy as np

from .geometry import layer


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


FIGURES = (("max_height_hist", "fig1_max_goal_height.png", "highest goal (layer, 0 = table)", 0),
           ("goal_count_hist", "fig2_goal_count.png", "number of goals", 1))


def figures(results, out_dir):
    """Figure 1 (maximum goal height) and Figure 2 (number of goals) per round, as PNG files:
    the fraction of each round's generated tasks per bin, rounds side by side."""
    from matplotlib.figure import Figure
    rounds = [r for r in results["rounds"] if "tasks" in r]
    width = 0.8 / max(len(rounds), 1)
    paths = []
    for key, fname, xlabel, first_bin in FIGURES:
        fig = Figure(figsize=(5, 3.2))
        ax = fig.add_subplot()
        for i, r in enumerate(rounds):
            h = np.array(r[key], float)
            x = np.arange(len(h)) + first_bin + (i - (len(rounds) - 1) / 2) * width
            label = f"round {r['round']}" + (" (base)" if r["round"] == 0 else "")
            ax.bar(x, h / max(h.sum(), 1), width, label=label)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("fraction of generated tasks")
        ax.legend()
        fig.tight_layout()
        paths.append(os.path.join(out_dir, fname))
        fig.savefig(paths[-1], dpi=100)
    return paths
