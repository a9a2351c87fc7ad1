"""lab/bench/capstone.py -- the course's capstone (exercise 12) on several seeds: does its bar hold?

    python lab/bench/capstone.py                       # the library's pieces, seeds 0 1 2
    python lab/bench/capstone.py --pieces instructor   # the instructor notebooks' solutions
    python lab/bench/capstone.py --seeds 3 4 --json capstone.json
    python lab/bench/capstone.py --wrong new-only      # one plausible wrong piece plugged in

Runs course.ex12.grow (two rounds of task expansion and self-distillation from the round-0 agent
of course/data/round0.npz, at the capstone's budget) on each seed and prints, per round, the moves
per generated demonstration and zero-shot success on the held-out shapes, then each seed's margin
over the check's bars (GROWTH, LIFT). --pieces instructor takes every function from the instructor
notebooks (course/notebooks/), as a kit with the solutions pasted in runs them: their float paths
differ from the library's, so their figures differ too. --wrong puts one plausible mistake in
place of the right piece: "no-prefix", an expansion step whose demonstrations are the run from
s_T alone (relabelled on failure), or "new-only", PPO on the new tasks alone (no old ones).
"""
import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
import course  # noqa: E402
import taskexp  # noqa: E402
from course import ex12  # noqa: E402


def no_prefix(agent, found, cfg, env, short_envs, rng, pieces):
    """An expansion step whose demonstration is the run from s_T alone: it forgets s0 -> s_T."""
    cands = [taskexp.candidates(t, env, rng, cfg, pieces.alter) for t in found]
    picks = [c[pieces.select_goal(agent, t.states[0], t.states[-1], c)]
             for t, c in zip(found, cands)]
    runs = taskexp.run_episodes(agent, [(t.states[-1], g) for t, g in zip(found, picks)],
                                short_envs, rng, values=False)
    demos = [r if r.success else pieces.relabel(r, env) for r in runs]
    return [d for d in demos if d is not None], [r.success for r in runs]


def new_only(run, demos, rng):
    """PPO's tasks without old ones: the new tasks alone."""
    new, _ = taskexp.distillation_tasks(run, demos, rng)
    return new, []


WRONG = {"no-prefix": ("expansion_step", no_prefix), "new-only": ("distillation_tasks", new_only)}


NAMES = course.ARGUMENTS["ex12"]          # check_ex12's arguments, before the ActionDist


def arguments(which, wrong=None):
    """check_ex12's arguments: the library's reference, or the instructor notebooks' functions."""
    args = ([course.REFERENCE[f] for f in NAMES] + [None] if which == "library" else
            course.functions("ex12", course.NOTEBOOK_DIR))
    if wrong:
        name, fn = WRONG[wrong]
        args[NAMES.index(name)] = fn
    return args


def run(which, seed, wrong=None):
    (mlp_backward, gae, ppo_loss, alter, select_goal, relabel, attention_backward, _join,
     expansion_step, distillation_data, distillation_tasks, dist) = arguments(which, wrong)
    pieces = ex12.capstone_pieces(gae, ppo_loss, alter, select_goal, relabel, expansion_step,
                                  distillation_data, distillation_tasks)
    t0 = time.time()
    records = ex12.grow(pieces, seed, log=lambda *a: None, mlp_backward=mlp_backward,
                        attention_backward=attention_backward, dist=dist)
    return dict(seed=seed, seconds=round(time.time() - t0, 1), records=records,
                problem=ex12.problem_of(records))


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--pieces", choices=["library", "instructor"], default="library")
    p.add_argument("--wrong", choices=sorted(WRONG), help="one wrong piece in place of the right")
    p.add_argument("--json", help="also write the figures to this file")
    a = p.parse_args()
    out = []
    for seed in a.seeds:
        r = run(a.pieces, seed, a.wrong)
        out.append(r)
        first, last = r["records"][0], r["records"][-1]
        lift = max(last["eval"][s] - first["eval"][s] for s in first["eval"])
        which = a.pieces + (f", {a.wrong}" if a.wrong else "")
        print(f"seed {seed} ({which} pieces, {r['seconds']:.0f} s): moves per demonstration "
              + " -> ".join(f"{x['moves']:.2f}" for x in r["records"]) + "; zero-shot "
              + "; ".join(f"{s} " + " -> ".join(f"{x['eval'][s]:.0%}" for x in r["records"])
                          for s in first["eval"])
              + f"; best gain {100 * lift:.0f} point(s) (bar {100 * ex12.LIFT:.0f}): "
              + ("PASS" if r["problem"] is None else f"FAIL ({r['problem']})"))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
