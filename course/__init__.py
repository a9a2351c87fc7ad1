"""course -- the problem set of taskexp: a grader, a check per exercise, the
notebook loader, the student kit and the command line.

Twelve exercises (course/notebooks/exNN_*.ipynb), most of them functions the student writes; the
reference solution is the library's own code (REFERENCE), wrapped in the student's signature only
where the library has it as a method:

  ex1  mlp_backward(params, hs, dout) -> (grads, dx)          taskexp_lib.nn.mlp_backward
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
  ex8  attention_backward(params, cache, dout) -> (grads, dx)  taskexp_lib.nn.SelfAttention.backward
  ex9  join(first, second, goals, success) -> Trajectory      taskexp.join        (sec 4.2)
       expansion_step(agent, found, cfg, env, short_envs, rng, pieces)
           -> (demos, reached)                                 taskexp.expansion_step
  ex10 distillation_data(run, demos, cfg) -> (obs, actions)   taskexp.distillation_data (4.3)
       distillation_tasks(run, demos, rng) -> (new, old)       taskexp.distillation_tasks
  ex11 select_goal(agent, s0, sT, candidates, mode) -> index  taskexp.select_goal (Table 3)
       one_drop_away(state, goals, threshold) -> bool          taskexp_lib.features.one_drop_away
       and two written answers, graded by hand (MANUAL)
  ex12 behavioural, the capstone: every piece above runs two rounds of the method (sec 4.2-4.3)

check_exN(...) prints PASS, or raises AssertionError with the failing case, expected vs got and a
hint; it writes nothing to stderr (nbgrader would give a graded cell 0 points). Deterministic.
In a student kit (release), the library's reference solutions are stubs and the checks read
recorded cases (vectors.py); exercises 4, 7 and 12 use the student's exercise 2 (action_dist).

    python -m course ex3 NOTEBOOK   # exec the notebook's solution cells, check_ex3
    python -m course all FOLDER     # every exercise, the total; exit 1 if one fails
    python -m course release OUT    # the student kit
    python -m course course DIR     # an nbgrader course that makes the same kit

grader.py (what every check is made of), ex1.py ... ex12.py (an exercise each: its cases, its
check, its reference wrapper if any; ex7 and ex12 train), checks.py (CHECKS), reference.py
(REFERENCE), dist.py (ActionDist from ex2), notebooks.py (the loader), kit.py (kit, course),
vectors.py (recorded cases), problems.py (notebooks, functions, points), __main__.py (the command
line), data/round0.npz (the round-0 agent of exercises 11 and 12).
"""
from . import kit
from .checks import CHECKS
from .dist import NotDone, student_action_dist
from .ex1 import check_ex1
from .ex2 import check_ex2
from .ex3 import check_ex3
from .ex4 import check_ex4
from .ex5 import check_ex5
from .ex6 import DistanceCritic, check_ex6
from .ex7 import EX7, base_policy_success, check_ex7, student_pieces, unfinished
from .ex8 import check_ex8
from .ex9 import check_ex9
from .ex10 import check_ex10
from .ex11 import ablation_table, check_ex11
from .ex12 import CAPSTONE, capstone_pieces, check_ex12, grow
from .grader import Report, numerical_grad, passes, tiny_env
from .notebooks import NOTEBOOK_DIR, action_dist, blank, functions, load, write_notebooks
from .problems import (
    ARGUMENTS,
    BEHAVIOURAL,
    CAPSTONE_NEEDS,
    EX7_NEEDS,
    FUNCTIONS,
    MANUAL,
    NOTEBOOKS,
    POINTS,
)
from .reference import REFERENCE
