"""The README's headline, one table of the default run and Table 3's rows against the paper, and
the longer comparison in lab/notes.md (every variant, Tables 1-3 round by round), both written
from the runs they name.

    python lab/bench/headline.py --keep runs/ours-seed0 runs/ours-seed1 runs/ours-seed2
    python lab/bench/run_seeds.py --rounds 1 --variants end2new no-restrict direct-ppo
    python lab/bench/run_seeds.py --rounds 3 --variants init2new
    python lab/bench/headline.py --keep runs/end2new-seed0 ...     # Table 3: the ablations
    python lab/bench/headline.py                    # print it from the kept copies
    python lab/bench/headline.py --readme README.md  # write it into the README between its markers
    python lab/bench/headline.py --notes lab/notes.md  # the comparison, into the lab notes

--keep copies each finished run's results.json, with its round-0 critic's feasibility
(lab/bench/feasible_goals.py, 600 base tasks, with the run's own selection rule) and each round's
first moves (lab/bench/build_order.py), both measured once and cached in the run's folder, and
this machine's name (keep runs where they were made), to lab/results/runs/<run>.json. Those copies
are committed: the headline is made from them alone, and tests/test_bench.py checks that the
README and the notes show exactly what they say. lab/results/runs/main-9032628/ keeps the runs
of the code before 2026-12-05 (its default then, the relations, the ablations), for comparison.
"""
import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import reproduce  # noqa: E402
from reproduce import PAPER_T1, PAPER_T2, success, table1, table2, table3  # noqa: E402
from run_seeds import FLAGS, KEPT, kept_name, load, pm  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
BEGIN = "<!-- headline: written by `python lab/bench/headline.py --readme README.md` -->"
END = "<!-- end of the headline -->"


def keep(run_dirs, kept=KEPT, tasks=600):
    """Copy finished runs (results.json + feasibility + machine) to kept/<run>.json."""
    os.makedirs(kept, exist_ok=True)
    for out in run_dirs:
        with open(os.path.join(out, "results.json")) as f:
            results = json.load(f)
        if len(results["rounds"]) != results["config"]["rounds"] + 1:
            raise SystemExit(f"{out}: not finished ({len(results['rounds']) - 1} of "
                             f"{results['config']['rounds']} rounds)")
        results.update(feasible=reproduce.feasibility(out, results["config"], tasks),
                       build_order=reproduce.first_moves(out, results["config"]["rounds"],
                                                         results["config"]["eval_episodes"]),
                       machine=reproduce.machine())
        path = os.path.join(kept, os.path.basename(os.path.normpath(out)) + ".json")
        with open(path, "w") as f:
            json.dump(results, f, indent=1)
        print("kept", os.path.relpath(path, ROOT))


def load_all(kept=KEPT):
    """{name: its kept runs} for every variant of the headline and every ablation of Table 3."""
    return {name: load(name, kept) for name in kept_names()}


VARIANTS = (("ours", "the default"),
            ("ours-nolabels", "`--label-tasks 0`: V(s, g) from PPO alone, as in the paper"),
            ("main-9032628/ours", "the default before 2026-12-05 (main 9032628: base goals "
             "anywhere, one order per demonstration, layer codes, later labels)"),
            ("main-9032628/ours-relations", "the same with the stacking relations computed by "
             "hand as features (`--features relations`)"))
# Table 3's rows beside ours, each the default with one flag (run_seeds.FLAGS), kept as
# run_seeds.kept_name names them (no-restrict: ours-norestrict-seedS)
ABLATIONS = ("end2new", "init2new", "no-restrict", "direct-ppo")


def kept_names():
    """The names of every kept run the headline reads: its rows, then Table 3's ablations."""
    return list(dict.fromkeys([name for name, _ in VARIANTS] + [kept_name(v) for v in ABLATIONS]))


