"""The reproduction report: the paper's Tables 1-3 and Figures 1-2 next to ours, over seeds.

    python lab/bench/reproduce.py                # 3 seeds, both feature sets: lab/RESULTS.md
    python lab/bench/reproduce.py --seeds 0 --features plain --scale 0.2     # a quick look
    python lab/bench/reproduce.py --kept          # from the runs kept in lab/results/runs/

Runs the method ("ours"), the direct-PPO baseline and the ablations of Table 3 (end2new, init2new,
w/o restriction; for --ablation-rounds, default 1: the paper's Table 3 is after round 1) with the
default settings, once with the plain features that self-attention learns from (the default) and
once with the hand-computed relations (--features relations).
Each run is one `taskexp.py` process through lab/bench/run_seeds.py: finished runs are reused and
stopped ones resumed, so a stopped report goes on where it was. Runs of the default features go
to runs/<variant>-seed<k> (where the notebooks look), the others to runs/<features>/...
--kept reads the runs' results.json as lab/bench/headline.py --keep copied them instead (the
README's headline comes from the same copies), named as taskexp.py names its folders
(ours-relations-seedK for the relations); a feature set other than the default may be kept for
ours alone.
Writes lab/RESULTS.md (mean +- std over seeds, the targets checked against them, the
machine and the wall-clock time; beside the shapes the families in which blocks that no goal names
must move, and the shapes in worlds of more blocks, for runs that measured them), its figures in
lab/results/, and appends
lab/discussion.md, the team's reading of the numbers, which is written by hand.
"""
import argparse
import json
import os
import platform
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import build_order  # noqa: E402
from run_seeds import KEPT, kept_name, load, pm, run_dir, run_one, split_argv  # noqa: E402

LAB = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))     # lab/: the report, notes

from env2d import BlockWorld  # noqa: E402
from taskexp_cli.report import (  # noqa: E402
    DPI,
    FAMILY_TITLES,
    FIGURES,
    histogram_figure,
    rates_by_blocks,
)
from taskexp_lib.config import Config, saved_config  # noqa: E402
from taskexp_lib.shapes import eval_tasks, site_free  # noqa: E402

# The paper's numbers (shared/paper/README.md): Table 1 by round 1-3, Table 2 by round 1-3,
# Table 3 after round 1; direct PPO: 0% on every shape (sec 5.3).
PAPER_T1 = {"high_goal_tasks": [12, 18, 938], "mean_episode_length": [2.5, 5, 7.6]}
PAPER_T2 = {"I": [93.7, 95.6, 89.3], "Y": [1.5, 33.5, 43.8], "3T": [58.2, 93.5, 98.2]}
PAPER_T3 = {"no-restrict": [0.3, 4.1, 38.7], "init2new": [7.3, 0.0, 0.0],
            "end2new": [79.4, 20.3, 59.4], "ours": [93.7, 1.0, 58.2],
            "direct-ppo": [0.0, 0.0, 0.0]}
VARIANTS = ("ours", "direct-ppo", "end2new", "init2new", "no-restrict")
NAMES = {"ours": "ours: argmax V(sT, g) - V(s0, g)", "end2new": "end2new: argmax V(sT, g)",
         "init2new": "init2new: argmin V(s0, g)", "no-restrict": "w/o restriction",
         "direct-ppo": "direct PPO on the evaluation tasks"}


def paper(values, k, digits=1, unit="%"):
    """The paper's figure for round k (1-based), or a dash where it has none."""
    return f"{values[k - 1]:.{digits}f}{unit}" if 1 <= k <= len(values) else "-"


def mean_layer(hist):
    """Mean highest-goal layer of a round's tasks, from its histogram (layer 0 = the table)."""
    return float(np.average(np.arange(len(hist)), weights=hist)) if sum(hist) else 0.0


def success(run, k, shape=None):
    """Zero-shot success (%) of a run after round k: one shape, or the mean over the shapes."""
    ev = run["rounds"][k]["eval"]
    return 100 * (ev[shape] if shape else np.mean(list(ev.values())))


