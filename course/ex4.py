"""course/ex4.py -- exercise 4: PPO's clipped surrogate and its gradient
(agent.ppo_loss).

The student writes ppo_loss(out, actions, logp_old, adv, n_x, clip, ent_coef) -> (L, dL/dout),
with the policy distribution of their exercise 2 (exercises.action_dist()). The check compares it
with the reference at ratio 1, inside and outside the clip range, with an entropy bonus, one
sample and another clip.
"""
import numpy as np

import agent

from .ex2 import random_actions
from .grader import Report, call, diff, first, graded
from .vectors import case

LOSS = ("L = -mean_k min(r_k A_k, clip(r_k, 1-eps, 1+eps) A_k) - ent_coef mean_k H_k "
        "is minimised; dL/dlogp_k = -r_k A_k / B where the unclipped term is the min, "
        "else 0; then ActionDist.backward(actions, dL/dlogp, -ent_coef / B)")
NEEDS_EX2 = ". (ActionDist runs your exercise 2: it must pass check_ex2 first)"

# (name, B, blocks n, n_x, n_y, ratios from 1 - lo to 1 + hi, clip, ent_coef, hint);
# case i has seed 300 + i
CASES = [("ratio 1 (the first minibatch: logp_old = logp)", 6, 3, 4, 3, 0, 0, 0.2, 0.0,
          "at r = 1 both terms are equal, and there your gradient is not the one of "
          "min(r A, clip(r) A): every sample of PPO's first minibatch has r = 1, so with "
          "this gradient its first step does nothing"),
         ("ratios inside the clip range", 8, 3, 5, 3, 0.15, 0.15, 0.2, 0.0, LOSS),
         ("ratios outside the clip range", 10, 4, 3, 4, 0.5, 0.5, 0.2, 0.0,
          "PPO takes the min of the two terms (a pessimistic bound); "
          "where the clipped term is the smaller one it is constant: "
          "no gradient (r > 1+eps with A > 0, r < 1-eps with A < 0)"),
         ("mixed ratios, entropy bonus", 12, 3, 4, 3, 0.6, 0.6, 0.2, 0.01,
          "the entropy bonus adds -ent_coef mean H to L: "
          "pass c = -ent_coef / B to ActionDist.backward"),
         ("one sample", 1, 6, 37, 6, 0.3, 0.3, 0.2, 0.003, LOSS),
         ("clip = 0.1", 9, 3, 4, 3, 0.3, 0.3, 0.1, 0.0,
          "use the clip argument, not a constant 0.2")]


def make_case(B, n, n_x, n_y, lo, hi, clip, ent, seed):
    """Random actor outputs and actions, logp_old set for chosen ratios pi / pi_old, random
    advantages, and the reference's (L, dL/dout)."""
    rng = np.random.default_rng(seed)
    out = rng.standard_normal((B, n, 1 + n_x + n_y))
    actions = random_actions(rng, B, n, n_x, n_y)
    r = rng.uniform(1 - lo, 1 + hi, B)                    # the ratios pi / pi_old
    if lo >= 0.5:                                         # both sides outside the clip range
        r = np.where(rng.random(B) < 0.5, rng.uniform(1.3, 1.6, B), rng.uniform(0.4, 0.7, B))
    logp_old = agent.ActionDist(out, n_x).log_prob(actions) - np.log(r)
    adv = rng.standard_normal(B)
    L, dout = agent.ppo_loss(out, actions, logp_old, adv, n_x, clip, ent)
    return dict(out=out, actions=actions, logp_old=logp_old, adv=adv, L=L, dout=dout)


@graded
def check_ex4(ppo_loss):
    """ppo_loss(out, actions, logp_old, adv, n_x, clip, ent_coef) -> (L, dL/dout (B, n, D))."""
    rep = Report("ex4")
    for seed, (name, B, n, n_x, n_y, lo, hi, clip, ent, hint) in enumerate(CASES):
        c = case(f"ex4/{seed}", lambda: make_case(B, n, n_x, n_y, lo, hi, clip, ent, 300 + seed))
        res, err = call(ppo_loss, c["out"], c["actions"], c["logp_old"], c["adv"], n_x, clip, ent)
        if err is None and not (isinstance(res, tuple) and len(res) >= 2):
            err = f"returned {type(res).__name__}, expected a tuple (L, dL/dout)"
        detail = (f"B={B}, n={n}, n_x={n_x}, n_y={n_y}, clip={clip}, ent_coef={ent}, "
                  f"seed {300 + seed}")
        problem = err or first(diff("L", res[0], c["L"]), diff("dL/dout", res[1], c["dout"]))
        hint = LOSS if problem and "sign error" in problem else hint
        rep.case(name, detail, problem, hint + NEEDS_EX2)
    rep.done(" (L and dL/dout agree with the reference, agent.ppo_loss)")
