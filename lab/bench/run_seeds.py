"""Run taskexp.py over several seeds (and ablations) and report zero-shot success as mean +- std.

    python lab/bench/run_seeds.py --seeds 0 1 2                       # ours, default budget
    python lab/bench/run_seeds.py --seeds 0 1 2 --variants ours direct-ppo end2new init2new \
        no-restrict

Each run is a separate `taskexp.py` process (one worker: two runs at a time use the two cores)
writing runs/<variant>-seed<k>, or the directory DIRS names (no-restrict:
runs/ours-norestrict-seed<k>, as `taskexp.py` would name it itself), where the notebooks look for
them. Prints a markdown table per variant and round.
"""
import argparse
import glob
import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np

import taskexp_cli as cli
from taskexp_lib.config import Config

FLAGS = {"ours": [], "direct-ppo": ["--baseline", "direct-ppo"], "end2new": ["--select", "end2new"],
         "init2new": ["--select", "init2new"], "no-restrict": ["--no-restrict"],
         "no-labels": ["--label-tasks", "0"], "expand6000": ["--expand-episodes", "6000"],
         "relations": ["--features", "relations"], "hidden64": ["--hidden", "64"]}


# finished runs' results.json, copied by lab/bench/headline.py --keep and committed
KEPT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "results", "runs")
# as taskexp.py names its default directories (expand6000 and hidden64: a name of ours, where
# taskexp.py would add a code of the setting)
DIRS = {"no-restrict": "ours-norestrict", "no-labels": "ours-nolabels",
        "expand6000": "ours-expand6000", "relations": "ours-relations", "hidden64": "ours-h64"}


def kept_name(variant, features=Config.features):
    """A variant's name as taskexp.py names its folder, the prefix of its kept runs' files too;
    other features than the default add -<features> (ours-relations), as cli.parse_args does."""
    return DIRS.get(variant, variant) + ("" if features == Config.features else f"-{features}")


def run_dir(variant, seed, root):
    """The folder of one run: root/<variant>-seed<k>, named as taskexp.py names its own."""
    return os.path.join(root, f"{kept_name(variant)}-seed{seed}")


def run_one(variant, seed, rounds, root, extra_args):
    """Finished runs are reused, stopped ones resumed (same results as if never stopped)."""
    out = run_dir(variant, seed, root)
    done = cli.saved_round(out)
    if done < rounds:
        cmd = [sys.executable, "-m", "taskexp_cli", "--rounds", str(rounds), "--out", out,
               "--workers", "1"]
        cmd += ["--resume"] if done >= 0 else ["--seed", str(seed), *FLAGS[variant], *extra_args]
        with open(out + ".log", "a" if done >= 0 else "w") as log:
            subprocess.run(cmd, check=True, stdout=log, stderr=subprocess.STDOUT)
    with open(os.path.join(out, "results.json")) as f:
        return variant, seed, json.load(f)


def load(name, kept=KEPT):
    """The kept runs of one name (a run folder's, without -seedK), in seed order."""
    runs = []
    for path in glob.glob(os.path.join(kept, f"{name}-seed*.json")):
        with open(path) as f:
            runs.append(json.load(f))
    configs = {json.dumps({k: v for k, v in r["config"].items() if k != "seed"}, sort_keys=True)
               for r in runs}
    if len(configs) > 1:
        raise ValueError(f"the kept {name} runs differ in more than their seed")
    return sorted(runs, key=lambda r: r["config"]["seed"])


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--variants", nargs="+", choices=list(FLAGS), default=["ours"])
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--root", default="runs")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--scale", default=None, help="passed to taskexp.py (smaller budgets)")
    a = p.parse_args()
    os.makedirs(a.root, exist_ok=True)
    extra_args = ["--scale", a.scale] if a.scale else []
    jobs = [(v, s) for v in a.variants for s in a.seeds]
    with ThreadPoolExecutor(a.jobs) as pool:
        done = list(pool.map(lambda vs: run_one(*vs, a.rounds, a.root, extra_args), jobs))
    summary = []
    for variant in a.variants:
        res = [r for v, _, r in done if v == variant]
        shapes = list(res[0]["rounds"][0]["eval"])
        print(f"\n{variant}: zero-shot success, mean +- std over seeds {a.seeds}")
        print("| round | " + " | ".join(shapes) + " | wall-clock (s) |")
        print("|---" * (len(shapes) + 2) + "|")
        for k in range(a.rounds + 1):
            cells = [pm([100 * r["rounds"][k]["eval"][s] for r in res], "%") for s in shapes]
            t = [r["wallclock"]["total_s"] for r in res] if k == a.rounds else None
            print(f"| {k} | " + " | ".join(cells) + f" | {'' if t is None else pm(t)} |")
        last = [100 * np.mean(list(r["rounds"][a.rounds]["eval"].values())) for r in res]
        summary.append((variant, pm(last, "%")))
        if not all("tasks" in r["rounds"][k] for r in res for k in range(1, a.rounds + 1)):
            continue                                 # direct PPO generates no tasks
        print(f"\n{variant}: generated tasks (Table 1, Figure 1), mean +- std over seeds")
        print("| round | tasks | high-goal tasks (>= 3 above ground) | mean episode length "
              "| mean highest goal layer |")
        print("|---|---|---|---|---|")
        for k in range(a.rounds + 1):
            rows = [r["rounds"][k] for r in res]
            layer = [np.average(np.arange(len(w["max_height_hist"])), weights=w["max_height_hist"])
                     if sum(w["max_height_hist"]) else 0.0 for w in rows]
            print(f"| {k} | {pm([w['tasks'] for w in rows])} | "
                  f"{pm([w['high_goal_tasks'] for w in rows])} | "
                  f"{pm([w['mean_episode_length'] for w in rows], '', 2)} | {pm(layer, '', 2)} |")
    print(f"\nround {a.rounds}, mean over the shapes, mean +- std over seeds {a.seeds}")
    print("| variant | success |\n|---|---|")
    for variant, cell in summary:
        print(f"| {variant} | {cell} |")


def pm(values, unit="", digits=0):
    """mean +- std of values, as text."""
    v = np.asarray(values, float)
    return f"{v.mean():.{digits}f} +- {v.std():.{digits}f}{unit}"

if __name__ == "__main__":
    main()