def family_success(run, k):
    """Zero-shot success (%) after round k of a run on each task of the families in which blocks
    that no goal names must move (taskexp_lib/shapes.py, FAMILIES): {family: {task: rate}}, or {}
    for a run made before they were measured (a family without tasks left out)."""
    return {family: {task: 100 * rate for task, rate in rates.items()}
            for family, rates in run["rounds"][k].get("families", {}).items() if rates}


def family_means(run, k):
    """Each family's zero-shot success (%) after round k of a run, the mean over its tasks:
    {family: mean}, or {} for a run made before the families were measured."""
    return {family: float(np.mean(list(rates.values())))
            for family, rates in family_success(run, k).items()}


def blocks_success(run, k, n, shape=None):
    """Zero-shot success (%) after round k in the world of n blocks (the run's own, or one of
    cfg.eval_blocks, with the same weights): one shape, or the mean over the shapes; None for a
    run that did not measure n."""
    rates = rates_by_blocks(run["rounds"][k], run["config"]["n_blocks"]).get(str(n))
    if rates is None:
        return None
    return 100 * (rates[shape] if shape else float(np.mean(list(rates.values()))))


def site_free_share(run, n):
    """{shape: % of the run's evaluation scenes with n blocks whose site was free at the start}
    (shapes.site_free: no block stood where the shape needs the ground)."""
    cfg = saved_config(run["config"])
    tasks = eval_tasks(cfg, BlockWorld(n, drop=cfg.action == "drop"))
    return {s: 100 * np.mean([site_free(s0, g) for s0, g in scenes]) for s, scenes in tasks.items()}


def table_blocks(runs, rounds, shapes):
    """The held-out shapes in worlds of other block counts, the weights learnt in the runs' own,
    round by round; and how often each world's scenes left the shape's site free."""
    counts = [runs[0]["config"]["n_blocks"], *runs[0]["config"].get("eval_blocks", [])]
    out = ["| round | blocks |" + "".join(f" {s} |" for s in shapes) + " mean over shapes |",
           "|---" * (3 + len(shapes)) + "|"]
    out += [f"| {k} | {n} |" + "".join(f" {pm([blocks_success(r, k, n, s) for r in runs], '%')} |"
                                       for s in [*shapes, None])
            for k in range(rounds + 1) for n in counts]
    free = {n: [site_free_share(r, n) for r in runs] for n in counts}
    out += [f"| scenes whose site was free | {n} |"
            + "".join(f" {pm([f[s] for f in free[n]], '%')} |" for s in shapes)
            + f" {pm([np.mean(list(f.values())) for f in free[n]], '%')} |" for n in counts]
    return out


def picks_reached(rows):
    """The share (%) of equation (1)'s picks that verification reached, mean +- std over seeds,
    or a dash for a round without task expansion (or a run older than the measurement)."""
    shares = [w.get("expansion", {}).get("picks_reached") for w in rows]
    return "-" if None in shares else pm([100 * s for s in shares], "%")


def feasibility(out, cfg, tasks):
    """lab/bench/feasible_goals.py on the round-0 critic of the run in `out` (settings cfg, as its
    results.json saves them): how many of the goals its selection rule picks (equation (1), or
    the run's ablation) one drop can meet. Kept in the run's folder, so a report written again
    reuses it."""
    path = os.path.join(out, "feasible_goals.json")
    if not os.path.exists(path):
        rule = ["--select", cfg["select"]] + ([] if cfg["restrict"] else ["--no-restrict"])
        script = os.path.join(os.path.dirname(os.path.abspath(__file__)), "feasible_goals.py")
        subprocess.run([sys.executable, script, os.path.join(out, "round0.npz"), "--tasks",
                        str(tasks), "--json", path, *rule], check=True, capture_output=True)
    with open(path) as f:
        return json.load(f)


