"""lab/bench/capstone.py -- the course's capstone (exercise 12) on several seeds: does its bar hold?

    python lab/bench/capstone.py                       # the library's pieces, seeds 0 1 2
    python lab/bench/capstone.py --pieces instructor   # the instructor notebooks' solutions
    python lab/bench/capstone.py --seeds 3 4 --json capstone.json

Runs course.ex12.grow (two rounds of task expansion and self-distillation from the round-0 agent
of course/data/round0.npz, at the capstone's budget) on each seed and prints, per round, the moves
per generated demonstration and zero-shot success on the held-out shapes, then each seed's margin
over the check's bars (GROWTH, LIFT). --pieces instructor takes every function from the instructor
notebooks (course/notebooks/), as a kit with the solutions pasted in runs them: their float paths
differ from the library's, so their figures differ too.
"""
import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
import course  # noqa: E402
from course import ex12  # noqa: E402


def arguments(which):
    """check_ex12's arguments: the library's reference, or the instructor notebooks' functions."""
    if which == "library":
        R = course.REFERENCE
        names = ["mlp_backward", "gae", "ppo_loss", "alter", "select_goal", "relabel",
                 "attention_backward", "join", "expansion_step", "distillation_data",
                 "distillation_tasks"]
        return [R[f] for f in names] + [None]
    return course.functions("ex12", course.NOTEBOOK_DIR)


def run(which, seed):
    (mlp_backward, gae, ppo_loss, alter, select_goal, relabel, attention_backward, _join,
     expansion_step, distillation_data, distillation_tasks, dist) = arguments(which)
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
    p.add_argument("--json", help="also write the figures to this file")
    a = p.parse_args()
    out = []
    for seed in a.seeds:
        r = run(a.pieces, seed)
        out.append(r)
        first, last = r["records"][0], r["records"][-1]
        lift = max(last["eval"][s] - first["eval"][s] for s in first["eval"])
        print(f"seed {seed} ({a.pieces} pieces, {r['seconds']:.0f} s): moves per demonstration "
              + " -> ".join(f"{x['moves']:.2f}" for x in r["records"]) + "; zero-shot "
              + "; ".join(f"{s} " + " -> ".join(f"{x['eval'][s]:.0%}" for x in r["records"])
                          for s in first["eval"])
              + f"; best gain {100 * lift:.0f} points (bar {100 * ex12.LIFT:.0f}): "
              + ("PASS" if r["problem"] is None else f"FAIL ({r['problem']})"))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
