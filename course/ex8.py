"""course/ex8.py -- exercise 8: the backward pass of one self-attention layer over
block tokens (taskexp_lib.nn.SelfAttention).

The student writes attention_backward(params, cache, dout) -> (grads, dx), where cache is what
SelfAttention.forward keeps. The check compares it with the reference (SelfAttention.backward, run
on the cache by reference_attention_backward) on one and two heads, one token, one sequence and
saturated attention, and with central finite differences through SelfAttention.forward. Its hint
is chosen by which gradients are wrong and how: a constant factor (1/sqrt(d)), dS rows that do not
sum to zero (the softmax Jacobian: grads["bk"] must be 0), transposed keys (grads["bq"] = 0), dx
alone (x feeds Q, K and V).
"""
import copy

import numpy as np

from taskexp_lib import nn

from .grader import Report, call_backward, diff, first, graded, numerical_grad
from .vectors import case

NAMES = ("Wq", "Wk", "Wv", "Wo", "bq", "bk", "bv", "bo")

HINTS = dict(
    out="out = Y Wo + bo over all B n tokens: dWo = Y^T dout and dbo = dout summed over B and n "
        "(reshape to (B n, D)); then dY = dout Wo^T, split into heads (B, h, n, d)",
    values="Y = A V per head: dV = A^T dY (dv_j = sum_i A_ij dy_i, summed over the queries i), "
           "dA = dY V^T; dWv = x^T dV and dbv = dV summed, with dV merged back to (B n, D)",
    scale="S = Q K^T / sqrt(d), with d = D / heads the size of a head (cache['scale']): the "
          "backward needs the same 1/sqrt(d), once, in dS before dQ and dK",
    softmax="softmax Jacobian: dS_ij = A_ij (dA_ij - sum_k A_ik dA_ik), row by row, not the "
            "elementwise A (1 - A) dA: raising one score lowers every other probability of its "
            "row. Check: each row of dS sums to 0, so grads['bk'] is 0",
    keys_q="transposed keys: S_ij = q_i . k_j / sqrt(d), so dQ = dS K (dq_i = sum_j dS_ij k_j), "
           "not dS^T K",
    keys_k="transposed keys: S_ij = q_i . k_j / sqrt(d), so dK = dS^T Q (dk_j = sum_i dS_ij q_i, "
           "summed over the queries i), not dS Q",
    scores="the scores: dA = dY V^T; dS = softmax Jacobian applied to dA (not A (1 - A) dA); "
           "times 1/sqrt(d); dQ = dS K and dK = dS^T Q (keys not transposed)",
    dx="x feeds Q, K and V: dx = dQ Wq^T + dK Wk^T + dV Wv^T (each merged back to (B n, D)), "
       "the sum of all three",
    one_token="with one token A = [[1]]: the scores get no gradient (dQ = dK = 0) and "
              "out = (x Wv + bv) Wo + bo",
    large="large logits saturate the softmax (rows of A near one-hot): use the cached attn, "
          "do not recompute exp of the scores")

# (name, B, tokens n, width D, heads, query and key weight scale, hint); case i has seed 800 + i
CASES = [("one head", 3, 4, 4, 1, 1.0, HINTS["scores"]),
         ("two heads", 2, 5, 6, 2, 1.0, HINTS["scores"]),
         ("one token (n = 1)", 3, 1, 4, 2, 1.0, HINTS["one_token"]),
         ("one sequence (B = 1), three heads", 1, 6, 6, 3, 1.0, HINTS["scores"]),
         ("large logits (saturated attention)", 2, 4, 4, 1, 6.0, HINTS["large"])]


def _tiny(a, ref):
    return float(np.max(np.abs(a), initial=0.0)) <= 1e-6 * float(np.max(np.abs(ref),
                                                                          initial=0.0)) + 1e-12


def _factor(got, want):
    """c != 1 if got = c want (a gradient off by a constant factor), else None."""
    got, want = np.asarray(got, dtype=np.float64), np.asarray(want, dtype=np.float64)
    if got.shape != want.shape or not want.any():
        return None
    c = float((got * want).sum() / (want * want).sum())
    return c if np.allclose(got, c * want, rtol=1e-5, atol=1e-9) and abs(c - 1) > 1e-4 else None