def first_moves(out, rounds, episodes):
    """The actor's leading indicator (lab/bench/build_order.py) on each round's checkpoint of the
    run in `out`, on its first `episodes` evaluation scenes per shape (the run's eval_episodes)
    -> {round: {shape: {"first_move": {kind: share}, ...}}}. Kept in the run's folder as
    feasibility is."""
    path = os.path.join(out, "build_order.json")
    if not os.path.exists(path):
        script = os.path.join(os.path.dirname(os.path.abspath(__file__)), "build_order.py")
        checkpoints = [os.path.join(out, f"round{k}.npz") for k in range(rounds + 1)]
        subprocess.run([sys.executable, script, *checkpoints, "--episodes", str(episodes),
                        "--json", path], check=True, capture_output=True)
    with open(path) as f:
        by_checkpoint = json.load(f)
    return {str(k): by_checkpoint[c] for k, c in enumerate(sorted(
        by_checkpoint, key=lambda c: int(os.path.basename(c)[5:-4])))}


def right_first(run, k, shape):
    """The share (%) of the evaluation scenes whose first move after round k is "right"."""
    return 100 * run["build_order"][str(k)][shape]["first_move"]["right"]


def table_first_moves(runs, rounds, shapes):
    """The actor's indicator round by round, mean +- std over seeds."""
    out = ["| round |" + "".join(f" {s}: right / higher goal |" for s in shapes),
           "|---" * (1 + len(shapes)) + "|"]
    for k in range(rounds + 1):
        cell = lambda s, kind: pm([100 * r["build_order"][str(k)][s]["first_move"][kind]
                                   for r in runs], "%")
        out.append(f"| {k} |" + "".join(f" {cell(s, 'right')} / {cell(s, 'higher goal')} |"
                                        for s in shapes))
    return out


def table_families(runs, rounds):
    """The families of blocks that no goal names: each family's mean over its tasks round by
    round, then each of its tasks after the last round, mean +- std over seeds (a dash for a
    round some run did not measure them in)."""
    families = family_success(runs[0], rounds)
    cell = lambda k, f: (pm([family_means(r, k)[f] for r in runs], "%")
                         if all(f in family_means(r, k) for r in runs) else "-")
    out = ["| round |" + "".join(f" {f}: mean over its tasks |" for f in families),
           "|---" * (1 + len(families)) + "|"]
    out += [f"| {k} |" + "".join(f" {cell(k, f)} |" for f in families) for k in range(rounds + 1)]
    return out + ["", f"| after round {rounds} | task | zero-shot success |", "|---|---|---|"] + [
        f"| {f} | {t} | {pm([family_success(r, rounds)[f][t] for r in runs], '%')} |"
        for f, tasks in families.items() for t in tasks]


def table_feasible(runs):
    """The leading indicator: the round-0 critic's picks, mean +- std over seeds."""
    cell = lambda key: pm([100 * r["feasible"][key] for r in runs], "%")
    return ["| round-0 critic | feasible among all candidates | feasible among the chosen g* | "
            "g* reached from s_T | reached, feasible picks | reached, infeasible picks |",
            "|---|---|---|---|---|---|",
            f"| `lab/bench/feasible_goals.py` | {cell('feasible_candidates')} | "
            f"{cell('feasible_picks')} | {cell('reached')} | {cell('reached_feasible')} | "
            f"{cell('reached_infeasible')} |"]


def table1(runs, rounds):
    out = ["| round | generated tasks | # high goals (>= 3 above ground) | paper | mean episode "
           "length | paper | mean highest goal layer | eq. (1) picks reached |",
           "|---|---|---|---|---|---|---|---|"]
    for k in range(rounds + 1):
        rows = [r["rounds"][k] for r in runs]
        out.append(f"| {k}{' (base)' if k == 0 else ''} | {pm([w['tasks'] for w in rows])} | "
                   f"{pm([w['high_goal_tasks'] for w in rows])} | "
                   f"{paper(PAPER_T1['high_goal_tasks'], k, 0, '')} | "
                   f"{pm([w['mean_episode_length'] for w in rows], '', 2)} | "
                   f"{paper(PAPER_T1['mean_episode_length'], k, 1, '')} | "
                   f"{pm([mean_layer(w['max_height_hist']) for w in rows], '', 2)} | "
                   f"{picks_reached(rows)} |")
    return out


