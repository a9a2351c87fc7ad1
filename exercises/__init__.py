"""exercises -- the problem set of taskexp: a check per exercise, the notebook loader, the release.

Seven exercises (notebooks/exercises/exN_*.ipynb), each a function the student writes; the
reference solution is the library's own code, wrapped in the student's signature (REFERENCE):

  ex1  mlp_backward(params, hs, dout) -> (grads, dx)          agent.mlp_backward
  ex2  logp_entropy(out, actions, n_x) -> (logp, H)           agent.ActionDist
       logp_entropy_backward(out, actions, n_x, a, c) -> dout  agent.ActionDist.backward
  ex3  gae(rewards, values, terminated, truncated, next_values, gamma, lam)
           -> (adv, ret)                                       agent.gae
  ex4  ppo_loss(out, actions, logp_old, adv, n_x, clip, ent_coef)
           -> (L, dL/dout)                                     agent.ppo_loss
  ex5  alter(goals, env, rng) -> new goals                    taskexp.alter       (sec 4.2)
  ex6  select_goal(agent, s0, sT, candidates) -> index        taskexp.select_goal (eq. 1)
       relabel(traj, env) -> Trajectory or None                taskexp.relabel
  ex7  behavioural: the student's mlp_backward, gae and ppo_loss train the base policy (sec 4.1)

check_exN(...) prints PASS, or FAIL with the case, expected vs got and a hint, and returns
True/False; a notebook's graded cell asserts it.  Deterministic (fixed seeds).

    python -m exercises ex3 [NOTEBOOK]     # exec the notebook's solution cells, run check_ex3
    python -m exercises all [DIR]          # every exercise; exit status 1 if any fails
    python -m exercises release OUT_DIR    # student versions: solutions blanked, outputs cleared

checks.py (ex1-ex6, ~420 lines), behaviour.py (ex7, ~90), notebooks.py (loader, release, CLI, ~120).
"""
from .behaviour import EX7, base_policy_success, check_ex7, student_pieces
from .checks import (
                     REFERENCE,
                     DistanceCritic,
                     Report,
                     check_ex1,
                     check_ex2,
                     check_ex3,
                     check_ex4,
                     check_ex5,
                     check_ex6,
                     tiny_env,
)
from .notebooks import (
                     CHECKS,
                     FUNCTIONS,
                     NOTEBOOK_DIR,
                     NOTEBOOKS,
                     blank,
                     functions,
                     load,
                     main,
                     release,
)
