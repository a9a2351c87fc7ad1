"""Run taskexp.py over several seeds (and ablations) and report zero-shot success as mean +- std.

    python lab/bench/run_seeds.py --seeds 0 1 2                       # ours, default budget
    python lab/bench/run_seeds.py --seeds 0 1 2 --variants ours direct-ppo end2new init2new \
        no-restrict
    python lab/bench/run_seeds.py --seeds 0 1 2 --slurm PARTITION --jobs 15   # on a cluster
    python lab/bench/run_seeds.py --seeds 0 1 --scale 0.1 -- --ppo-steps 40000  # flags for taskexp

Each run is a separate `taskexp.py` process, handed to an engine (lab/bench/engine.py: submitit),
writing runs/<variant>-seed<k>, or the directory DIRS names (no-restrict:
runs/ours-norestrict-seed<k>, as `taskexp.py` would name it itself), where the notebooks and
lab/bench/reproduce.py look for them. On this machine --jobs runs go at a time with one worker
each (two runs use the two cores); with --slurm each run is a job with --cores cores. Finished runs
are reused and stopped ones resumed; a run that fails is reported with the end of its log, the
others go on. Prints a markdown table per variant and round.
"""
import argparse
import glob
import json
import os
import subprocess
import sys

import numpy as np

BENCH = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(BENCH))              # the checkout, installed or not
sys.path[:0] = [BENCH, ROOT]
import engine  # noqa: E402

import taskexp_cli as cli  # noqa: E402
from taskexp_lib.config import ADDED, REMOVED, Config  # noqa: E402

FLAGS = {"ours": [], "direct-ppo": ["--baseline", "direct-ppo"], "end2new": ["--select", "end2new"],
         "init2new": ["--select", "init2new"], "no-restrict": ["--no-restrict"],
         "no-labels": ["--label-tasks", "0"], "expand6000": ["--expand-episodes", "6000"],
         "relations": ["--features", "relations"], "hidden64": ["--hidden", "64"]}


# finished runs' results.json, copied by lab/bench/headline.py --keep and committed
KEPT = os.path.join(os.path.dirname(BENCH), "results", "runs")
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


def command(variant, seed, rounds, root, extra_args, workers=1):
    """The command that makes one run, or goes on with it (--resume: the same results as if never
    stopped); None when it is finished. workers=None: as many as the job's cores."""
    out = run_dir(variant, seed, root)
    done = cli.saved_round(out)
    if done >= rounds:
        return None
    cmd = [sys.executable, os.path.join(ROOT, "taskexp.py"), "--rounds", str(rounds), "--out", out]
    cmd += [] if workers is None else ["--workers", str(workers)]
    return cmd + (["--resume"] if done >= 0 else ["--seed", str(seed), *FLAGS[variant],
                                                   *extra_args])


def results_of(variant, seed, root):
    with open(os.path.join(run_dir(variant, seed, root), "results.json")) as f:
        return json.load(f)


def fresh_log(cmd, variant, seed, root):
    """The log file of a run that `cmd` makes or resumes: a new run starts a new log (the old
    one removed), a resumed one appends to its own."""
    log = run_dir(variant, seed, root) + ".log"
    if "--resume" not in cmd and os.path.exists(log):
        os.remove(log)
    return log


def run_one(variant, seed, rounds, root, extra_args):
    """One run in this process's thread (lab/bench/reproduce.py): made, resumed or reused."""
    cmd = command(variant, seed, rounds, root, extra_args)
    if cmd:
        with open(fresh_log(cmd, variant, seed, root), "a") as log:
            subprocess.run(cmd, check=True, stdout=log, stderr=subprocess.STDOUT)
    return variant, seed, results_of(variant, seed, root)


def run_many(pairs, rounds, root, extra_args, jobs=2, slurm=None, cores=2):
    """Every (variant, seed) run through the engine: the unfinished ones made or resumed, at most
    `jobs` at a time. -> ({(variant, seed): results} of the finished runs, {run: end of its log}
    of the failed ones)."""
    runs = {}
    for variant, seed in pairs:
        cmd = command(variant, seed, rounds, root, extra_args, None if slurm else 1)
        if cmd:
            runs[os.path.basename(run_dir(variant, seed, root))] = cmd, fresh_log(
                cmd, variant, seed, root)
    print(f"{len(pairs) - len(runs)} of {len(pairs)} runs finished already; {len(runs)} to go")
    failed = engine.run_all(runs, os.path.join(root, ".submitit"), jobs, slurm,
                            cores if slurm else 1)
    done = {(v, s): results_of(v, s, root) for v, s in pairs
            if os.path.basename(run_dir(v, s, root)) not in failed}
    return done, failed


def load(name, kept=KEPT):
    """The kept runs of one name (a run folder's, without -seedK), in seed order."""
    runs = []
    for path in glob.glob(os.path.join(kept, f"{name}-seed*.json")):
        with open(path) as f:
            runs.append(json.load(f))
    # a field added or removed since (config.ADDED, REMOVED) at the value today's code runs is
    # the same setting whether a run's results record it or not
    same = lambda k, v: k in REMOVED and v == REMOVED[k]
    configs = {json.dumps({k: v for k, v in {**ADDED, **r["config"]}.items()
                           if k != "seed" and not same(k, v)}, sort_keys=True) for r in runs}
    if len(configs) > 1:
        raise ValueError(f"the kept {name} runs differ in more than their seed")
    return sorted(runs, key=lambda r: r["config"]["seed"])


def split_argv(argv):
    """This script's flags, and those after `--`, which go to every new run's taskexp.py."""
    if "--" not in argv:
        return argv, []
    return argv[:argv.index("--")], argv[argv.index("--") + 1:]


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--variants", nargs="+", choices=list(FLAGS), default=["ours"])
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--root", default="runs")
    p.add_argument("--jobs", type=int, default=2, help="runs at a time (default 2)")
    p.add_argument("--scale", default=None, help="passed to taskexp.py (smaller budgets)")
    p.add_argument("--slurm", metavar="PARTITION", help="run each as a job on this SLURM partition "
                   "(default: processes on this machine)")
    p.add_argument("--cores", type=int, default=2, help="with --slurm: cores per run (default 2)")
    ours, theirs = split_argv(sys.argv[1:])
    a = p.parse_args(ours)
    root = os.path.abspath(a.root)              # the jobs may start in another folder
    os.makedirs(root, exist_ok=True)
    extra_args = (["--scale", a.scale] if a.scale else []) + theirs
    pairs = [(v, s) for v in a.variants for s in a.seeds]
    done, failed = run_many(pairs, a.rounds, root, extra_args, a.jobs, a.slurm, a.cores)
    summary = []
    for variant in a.variants:
        res = [done[v, s] for v, s in pairs if v == variant and (v, s) in done]
        if len(res) < len(a.seeds):
            print(f"\n{variant}: {len(a.seeds) - len(res)} of its runs failed; no table")
            continue
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
    if failed:
        sys.exit(f"{len(failed)} run(s) failed: {', '.join(failed)} (their logs: {root}/)")


def pm(values, unit="", digits=0):
    """mean +- std of values, as text."""
    v = np.asarray(values, float)
    return f"{v.mean():.{digits}f} +- {v.std():.{digits}f}{unit}"


if __name__ == "__main__":
    main()