def table2(runs, rounds, shapes, with_paper=True):
    head = "".join(f" {s} |" + (" paper |" if with_paper else "") for s in shapes)
    out = [f"| round |{head} mean over shapes |",
           "|---" * (2 + len(shapes) * (1 + with_paper)) + "|"]
    for k in range(rounds + 1):
        cells = "".join(f" {pm([success(r, k, s) for r in runs], '%')} |"
                        + (f" {paper(PAPER_T2.get(s, []), k)} |" if with_paper else "")
                        for s in shapes)
        out.append(f"| {k} |{cells} {pm([success(r, k) for r in runs], '%')} |")
    return out


def table3(by_variant, k, shapes):
    out = [f"| after round {k} |" + "".join(f" {s} | paper |" for s in shapes)
           + " mean | its picks reached |", "|---" * (3 + 2 * len(shapes)) + "|"]
    seeds = lambda runs: [r["config"]["seed"] for r in runs]
    for v, runs in by_variant.items():
        name = NAMES[v] + ("" if seeds(runs) == seeds(by_variant["ours"]) else
                           " (seeds " + ", ".join(map(str, seeds(runs))) + ")")
        cells = "".join(f" {pm([success(r, k, s) for r in runs], '%')} | "
                        f"{PAPER_T3[v][i]:.1f}% |" for i, s in enumerate(shapes))
        out.append(f"| {name} |{cells} {pm([success(r, k) for r in runs], '%')} | "
                   f"{picks_reached([r['rounds'][k] for r in runs])} |")
    return out


def targets(by_variant, rounds, shapes):
    """The targets of 2026-12-05, each with what was measured and whether it holds (seed means)."""
    ours = by_variant["ours"]
    mean = lambda k, runs=ours, shape=None: np.mean([success(r, k, shape) for r in runs])
    zs = [mean(k) for k in range(rounds + 1)]
    paper_means = [np.mean([PAPER_T2[s][k] for s in shapes]) for k in range(rounds)]
    spread = np.std([success(r, rounds) for r in ours])
    high = [np.mean([r["rounds"][k]["high_goal_tasks"] for r in ours]) for k in (0, rounds)]
    out = [(f"zero-shot mean over shapes >= the paper's, round {k}", f"{zs[k]:.0f}% vs "
            f"{paper_means[k - 1]:.0f}%", zs[k] >= paper_means[k - 1])
           for k in range(1, rounds + 1)]
    out += [(f"round-{rounds} mean over shapes: spread over seeds <= 10 points",
             f"{spread:.0f} points", spread <= 10),
            (f"every shape >= 60% after round {rounds}",
             ", ".join(f"{s} {mean(rounds, shape=s):.0f}%" for s in shapes),
             all(mean(rounds, shape=s) >= 60 for s in shapes)),
            ("the mean never falls from one round to the next",
             " -> ".join(f"{z:.0f}%" for z in zs), all(np.diff(zs) >= 0)),
            (f"tasks with >= 3 high goals >= 300 in round {rounds}, rising from round 0",
             f"{high[0]:.0f} -> {high[1]:.0f}", high[1] >= 300 and high[1] > high[0])]
    if all("build_order" in r for r in ours):
        worst = min(np.mean([right_first(r, k, s) for r in ours])
                    for k in range(1, rounds + 1) for s in shapes)
        out.append(("first move right >= 90% of each shape's scenes after every round from 1 "
                    "(lab/bench/build_order.py; lowest shown)", f"{worst:.0f}%", worst >= 90))
    if all(family_means(r, rounds) for r in ours):             # runs made before: no families
        means = {f: np.mean([family_means(r, rounds)[f] for r in ours])
                 for f in family_means(ours[0], rounds)}
        tasks = {f: {t: np.mean([family_success(r, rounds)[f][t] for r in ours]) for t in rates}
                 for f, rates in family_success(ours[0], rounds).items()}
        out += [(f"each family's mean over its tasks >= 80% after round {rounds} (blocks that no "
                 "goal names must move)", ", ".join(f"{f} {m:.0f}%" for f, m in means.items()),
                 all(m >= 80 for m in means.values())),
                (f"every task of the families >= 60% after round {rounds}",
                 "; ".join(f"{f}: " + ", ".join(f"{t} {m:.0f}%" for t, m in rates.items())
                           for f, rates in tasks.items()),
                 all(m >= 60 for rates in tasks.values() for m in rates.values()))]
    if all(blocks_success(r, rounds, 7) is not None for r in ours):
        m6, m7 = (np.mean([blocks_success(r, rounds, n) for r in ours]) for n in (6, 7))
        out.append((f"round-{rounds} mean over shapes with 7 blocks within 10 points of 6 blocks "
                    "(the same weights)", f"{m7:.0f}% vs {m6:.0f}%", m6 - m7 <= 10))
    if all("feasible" in r for r in ours):
        picks = np.mean([100 * r["feasible"]["feasible_picks"] for r in ours])
        out.insert(0, ("feasible among equation (1)'s picks, round-0 critic >= 75%",
                       f"{picks:.0f}%", picks >= 75))
    if "direct-ppo" in by_variant:           # after the last round direct PPO was run for
        k = min(rounds, len(by_variant["direct-ppo"][0]["rounds"]) - 1)
        theirs = {s: mean(k, by_variant["direct-ppo"], s) for s in shapes}
        out.append((f"ours above direct PPO on every shape after round {k}",
                    ", ".join(f"{s} {mean(k, shape=s):.0f}% vs {v:.0f}%"
                              for s, v in theirs.items()),
                    all(mean(k, shape=s) > v for s, v in theirs.items())))
    for v, strict in (("no-restrict", True), ("init2new", True), ("end2new", False)):
        if v in by_variant:
            a, b = mean(1), mean(1, by_variant[v])
            out.append((f"ours {'>' if strict else '>='} {NAMES[v]} on the mean over shapes, "
                        "round 1", f"{a:.0f}% vs {b:.0f}%", a > b if strict else a >= b))
    return ["| target | measured (mean over seeds) | |", "|---|---|---|"] + \
        [f"| {t} | {m} | {'met' if ok else '**missed**'} |" for t, m, ok in out]


