"""course/ex2.py -- exercise 2: the log-probability and entropy of the policy pi(b,
x, y), and their gradient (agent.ActionDist).

The student writes logp_entropy(out, actions, n_x) -> (logp, H), logp_entropy_backward(out,
actions, n_x, a, c) -> dout and log_softmax(z). The library has them as the methods of
agent.ActionDist, so the reference solutions here call those in the student's signatures.
"""
import numpy as np

import agent

from .grader import Report, call, diff, first, graded
from .vectors import case

HEADS = ("log pi(b, x, y) = logsoftmax(l)[b] + logsoftmax(X_b)[x] + logsoftmax(Y_b)[y], "
         "with out[..., 0] = l, out[..., 1:1+n_x] = X, out[..., 1+n_x:] = Y; "
         "H = H(b) + sum_b pi(b) (H(X_b) + H(Y_b))")
GRAD = ("per head d logsoftmax(z)[k]/dz = onehot(k) - p and dH/dz = -p (log p + H); "
        "the block logits also get pi(b) (K_b - sum_b' pi(b') K_b') from H's weights, "
        "with K_b = H(X_b) + H(Y_b)")
LOG_SOFTMAX = "log_softmax(z) = z - max(z) - log sum exp(z - max(z)), over the last axis"

# (name, B, blocks n, n_x, n_y, logit scale, hint); case i has seed 100 + i
CASES = [("random", 5, 3, 4, 3, 1.0, HEADS), ("one block", 4, 1, 5, 2, 1.0, HEADS),
         ("one x-bin", 3, 4, 1, 3, 1.0, "a head with one logit has log-prob 0 and entropy 0"),
         ("uniform logits", 2, 3, 4, 3, 0.0, "all logits equal: H = log n + log n_x + log n_y"),
         ("one sample", 1, 6, 37, 6, 2.0, HEADS),
         ("extreme logits (+-1000)", 6, 3, 5, 4, 1000.0,
          "subtract the max before exp (log-sum-exp), "
          "and count p log p as 0 where p = 0: no inf or nan")]


def reference_logp_entropy(out, actions, n_x):
    """agent.ActionDist's log pi(actions) and H, in the student's signature."""
    d = agent.ActionDist(out, n_x)
    return d.log_prob(actions), d.entropy()


def reference_logp_entropy_backward(out, actions, n_x, a, c):
    """agent.ActionDist.backward, in the student's signature."""
    return agent.ActionDist(out, n_x).backward(actions, a, c)


def random_actions(rng, B, n, n_x, n_y):
    """B random actions (block, x-bin, layer) -> (B, 3) int."""
    return np.stack([rng.integers(n, size=B), rng.integers(n_x, size=B),
                     rng.integers(n_y, size=B)], 1)


def make_case(B, n, n_x, n_y, scale, seed):
    """Random actor outputs, actions and weights a, c, with the reference's answers."""
    rng = np.random.default_rng(seed)
    out = scale * rng.standard_normal((B, n, 1 + n_x + n_y))
    actions = random_actions(rng, B, n, n_x, n_y)
    a, c = rng.standard_normal(B), rng.standard_normal(B)
    logp, H = reference_logp_entropy(out, actions, n_x)
    return dict(out=out, actions=actions, a=a, c=c, logp=logp, H=H,
                dout=reference_logp_entropy_backward(out, actions, n_x, a, c),
                log_softmax=agent.log_softmax(out))


def forward_problem(logp_entropy, c, n_x):
    """What is wrong, if anything, with the student's (logp, H) on case c."""
    res, err = call(logp_entropy, c["out"], c["actions"], n_x)
    if err is None and not (isinstance(res, tuple) and len(res) == 2):
        err = f"logp_entropy returned {type(res).__name__}, expected a tuple (logp, H)"
    return err or first(diff("logp", res[0], c["logp"]), diff("H", res[1], c["H"]))


def backward_problem(logp_entropy_backward, c, n_x):
    """What is wrong, if anything, with the student's dout on case c."""
    d, err = call(logp_entropy_backward, c["out"], c["actions"], n_x, c["a"], c["c"])
    return err and "logp_entropy_backward " + err or diff("dout", d, c["dout"])


def log_softmax_problem(log_softmax, c):
    """What is wrong, if anything, with the student's log_softmax of case c's logits."""
    ls, err = call(log_softmax, c["out"])
    return err and "log_softmax " + err or diff("log_softmax(out)", ls, c["log_softmax"])


@graded
def check_ex2(logp_entropy, logp_entropy_backward, log_softmax=None):
    """logp_entropy(out, actions, n_x) -> (logp (B,), H (B,)); logp_entropy_backward(out, actions,
    n_x, a (B,), c (B,)) -> d/dout of sum_k a_k logp_k + c_k H_k (B, n, 1 + n_x + n_y); and, when
    given, log_softmax(z) over the last axis (exercises.action_dist samples with it)."""
    rep = Report("ex2")
    for seed, (name, B, n, n_x, n_y, scale, hint) in enumerate(CASES):
        c = case(f"ex2/{seed}", lambda: make_case(B, n, n_x, n_y, scale, 100 + seed))
        detail = f"B={B}, n={n}, n_x={n_x}, n_y={n_y}, seed {100 + seed}"
        rep.case(name, detail, forward_problem(logp_entropy, c, n_x), hint)
        rep.case("backward, " + name, detail, backward_problem(logp_entropy_backward, c, n_x),
                 hint if scale > 100 else GRAD)
        if log_softmax is not None:
            rep.case("log_softmax, " + name, detail, log_softmax_problem(log_softmax, c),
                     LOG_SOFTMAX)
    rep.done(" (logp, H and their gradient agree with the reference, agent.ActionDist)")