def headline(by_variant):
    """The README's headline as markdown lines: one table, zero-shot success of the default
    round by round and of Table 3's rows after round 1 (direct PPO: every round it was run
    for), each mean +- std over the seeds kept, next to the paper's; then the tall tasks
    generated, round by round, and the default's families of blocks that no goal names (where
    its runs measured them)."""
    ours = by_variant["ours"]
    rounds, shapes = ours[0]["config"]["rounds"], list(ours[0]["config"]["shapes"])
    every = range(1, rounds + 1)
    paper = lambda k: np.mean([PAPER_T2[s][k - 1] for s in shapes])
    out = ["| zero-shot success, mean over " + ", ".join(f'"{s}"' for s in shapes) + " |"
           + "".join(f" round {k} |" for k in every) + f" round {rounds} by shape |"
           + " the paper |", "|---" * (rounds + 3) + "|"]
    by_shape = " / ".join(f"{np.mean([success(r, rounds, s) for r in ours]):.0f}" for s in shapes)
    out.append("| **ours**, `python taskexp.py --rounds 3` |"
               + "".join(f" {pm([success(r, k) for r in ours], '%')} |" for k in every)
               + f" {by_shape} (%) | " + " / ".join(f"{paper(k):.0f}" for k in every) + " (%) |")
    for v in ABLATIONS:                  # Table 3 after round 1; direct PPO as long as it ran
        runs = by_variant.get(kept_name(v))
        if runs:
            ran = min(len(r["rounds"]) for r in runs) - 1
            last = (" / ".join(f"{np.mean([success(r, rounds, s) for r in runs]):.0f}"
                               for s in shapes) + " (%)") if ran >= rounds else "-"
            out.append(f"| {reproduce.NAMES[v]} (`{' '.join(FLAGS[v])}`) |"
                       + "".join(f" {pm([success(r, k) for r in runs], '%')} |" if k <= ran
                                 else " - |" for k in every)
                       + f" {last} | {np.mean(reproduce.PAPER_T3[v]):.0f}% after round 1 |")
    seeds = ", ".join(str(r["config"]["seed"]) for r in ours)
    tall = " / ".join(f"{np.mean([r['rounds'][k]['high_goal_tasks'] for r in ours]):.0f}"
                      for k in every)
    out += ["", f"Seeds {seeds}, mean +- std over the seeds. The paper's figures are from a "
            "3D world with about 150M PPO steps per round; for the ablations, the mean of its "
            "Table 3. Tasks generated with >= 3 goals above the ground, rounds "
            f"{' / '.join(map(str, every))}: {tall} (the paper: "
            f"{' / '.join(map(str, PAPER_T1['high_goal_tasks']))})."]
    means = reproduce.family_means
    if all(means(r, k) for r in ours for k in every):           # runs made before: no families
        family = lambda f: " / ".join(f"{np.mean([means(r, k)[f] for r in ours]):.0f}"
                                      for k in every)
        out += ["", f"Blocks no goal names, after rounds {' / '.join(map(str, every))}: "
                + ", ".join(f"{f} {family(f)}%" for f in means(ours[0], rounds))
                + f" (mean over the family's tasks and seeds {seeds})."]
    return out


def comparison(by_variant):
    """The lab notes' comparison as markdown lines: the default next to the run without labelled
    outcomes and the code before, each mean +- std over the seeds kept, then the default's
    Tables 1 and 2 round by round and Table 3."""
    ours = by_variant["ours"]
    rounds, shapes = ours[0]["config"]["rounds"], list(ours[0]["config"]["shapes"])
    earlier, every = range(1, rounds), " / ".join(map(str, range(1, rounds + 1)))
    zero_shot = ["| zero-shot success |" + "".join(f" round {k} |" for k in earlier)
                 + "".join(f" round {rounds}: {s} |" for s in shapes) + " mean over shapes |",
                 "|---" * (2 + len(earlier) + len(shapes)) + "|"]
    tasks = [f"| generated tasks | feasible among the picks (eq. (1) or the row's rule), round-0 "
             f"critic | picks reached, rounds {every} | tasks with >= 3 goals above the ground, "
             f"rounds {every} |",
             "|---|---|---|---|"]
    for name, label in VARIANTS:
        runs = by_variant.get(name)
        if not runs:
            continue
        if [r["config"]["seed"] for r in runs] != [r["config"]["seed"] for r in ours]:
            label += " (seeds " + ", ".join(str(r["config"]["seed"]) for r in runs) + ")"
        cells = [pm([success(r, k) for r in runs], "%") for k in earlier]
        cells += [pm([success(r, rounds, s) for r in runs], "%") for s in shapes]
        zero_shot.append(f"| {label} | {' | '.join(cells)} | "
                         f"**{pm([success(r, rounds) for r in runs], '%')}** |")
        per_round = lambda of: " / ".join(f"{np.mean([of(r['rounds'][k]) for r in runs]):.0f}"
                                          for k in range(1, rounds + 1))
        feasible = pm([100 * r["feasible"]["feasible_picks"] for r in runs], "%")
        tasks.append(f"| {label} | {feasible} | "
                     f"{per_round(lambda w: 100 * w['expansion']['picks_reached'])} (%) | "
                     f"{per_round(lambda w: w['high_goal_tasks'])} |")
    paper = lambda k, s=None: (PAPER_T2[s][k - 1] if s else
                               np.mean([PAPER_T2[s][k - 1] for s in shapes]))
    zero_shot.append("| the paper (3D, ~150M PPO steps per round) |"
                     + "".join(f" {paper(k):.0f}% |" for k in earlier)
                     + "".join(f" {paper(rounds, s):.0f}% |" for s in shapes)
                     + f" {paper(rounds):.0f}% |")
    tasks.append(f"| the paper | - | - | {' / '.join(map(str, PAPER_T1['high_goal_tasks']))} |")
    seeds = ", ".join(str(r["config"]["seed"]) for r in ours)
    made = {}                                                  # machine -> the runs made there
    for name in kept_names():
        for m in sorted({r["machine"] for r in by_variant.get(name) or []}):
            made.setdefault(m, []).append(f"`{name}-seedS`")
    where = (f"machine: {next(iter(made))}" if len(made) == 1 else
             "machines: " + "; ".join(f"{', '.join(runs)} on {m}" for m, runs in made.items()))
    return [f"`python taskexp.py --rounds {rounds} --seed S`, seeds {seeds}, mean +- std over the "
            f"seeds (the runs are kept in `lab/results/runs/`; {where}):", "",
            *zero_shot, "", *tasks, "",
            "The default, round by round: zero-shot success (Table 2) and the generated tasks "
            "(Table 1).", "",
            *table2(ours, rounds, shapes), "", *table1(ours, rounds), *ablations(by_variant)]


