"""exercises -- the problem set of taskexp: a check per exercise, the notebook loader, the student
kit and the CLI.

Eight exercises (notebooks/exercises/exN_*.ipynb), each a function the student writes; the
reference solution is the library's own code, wrapped in the student's signature (REFERENCE):

  ex1  mlp_backward(params, hs, dout) -> (grads, dx)          agent.mlp_backward
  ex2  logp_entropy(out, actions, n_x) -> (logp, H)           agent.ActionDist
       logp_entropy_backward(out, actions, n_x, a, c) -> dout  agent.ActionDist.backward
       log_softmax(z)                                          agent.log_softmax
  ex3  gae(rewards, values, terminated, truncated, next_values, gamma, lam)
           -> (adv, ret)                                       agent.gae
  ex4  ppo_loss(out, actions, logp_old, adv, n_x, clip, ent_coef)
           -> (L, dL/dout)                                     agent.ppo_loss
  ex5  alter(goals, env, rng) -> new goals                    taskexp.alter       (sec 4.2)
  ex6  select_goal(agent, s0, sT, candidates) -> index        taskexp.select_goal (eq. 1)
       relabel(traj, env) -> Trajectory or None                taskexp.relabel
  ex7  behavioural: the student's ex1-ex4 train the base policy (sec 4.1)
  ex8  attention_backward(params, cache, dout) -> (grads, dx)  agent.SelfAttention.backward

check_exN(...) prints PASS, or raises AssertionError with the failing case, expected vs got and a
hint; it writes nothing to stderr (nbgrader would give a graded cell 0 points). Deterministic.
In a student kit (release), the library's reference solutions are stubs and the checks read
recorded cases (vectors.py); exercise 4 and 7 use the student's exercise 2 (action_dist).

    python -m exercises ex3 NOTEBOOK       # exec the notebook's solution cells, run check_ex3
    python -m exercises all FOLDER         # every exercise, then the total; exit 1 if any fails
    python -m exercises release OUT        # the student kit
    python -m exercises course DIR         # an nbgrader course that makes the same kit

checks.py (ex1-ex6), behaviour.py (ex7), attention.py (ex8), dist.py (ActionDist from ex2),
notebooks.py (loader, CLI), kit.py (kit, course), vectors.py (recorded cases), problems.py
(notebooks, points).
"""
from .attention import check_ex8
from .behaviour import EX7, base_policy_success, check_ex7, student_pieces, unfinished
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
                     passes,
                     tiny_env,
)
from .dist import NotDone, student_action_dist
from .notebooks import (
                     CHECKS,
                     NOTEBOOK_DIR,
                     action_dist,
                     blank,
                     check,
                     functions,
                     load,
                     main,
                     write_notebooks,
)
from .problems import EX7_NEEDS, FUNCTIONS, NOTEBOOKS, POINTS
