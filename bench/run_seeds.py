"""Run taskexp.py over several seeds (and ablations) and report zero-shot success as mean +- std.

    python bench/run_seeds.py --seeds 0 1 2                       # ours, default budget
    python bench/run_seeds.py --seeds 0 1 2 --variants ours direct-ppo end2new init2new no-restrict

Each run is a separate `taskexp.py` process writing runs/bench/<variant>-seed<k>; two run at a time
(one per core, each pinned to one BLAS thread). Prints a markdown table per variant and round.
"""
import argparse
import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np

import cli

FLAGS = {"ours": [], "direct-ppo": ["--baseline", "direct-ppo"], "end2new": ["--select", "end2new"],
         "init2new": ["--select", "init2new"], "no-restrict": ["--no-restrict"]}


def run_one(variant, seed, rounds, root, extra_args):
    """Finished runs are reused, stopped ones resumed (same results as if never stopped)."""
    out = os.path.join(root, f"{variant}-seed{seed}")
    done = cli.saved_round(out)
    if done < rounds:
        cmd = [sys.executable, "-m", "cli", "--rounds", str(rounds), "--out", out]
        cmd += ["--resume"] if done >= 0 else ["--seed", str(seed), *FLAGS[variant], *extra_args]
        with open(out + ".log", "a" if done >= 0 else "w") as log:
            subprocess.run(cmd, check=True, stdout=log, stderr=subprocess.STDOUT)
    with open(os.path.join(out, "results.json")) as f:
        return variant, seed, json.load(f)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--variants", nargs="+", choices=list(FLAGS), default=["ours"])
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--root", default=os.path.join("runs", "bench"))
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--scale", default=None, help="passed to taskexp.py (smaller budgets)")
    a = p.parse_args()
    os.makedirs(a.root, exist_ok=True)
    extra_args = ["--scale", a.scale] if a.scale else []
    jobs = [(v, s) for v in a.variants for s in a.seeds]
    with ThreadPoolExecutor(a.jobs) as pool:
        done = list(pool.map(lambda vs: run_one(*vs, a.rounds, a.root, extra_args), jobs))
    for variant in a.variants:
        res = [r for v, _, r in done if v == variant]
        shapes = list(res[0]["rounds"][0]["eval"])
        print(f"\n{variant}: zero-shot success, mean +- std over seeds {a.seeds}")
        print("| round | " + " | ".join(shapes) + " | wall-clock (s) |")
        print("|---" * (len(shapes) + 2) + "|")
        for k in range(a.rounds + 1):
            cells = []
            for s in shapes:
                v = 100 * np.array([r["rounds"][k]["eval"][s] for r in res])
                cells.append(f"{v.mean():.0f} +- {v.std():.0f}%")
            t = np.array([r["wallclock"]["total_s"] for r in res]) if k == a.rounds else None
            print(f"| {k} | " + " | ".join(cells)
                  + f" | {'' if t is None else f'{t.mean():.0f} +- {t.std():.0f}'} |")


if __name__ == "__main__":
    main()