def diagnose(grads, want, bad, default):
    """The hint for the gradients in `bad` (the names that differ from `want`), from how they
    differ."""
    if bad == {"dx"}:
        return HINTS["dx"]
    if bad & {"Wo", "bo"}:
        return HINTS["out"]
    if bad & {"Wv", "bv"}:
        return HINTS["values"]
    if not bad & {"Wq", "Wk", "bq", "bk"}:
        return default
    if "Wk" not in bad:
        return HINTS["keys_q"]
    if "Wq" not in bad:
        return HINTS["keys_k"]
    c = _factor(grads["Wq"], want["Wq"])
    if c is not None and _factor(grads["Wk"], want["Wk"]) is not None:
        return f"your dWq is {c:.4g} times the expected: {HINTS['scale']}"
    if _tiny(grads["bq"], want["bq"]) and not _tiny(want["bq"], want["Wq"]):
        return HINTS["keys_q"] + "; and dK = dS^T Q. (Your grads['bq'] is 0: dS^T has rows " \
            "that sum to 0)"
    if not _tiny(grads["bk"], want["bq"]):
        return HINTS["softmax"]
    return HINTS["scores"]


def reference_attention_backward(params, cache, dout):
    """nn.SelfAttention.backward on a forward's cache (as check_ex8 hands it to students), in
    the student's signature."""
    B, n, D = cache["x"].shape
    att = nn.SelfAttention(D, cache["heads"])
    att.params = {k: np.array(v, dtype=np.float64) for k, v in params.items()}
    att.x2, att.Y = cache["x"].reshape(B * n, D), cache["Y"].reshape(B * n, D)
    att.Q, att.K, att.V, att.attn = cache["Q"], cache["K"], cache["V"], cache["attn"]
    grads = att.backward(dout)
    return grads, att.dx


def make_case(B, n, D, heads, scale, seed):
    """A layer with scaled query and key weights and random biases, its forward on random x
    (the cache), and the reference gradients for a random dout."""
    att = nn.SelfAttention(D, heads, seed=seed)
    rng = np.random.default_rng(seed)
    for c in "qk":
        att.params[f"W{c}"] *= scale
    for c in "qkvo":
        att.params[f"b{c}"] += 0.3 * rng.standard_normal(D)
    x, dout = rng.standard_normal((B, n, D)), rng.standard_normal((B, n, D))
    att.forward(x)
    cache = dict(x=x, Q=att.Q, K=att.K, V=att.V, attn=att.attn, Y=att.Y.reshape(B, n, D),
                 heads=heads, scale=att.scale)
    grads, dx = reference_attention_backward(att.params, cache, dout)
    return dict(params=att.params, cache=cache, dout=dout, grads=grads, dx=dx)


def finite_differences(grads, dx, c):
    """The problem, if any, of the student's grads and dx against central finite differences of
    sum(forward(x) * dout), whose gradient w.r.t. the output is dout."""
    B, n, D = c["cache"]["x"].shape
    att = nn.SelfAttention(D, c["cache"]["heads"])
    att.params = copy.deepcopy(c["params"])
    x = c["cache"]["x"].copy()
    f = lambda: np.sum(att.forward(x) * c["dout"])
    return first(*(diff(f"grads[{k!r}] vs finite differences", grads[k],
                        numerical_grad(f, att.params[k]), 1e-5, 1e-6) for k in NAMES),
                 diff("dx vs finite differences", dx, numerical_grad(f, x), 1e-5, 1e-6))


@graded
def check_ex8(attention_backward):
    """attention_backward(params, cache, dout) -> (grads, dx), against
    taskexp_lib.nn.SelfAttention.backward and central finite differences."""
    rep = Report("ex8")
    for seed, (name, B, n, D, heads, scale, hint) in enumerate(CASES):
        c = case(f"ex8/{seed}", lambda: make_case(B, n, D, heads, scale, 800 + seed))
        want, want_dx = c["grads"], c["dx"]
        detail = f"B={B}, n={n}, D={D}, heads={heads}, seed {800 + seed}"
        res, err = call_backward(attention_backward, c["params"], c["cache"], c["dout"],
                                 keys=NAMES)
        if err:
            rep.case(name, detail, err, hint)
            continue
        grads, dx = res
        problems = {k: diff(f"grads[{k!r}]", grads[k], want[k]) for k in NAMES}
        problems["dx"] = diff("dx", dx, want_dx)
        bad = {k for k, p in problems.items() if p}
        shapes_ok = all(np.shape(grads[k]) == np.shape(want[k]) for k in NAMES) and \
            np.shape(dx) == np.shape(want_dx)
        problem = first(*problems.values())
        # and against the definition of a gradient, as part of this case (not a case of its own,
        # which would exist only when the answer is right: a check counts the same cases always)
        if name == "two heads" and problem is None:
            problem = finite_differences(grads, dx, c)
        rep.case(name, detail, problem, diagnose(grads, want, bad, hint) if shapes_ok else hint)
    rep.done(" (agrees with the reference, taskexp_lib.nn.SelfAttention.backward, and central "
             "finite differences)")
