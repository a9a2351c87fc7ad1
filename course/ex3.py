"""course/ex3.py -- exercise 3: generalised advantage estimation (agent.gae).

The student writes gae(rewards, values, terminated, truncated, next_values, gamma, lam) ->
(advantages, returns). The check compares it with the reference on episodes with and without
terminations and truncations, T = 1, gamma = 0, lam = 0 and lam = 1.
"""
import numpy as np

import agent

from .grader import Report, call, diff, first, graded
from .vectors import case

RECURSION = ("delta_t = r_t + gamma V(s_{t+1}) - V(s_t) with V(s_{t+1}) = next_values[t]; "
             "A_t = delta_t + gamma lam A_{t+1}, computed from the last step backwards; "
             "returns = A + values")
TERMINATED = ("at a terminated step there is no next state: delta_t = r_t - V(s_t) "
              "(mask the bootstrap with terminated) and A_{t+1} belongs to the next episode "
              "(cut the recursion); use the flags of step t itself, not of t+1")
TRUNCATED = ("a truncated episode was cut, not ended: still bootstrap from next_values[t], "
             "but cut the recursion (A_{t+1} belongs to the next episode) -- "
             "mask the bootstrap with terminated, the trace with terminated or truncated")

# (name, T, N, P(terminated), P(truncated), gamma, lam, hint); case i has seed 200 + i
CASES = [("one episode, no ends", 6, 1, 0, 0, 0.99, 0.95, RECURSION),
         ("batch, no ends", 7, 3, 0, 0, 0.9, 0.8, RECURSION),
         ("terminations", 9, 3, 0.25, 0, 0.97, 0.9, TERMINATED),
         ("truncations", 9, 3, 0, 0.25, 0.97, 0.9, TRUNCATED),
         ("terminations and truncations", 12, 4, 0.2, 0.2, 0.95, 0.9, TRUNCATED),
         ("length-1 episodes (every step terminated)", 5, 2, 1, 0, 0.9, 0.9, TERMINATED),
         ("every step truncated", 5, 2, 0, 1, 0.9, 0.9, TRUNCATED),
         ("both flags at once (counts as terminated)", 6, 3, 0.5, 1, 0.9, 0.7, TERMINATED),
         ("T = 1", 1, 5, 0.5, 0.3, 0.99, 0.95, TERMINATED + "; T = 1 must work too"),
         ("gamma = 0", 6, 2, 0.2, 0.2, 0.0, 0.95, "gamma = 0: A_t = r_t - V(s_t)"),
         ("lam = 0 (one-step TD)", 6, 2, 0.2, 0.2, 0.9, 0.0, "lam = 0: A_t = delta_t"),
         ("lam = 1 (Monte Carlo)", 8, 2, 0.2, 0.2, 0.9, 1.0, RECURSION)]


def make_case(T, N, p_term, p_trunc, gamma, lam, seed):
    """Random rewards, values, next values and end flags (T, N), with the reference's answer."""
    rng = np.random.default_rng(seed)
    r, v, nv = rng.random((T, N)), rng.standard_normal((T, N)), rng.standard_normal((T, N))
    te, tr = (rng.random((T, N)) < p_term) * 1.0, (rng.random((T, N)) < p_trunc) * 1.0
    adv, ret = agent.gae(r, v, te, tr, nv, gamma, lam)
    return dict(r=r, v=v, te=te, tr=tr, nv=nv, adv=adv, ret=ret)


@graded
def check_ex3(gae):
    """gae(rewards, values, terminated, truncated, next_values, gamma, lam) -> (adv, returns),
    all (T, N)."""
    rep = Report("ex3")
    for seed, (name, T, N, p_term, p_trunc, gamma, lam, hint) in enumerate(CASES):
        c = case(f"ex3/{seed}", lambda: make_case(T, N, p_term, p_trunc, gamma, lam, 200 + seed))
        res, err = call(gae, c["r"], c["v"], c["te"], c["tr"], c["nv"], gamma, lam)
        if err is None and not (isinstance(res, tuple) and len(res) == 2):
            err = f"returned {type(res).__name__}, expected a tuple (advantages, returns)"
        detail = f"T={T}, N={N}, gamma={gamma}, lam={lam}, seed {200 + seed}"
        rep.case(name, detail, err or first(diff("advantages", res[0], c["adv"]),
                                            diff("returns", res[1], c["ret"])), hint)
    rep.done(" (agrees with the reference, agent.gae)")
