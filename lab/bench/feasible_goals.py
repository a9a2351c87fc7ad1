"""Does equation (1) pick goals the policy can reach? A diagnostic of V(s, g) for one checkpoint.

    python lab/bench/feasible_goals.py runs/ours-seed0/round0.npz
    python lab/bench/feasible_goals.py runs/relations/ours-seed0/round0.npz
    python lab/bench/feasible_goals.py runs/ours-seed0/round0.npz --json feasible.json
    python lab/bench/feasible_goals.py runs/end2new-seed0/round0.npz --select end2new

Runs the checkpoint's policy on fresh base tasks (sec 4.1), and for every success s0 -> sT draws K
one-alteration candidates and picks g* by equation (1), as task_expansion does. A candidate is
called *feasible* when every goal not yet met at sT has its support in place (features.relations:
nothing in its spot, and the table or a block right under it), so one drop can meet it. The
hand-computed relations (taskexp_lib.features.relations) only judge here; the agent may never
have seen them. Prints the share of
feasible goals among all candidates and among the chosen ones, and how often the verification
run from sT (cfg.short_steps actions) reaches g*, for feasible and infeasible picks.
--select and --no-restrict pick as the ablations of Table 3 do (lab/bench/reproduce.py passes a
run's own settings), so that each variant is judged on the goals it would pick.
"""
import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
import taskexp  # noqa: E402
from agent import Agent  # noqa: E402
from env2d import run_worlds  # noqa: E402
from taskexp_lib import one_blas_thread  # noqa: E402
from taskexp_lib.features import one_drop_away as feasible  # noqa: E402
from taskexp_lib.rollout import run_episodes  # noqa: E402


def measure(checkpoint, tasks=600, seed=5, select="ours", restrict=True,
            candidates=taskexp.Config.candidates):
    """The diagnostic for one checkpoint, picking by `select` among K = `candidates` drawn with
    or without the restriction -> dict of the shares (0..1) and counts it prints."""
    agent = Agent.load(checkpoint)
    drop = agent.drops
    cfg = taskexp.Config(features=agent.feature_set, network=agent.network,
                         action="drop" if drop else "place", select=select, restrict=restrict,
                         candidates=candidates)
    rng = np.random.default_rng(seed)
    envs, short = run_worlds(cfg)
    base, _, _ = taskexp.base_demos(cfg, envs[0], rng, tasks)
    found = [t for t in run_episodes(agent, base, envs, rng, values=False) if t.success]
    share, chosen = [], []
    for t in found:
        sT = t.states[-1]
        cands = taskexp.candidates(t, envs[0], rng, cfg)
        i = taskexp.select_goal(agent, t.states[0], sT, cands, cfg.select)
        ok = [feasible(sT, g) for g in cands]
        share.append(np.mean(ok))
        chosen.append((cands[i], ok[i]))
    runs = run_episodes(agent, [(t.states[-1], g) for t, (g, _) in zip(found, chosen)], short, rng,
                        values=False)
    reached = np.array([r.success for r in runs])
    picked = np.array([ok for _, ok in chosen])
    mean = lambda x: float(np.mean(x)) if len(x) else float("nan")
    return dict(tasks=tasks, solved=len(found), candidates=cfg.candidates, select=select,
                restrict=restrict,
                feasible_candidates=mean(share), feasible_picks=mean(picked),
                reached=mean(reached), reached_feasible=mean(reached[picked]),
                reached_infeasible=mean(reached[~picked]))


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("checkpoint")
    p.add_argument("--tasks", type=int, default=600, help="base tasks to start from")
    p.add_argument("--seed", type=int, default=5)
    p.add_argument("--select", choices=["ours", "end2new", "init2new"], default="ours",
                   help="the selection rule: equation (1) or an ablation of Table 3")
    p.add_argument("--no-restrict", dest="restrict", action="store_false",
                   help="candidates without the one-alteration restriction (Table 3)")
    p.add_argument("--candidates", type=int, default=taskexp.Config.candidates,
                   help="K, the candidates drawn per success (default: the default's)")
    p.add_argument("--json", help="also write the figures to this file (lab/bench/reproduce.py)")
    a = p.parse_args()
    m = measure(a.checkpoint, a.tasks, a.seed, a.select, a.restrict, a.candidates)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(m, f, indent=1)
    pc = lambda key: f"{100 * m[key]:.0f}%"
    rule = a.select + ("" if a.restrict else ", without the restriction")
    print(f"{a.checkpoint}: {m['solved']} of {m['tasks']} base tasks solved; "
          f"K = {m['candidates']}; picks by {rule}")
    print(f"  feasible among all candidates  {pc('feasible_candidates')}")
    print(f"  feasible among the chosen g*   {pc('feasible_picks')}")
    print(f"  g* reached from sT: {pc('reached')} (feasible picks {pc('reached_feasible')}, "
          f"infeasible {pc('reached_infeasible')})")


if __name__ == "__main__":
    with one_blas_thread():
        main()
