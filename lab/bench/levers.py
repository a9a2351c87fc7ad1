"""Runs of one lever over seeds, round by round: mean +- std of what the issue of the families asks.

    python lab/bench/levers.py "clearing pairs, parts in BC=runs/cpB-seed0,runs/cpB-seed1"
    python lab/bench/levers.py "held=lab/results/runs/issue53/relH-seed*.json"

Each argument is NAME=RUNS: run directories (their results.json) or results.json files, comma
separated, a glob expanded. Per round it prints the mean over the held-out shapes (sec 5), each
family's mean over its tasks, and the shapes in worlds of other block counts, as mean +- std over
the runs, with the per-task means below each round.
"""
import argparse
import glob
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from run_seeds import pm  # noqa: E402


def load(paths):
    """results.json of each path (a run directory, or the file itself), globs expanded."""
    out = []
    for p in (f for part in paths.split(",") for f in sorted(glob.glob(part)) or [part]):
        with open(os.path.join(p, "results.json") if os.path.isdir(p) else p) as f:
            out.append(json.load(f))
    return out


def summary(runs):
    """-> [(round, {figure: [per run]}, {figure: {task: mean over runs}})], over the rounds every
    run has. Figures: "I/Y/3T" (the mean over the shapes), each family, "N blocks" (the shapes in
    the worlds of other block counts)."""
    rows = []
    for k in range(min(len(r["rounds"]) for r in runs)):
        records = [r["rounds"][k] for r in runs]
        groups = {"I/Y/3T": [r["eval"] for r in records]}
        groups.update({f: [r["families"][f] for r in records] for f in records[0]["families"]})
        for n in records[0].get("blocks", {}):
            groups[f"{n} blocks"] = [r["blocks"][n] for r in records]
        means = {name: [float(np.mean(list(t.values()))) for t in per_run]
                 for name, per_run in groups.items()}
        tasks = {name: {t: float(np.mean([p[t] for p in per_run])) for t in per_run[0]}
                 for name, per_run in groups.items()}
        rows.append((records[0]["round"], means, tasks))
    return rows


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("levers", nargs="+", metavar="NAME=RUNS")
    a = p.parse_args()
    for lever in a.levers:
        name, sep, paths = lever.partition("=")
        if not sep:
            p.error(f"{lever!r}: give NAME=RUNS")
        runs = load(paths)
        print(f"## {name} ({len(runs)} runs)")
        for k, means, tasks in summary(runs):
            print(f"round {k}: " + " | ".join(f"{n} {pm(100 * np.asarray(v), '%')}"
                                        for n, v in means.items()))
            print("    " + "; ".join(f"{n}: " + ", ".join(f"{t} {100 * v:.0f}"
                                                         for t, v in per.items())
                                   for n, per in tasks.items()))


if __name__ == "__main__":
    main()
