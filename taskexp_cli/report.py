"""taskexp_cli/report.py -- what a run reports: Tables 1 and 2 of the paper as markdown and
Figures 1 and 2 as PNG files, from a run's results.json (the statistics: taskexp_lib/stats.py)."""
import os

import numpy as np


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


def family_tables(results):
    """Not in the paper: zero-shot success on the families of blocks that no goal names, one
    markdown table per family, round by round ("" for a run made before they were measured)."""
    rounds, out = results["rounds"], []
    for family, rates in rounds[-1].get("families", {}).items():
        tasks = list(rates)
        out += ["", f"Zero-shot success, {FAMILY_TITLES.get(family, family)}",
                "| round | " + " | ".join(tasks) + " |", "|---" * (len(tasks) + 1) + "|"]
        out += [f"| {r['round']} | " + " | ".join(f"{100 * r['families'][family][t]:.0f}%"
                                                  for t in tasks) + " |"
                for r in rounds if family in r.get("families", {})]
    return "\n".join(out[1:])


def rates_by_blocks(record, n_blocks):
    """{block count (str): {shape: success}} of one round's record: the run's own world of
    n_blocks ("eval") and the other worlds it measured ("blocks", none for a run made before)."""
    return {str(n_blocks): record["eval"], **record.get("blocks", {})}


def blocks_table(results):
    """Not in the paper: zero-shot success on the held-out shapes in worlds of other block counts,
    with the weights learnt in the run's own, beside it, round by round ("" for a run made before
    they were measured)."""
    rounds, n = results["rounds"], results["config"]["n_blocks"]
    counts = list(rounds[-1].get("blocks", {}))
    if not counts:
        return ""
    shapes = list(rounds[0]["eval"])
    out = [f"Zero-shot success in worlds of other block counts (the weights learnt with {n})",
           "| round | blocks | " + " | ".join(shapes) + " |", "|---" * (len(shapes) + 2) + "|"]
    for r in rounds:
        for count, rates in rates_by_blocks(r, n).items():
            out.append(f"| {r['round']} | {count} | "
                       + " | ".join(f"{100 * rates[s]:.0f}%" for s in shapes) + " |")
    return "\n".join(out)


FAMILY_TITLES = {"blocked": "blocked: a block no goal names stands on a ground goal's spot",
                 "air": "air: goals whose supports no goal names, over an empty spot"}


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
