"""course/ex1.py -- exercise 1: the backward pass of an MLP
(taskexp_lib.nn.mlp_backward).

The student writes mlp_backward(params, hs, dout) -> (grads, dx) for tanh hidden layers and a
linear output. The check compares it with the reference on one to four layers, one sample and
saturated tanh, and (in the two-layer case) with central finite differences through the forward
pass.
"""
import copy

import numpy as np

from taskexp_lib import nn

from .grader import Report, call_backward, diff, first, graded, numerical_grad
from .vectors import case

TANH_HINT = ("h_{k+1} = tanh(h_k W_k + b_k) except the last layer, which is linear: "
             "tanh'(z) = 1 - h^2 with h = hs[k+1]; dW_k = hs[k]^T dz, "
             "db_k = dz summed over the batch, dh_k = dz W_k^T")

# (name, layer sizes, batch size B, weight scale, hint); case i has seed i
CASES = [("one linear layer", [3, 2], 4, 1.0,
          "with no hidden layer: dW = x^T dout, db = dout.sum(0), "
          "dx = dout W^T (no tanh anywhere)"),
         ("two layers", [3, 5, 2], 6, 1.0, TANH_HINT),
         ("one sample", [4, 3, 1], 1, 1.0, "B = 1: keep the batch axis; db sums over it"),
         ("four layers", [6, 8, 7, 5, 3], 9, 1.0,
          TANH_HINT + "; loop over all layers, last to first"),
         ("saturated tanh (large weights)", [3, 4, 2], 5, 8.0,
          "1 - h^2 is near 0 where tanh saturates: "
          "use h = hs[k+1] (the tanh output), not z")]


def mlp_forward(params, x):
    """nn.MLP's forward pass (tanh hidden layers, linear output), for the finite differences."""
    L = len(params) // 2
    for k in range(L):
        x = x @ params[f"W{k}"] + params[f"b{k}"]
        x = np.tanh(x) if k < L - 1 else x
    return x


def make_case(sizes, B, scale, seed):
    """An MLP with scaled weights and random biases, its forward on random x, and the reference
    gradients for a random dout."""
    net = nn.MLP(sizes, seed=seed)
    rng = np.random.default_rng(seed)
    for k in range(net.n_layers):
        net.params[f"W{k}"] *= scale
        net.params[f"b{k}"] += 0.3 * rng.standard_normal(sizes[k + 1])
    x, dout = rng.standard_normal((B, sizes[0])), rng.standard_normal((B, sizes[-1]))
    net.forward(x)
    grads, dx = nn.mlp_backward(net.params, net.hs, dout)
    return dict(params=net.params, hs=net.hs, dout=dout, grads=grads, dx=dx)


def finite_differences(grads, c):
    """The problem, if any, of the student's grads against central finite differences of
    sum(forward(x) * dout), whose gradient w.r.t. the output is dout."""
    params, x = copy.deepcopy(c["params"]), c["hs"][0]
    f = lambda: np.sum(mlp_forward(params, x) * c["dout"])
    return first(*(diff(f"grads[{k!r}] vs finite differences", grads[k], numerical_grad(f, p),
                        1e-5, 1e-6) for k, p in params.items()))


@graded
def check_ex1(mlp_backward):
    """mlp_backward(params, hs, dout) -> (grads, dx), against taskexp_lib.nn.mlp_backward and
    finite differences."""
    rep = Report("ex1")
    for seed, (name, sizes, B, scale, hint) in enumerate(CASES):
        c = case(f"ex1/{seed}", lambda: make_case(sizes, B, scale, seed))
        detail = f"sizes {sizes}, B={B}, seed {seed}"
        res, err = call_backward(mlp_backward, c["params"], c["hs"], c["dout"],
                                 keys=sorted(c["grads"]))
        if err:
            rep.case(name, detail, err, hint)
            continue
        grads, dx = res
        problem = first(*(diff(f"grads[{k!r}]", grads[k], c["grads"][k]) for k in c["grads"]),
                        diff("dx", dx, c["dx"]))
        # and against the definition of a gradient, as part of this case (not a case of its own,
        # which would exist only when the answer is right: a check counts the same cases always)
        if name == "two layers" and problem is None:
            problem = finite_differences(grads, c)
        rep.case(name, detail, problem, hint)
    rep.done(" (agrees with the reference, taskexp_lib.nn.mlp_backward, and central finite "
             "differences)")