def ablations(by_variant):
    """Table 3 as markdown lines (none without kept ablation runs): after each round the ablation
    runs have, ours next to the ablations, each the default with one flag, over the same seeds."""
    rows = {v: by_variant.get(kept_name(v)) for v in ABLATIONS}
    rows = {"ours": by_variant["ours"], **{v: runs for v, runs in rows.items() if runs}}
    if len(rows) == 1:
        return []
    shapes = list(by_variant["ours"][0]["config"]["shapes"])
    rounds = {v: runs[0]["config"]["rounds"] for v, runs in rows.items() if v != "ours"}
    seeds = ", ".join(str(r["config"]["seed"]) for r in rows["ours"])
    out = ["", "Goal selection and the restriction (Table 3; the paper's is after round 1), and "
           "PPO directly on the evaluation tasks from the same base policy with the same PPO "
           "budget per round: `python taskexp.py --rounds R --seed S` with the flag of each row "
           f"in `lab/bench/run_seeds.py` (R: {', '.join(f'{v} {k}' for v, k in rounds.items())}), "
           f"seeds {seeds}; ours are the runs above."]
    for k in range(1, min(rounds.values()) + 1):
        out += ["", *table3(rows, k, shapes)]
    return out


def write_readme(path, lines, begin=BEGIN, end=END):
    """Replace the block between the markers begin and end (the headline's, or another
    generated block's: lab/bench/times.py) in the README (or notes) at `path` by `lines`."""
    with open(path) as f:
        text = f.read()
    if begin not in text or end not in text:
        raise SystemExit(f"{path} has no markers ({begin} ... {end})")
    head, rest = text.split(begin, 1)
    with open(path, "w") as f:
        f.write(head + "\n".join([begin, "", *lines, "", end]) + rest.split(end, 1)[1])


def readme_block(path, begin=BEGIN, end=END):
    """The lines between the markers of the README at `path` (what write_readme wrote)."""
    with open(path) as f:
        text = f.read()
    return text.split(begin, 1)[1].split(end, 1)[0].strip("\n").split("\n")


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--keep", nargs="+", metavar="RUN", help="finished run folders to keep first")
    p.add_argument("--readme", help="write the headline into this README between its markers")
    p.add_argument("--notes", help="write the comparison into these notes between its markers")
    a = p.parse_args()
    if a.keep:
        keep(a.keep)
    by_variant = load_all()
    if not by_variant["ours"]:
        raise SystemExit(f"no kept runs in {os.path.relpath(KEPT, ROOT)}: --keep RUN ... first")
    lines, notes = headline(by_variant), comparison(by_variant)
    print("\n".join(lines + [""] + notes))
    for path, block, what in ((a.readme, lines, "the headline"),
                              (a.notes, notes, "the comparison")):
        if path:
            write_readme(path, block)
            print(f"wrote {what} into {path}")


if __name__ == "__main__":
    main()