def machine():
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if "model name" in line)
    except (OSError, StopIteration):
        pass
    return f"{cpu}, {os.cpu_count()} cores, {platform.system()}, Python {platform.python_version()}"


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--features", nargs="+", default=["plain", "relations"],
                   choices=["plain", "relations"])
    p.add_argument("--variants", nargs="+", choices=VARIANTS, default=list(VARIANTS))
    p.add_argument("--rounds", type=int, default=Config.rounds)
    p.add_argument("--ablation-rounds", type=int, default=1,
                   help="rounds of end2new, init2new and w/o restriction (Table 3)")
    p.add_argument("--direct-rounds", type=int, default=Config.rounds,
                   help="rounds of direct PPO (--kept: as many as the kept runs have)")
    p.add_argument("--root", default="runs")
    p.add_argument("--jobs", type=int, default=2, help="runs at a time (one core each)")
    p.add_argument("--scale", default=None, help="passed to taskexp.py (smaller budgets)")
    p.add_argument("--kept", nargs="?", const=KEPT, metavar="DIR",
                   help="write the report from the runs kept in DIR (default lab/results/runs/, "
                        "where lab/bench/headline.py --keep copies them) instead of making them")
    p.add_argument("--out", default=os.path.join(LAB, "RESULTS.md"))
    p.add_argument("--figures", default=os.path.join(LAB, "results"), help="folder for the figures")
    ours, theirs = split_argv(sys.argv[1:])        # after `--`: flags for every new run
    a = p.parse_args(ours)
    if "ours" not in a.variants:
        p.error("--variants must include ours: every table compares with it")
    os.makedirs(a.figures, exist_ok=True)
    shapes = list(Config.shapes)
    start = time.time()
    jobs = [(f, v, s) for f in a.features for v in a.variants for s in a.seeds]
    rounds_of = lambda v: {"ours": a.rounds, "direct-ppo": a.direct_rounds}.get(v,
                                                                             a.ablation_rounds)
    # --kept: each variant's kept runs read once, by seed (the relations' runs: ours-relations)
    by_seed = {(f, v): {r["config"]["seed"]: r for r in load(kept_name(v, f), a.kept)}
               for f in a.features for v in a.variants} if a.kept else {}
    if a.kept:        # the other feature set, and the ablations, may be kept for fewer seeds
        jobs = [(f, v, s) for f, v, s in jobs if s in by_seed[f, v] or (
            f == Config.features and (v == "ours" or not by_seed[f, v]))]    # kept(): missing

    def kept(job):
        f, v, s = job
        r, rounds = by_seed[f, v].get(s), a.rounds if v == "ours" else 1    # as many as kept
        if r is None or r["config"]["features"] != f or len(r["rounds"]) <= rounds:
            raise SystemExit(f"{a.kept} keeps no {f} {v} run of seed {s} with {rounds} rounds: "
                             f"make it (lab/bench/run_seeds.py), keep it (lab/bench/headline.py)")
        return job, r

    def one(job):
        f, v, s = job
        root = a.root if f == Config.features else os.path.join(a.root, f)
        os.makedirs(root, exist_ok=True)
        extra = ["--features", f] + (["--scale", a.scale] if a.scale else []) + theirs
        print(f"[{time.time() - start:5.0f}s] {f} {v} seed {s}", flush=True)
        results = run_one(v, s, rounds_of(v), root, extra)[2]
        if v == "ours":                   # the leading indicators: the critic's, the actor's
            results["feasible"] = feasibility(run_dir(v, s, root), results["config"],
                                              max(50, int(600 * float(a.scale or 1))))
            results["build_order"] = first_moves(run_dir(v, s, root), rounds_of(v),
                                                 results["config"]["eval_episodes"])
        return job, results

    if a.kept:
        done = dict(map(kept, jobs))
    else:
        with ThreadPoolExecutor(a.jobs) as pool:
            done = dict(pool.map(one, jobs))
    seeds = " ".join(map(str, a.seeds))
    cmd = "python lab/bench/reproduce.py " + " ".join(sys.argv[1:])
    where = (f"the runs kept in `{os.path.relpath(a.kept)}/`, each made on the machine it names: "
             + "; ".join(sorted({r["machine"] for r in done.values()})) if a.kept else machine())
    md = ["# Reproduction report", "",
          f"Written by `{cmd.strip()}` on {time.strftime('%Y-%m-%d')}: the default settings "
          f"(`python taskexp.py --rounds {a.rounds}`" + (f" --scale {a.scale}" if a.scale else "")
          + f"), seeds {seeds}, every figure mean +- std over the seeds. Machine: {where}. "
          "Results differ between machines (BLAS kernels differ), so compare spreads, not one "
          "seed's digits.", ""]
    for f in a.features:
        by_variant = {v: [done[(f, v, s)] for s in a.seeds if (f, v, s) in done]
                      for v in a.variants}
        by_variant = {v: runs for v, runs in by_variant.items() if runs}
        if not by_variant:
            print(f"{a.kept} keeps no {f} runs: RESULTS.md leaves them out")
            continue
        ours = by_variant["ours"]
        clock = {v: pm([r["wallclock"]["total_s"] for r in runs]) for v, runs in by_variant.items()}
        title = {"plain": "self-attention over plain features (the default)",
                 "relations": "hand-computed relations (--features relations)"}[f]
        md += [f"## {title}", "",
               "Wall-clock per run, seconds ("
               + ("as each was made" if a.kept else "two runs at a time, one worker each") + "): "
               + ", ".join(f"{v} {c}" for v, c in clock.items()) + ".", "",
               "### Targets", "", *targets(by_variant, a.rounds, shapes), "",
               "### Does equation (1) pick goals the policy can reach?", "",
               "Of the K one-alteration candidates at s_T, how many one drop can meet, and how "
               "many of the goals equation (1) picks (600 base tasks per seed, judged by the "
               "hand-computed relations, which plain features never show the agent):", "",
               *table_feasible(ours), "",
               "### Table 1: generated tasks (ours)", "", *table1(ours, a.rounds), ""]
        for key, fname, title, xlabel, first, log in FIGURES:
            path = os.path.join(a.figures, f"{fname.split('_')[0]}_{f}.png")    # fig1_plain.png
            per_round = [(k, [r["rounds"][k][key] for r in ours]) for k in range(a.rounds + 1)]
            fig = histogram_figure(per_round, title, xlabel, first, log)
            fig.savefig(path, dpi=DPI)
            link = os.path.relpath(path, os.path.dirname(os.path.abspath(a.out)))
            md += [f"{title}:", "", f"![{title}]({link})", ""]
        md += ["### Table 2: zero-shot success (ours)", "", *table2(ours, a.rounds, shapes), ""]
        if all(family_means(r, a.rounds) for r in ours):      # runs made before: no families
            md += ["### Blocks no goal names: zero-shot success of the families", "",
                   "Not in the paper (taskexp_lib/shapes.py, FAMILIES): "
                   + "; ".join(FAMILY_TITLES.get(f, f) for f in family_means(ours[0], a.rounds))
                   + ". Each family's mean over its tasks round by round, then each task after "
                   f"round {a.rounds}:", "", *table_families(ours, a.rounds), ""]
        if all(r["rounds"][a.rounds].get("blocks") for r in ours):  # runs made before: none
            md += ["### Worlds of other block counts: zero-shot success, the same weights", "",
                   "Not in the paper: the held-out shapes in worlds of more blocks than the runs "
                   "learnt in (the network is self-attention over any number of block tokens), "
                   "round by round; the last rows give how often each world's scenes left the "
                   "shape's site free (a crowded table may not, and the policy does not move "
                   "blocks that no goal names):", "", *table_blocks(ours, a.rounds, shapes), ""]
        if all("build_order" in r for r in ours):
            md += ["### The order of the moves (lab/bench/build_order.py)", "",
                   "The greedy policy's first move on the evaluation scenes after each round: "
                   "a block of the lowest layer still to build, at its goal's x (right), or a "
                   "block whose goal lies above one still to build (higher goal):", "",
                   *table_first_moves(ours, a.rounds, shapes), ""]
        if "direct-ppo" in by_variant:
            direct = by_variant["direct-ppo"]
            md += ["### Direct PPO on the evaluation tasks (sec 5.3; paper: 0%)", "",
                   *table2(direct, len(direct[0]["rounds"]) - 1, shapes, with_paper=False), ""]
        if f == Config.features:
            run_cfg = saved_config(ours[0]["config"])     # the scenes the runs were tried on
            luck = build_order.chance(run_cfg, orders=10)
            md += ["Chance level (`build_order.chance`): the base skill done perfectly, each "
                   "goal block dropped once at its goal's x in a random order, played in the "
                   f"world (10 orders on each of the {run_cfg.eval_episodes} evaluation scenes "
                   "per shape): "
                   + ", ".join(f"{s} {100 * v:.1f}%" for s, v in luck.items())
                   + ". Only the orders that build every support first succeed.", ""]
        if len(by_variant) == 1:                          # ours alone: no ablation kept
            continue
        md += ["### Table 3: goal selection and the restriction", ""]
        for k in sorted({1, min(a.rounds, a.ablation_rounds)}):
            md += [*table3(by_variant, k, shapes), ""]
    runs_s = sum(r["wallclock"]["total_s"] for r in done.values())
    md += [f"The {len(done)} runs took {runs_s:.0f} s of wall-clock in all, "
           + ("as they were made." if a.kept else f"run {a.jobs} at a time; this invocation took "
              f"{time.time() - start:.0f} s (finished runs are reused)."), ""]
    notes = os.path.join(LAB, "discussion.md")
    if os.path.exists(notes):
        with open(notes) as fh:
            md += [fh.read()]
    with open(a.out, "w") as fh:
        fh.write("\n".join(md))
    print(f"wrote {a.out} and the figures in {a.figures}/")


if __name__ == "__main__":
    main()
