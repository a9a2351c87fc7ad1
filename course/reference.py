"""course/reference.py -- the reference solution of every function a student writes:
the library's own, called directly where its signature is the exercise's, or through the wrapper of
its exercise (ex2.py, ex8.py) where the library has it as a method.

Only the checks' make() functions call these, so that a student kit (whose library has stubs and
whose checks read recorded cases) never does.
"""
import agent
import taskexp
from taskexp_lib import features, nn

from .ex2 import reference_logp_entropy, reference_logp_entropy_backward
from .ex8 import reference_attention_backward

REFERENCE = dict(
    mlp_backward=nn.mlp_backward,                                   # ex1
    logp_entropy=reference_logp_entropy,                            # ex2
    logp_entropy_backward=reference_logp_entropy_backward,
    log_softmax=agent.log_softmax,
    gae=agent.gae,                                                  # ex3
    ppo_loss=agent.ppo_loss,                                        # ex4
    alter=taskexp.alter,                                            # ex5
    select_goal=taskexp.select_goal,                                # ex6
    relabel=taskexp.relabel,
    attention_backward=reference_attention_backward,                # ex8
    join=taskexp.join,                                              # ex9
    expansion_step=taskexp.expansion_step,
    distillation_data=taskexp.distillation_data,                    # ex10
    distillation_tasks=taskexp.distillation_tasks,
    one_drop_away=features.one_drop_away)                           # ex11 (and select_goal)
