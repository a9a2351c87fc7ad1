"""exercises/checks.py -- the checks of exercises 1-6, and the reporting they share.  ~610 lines.

Each check_exN(student functions) runs them on fixed inputs of varied shapes plus edge cases and
compares them with the reference solution. It prints one PASS line and returns None, or raises an
AssertionError whose message gives the first failing case, expected vs got, and a hint. Every case
has its own seed, so a check is deterministic.

A case's inputs and expected outputs come from its make() function, run on the library (REFERENCE)
in the repository; a student kit, whose library has stubs, reads them from recorded test vectors
(vectors.py). The comparisons and hints are the same code in both.
"""
import contextlib
import copy
import functools
import sys
import traceback
import warnings
from types import SimpleNamespace

import numpy as np

import agent
import taskexp
from env2d import BLOCK_H, TABLE_X, THRESHOLD, X_BINS, layer_y, observation

from .vectors import case


def tiny_env(n_blocks):
    """What ex5/ex6 may use of a BlockWorld: n_blocks, x_bins (37,), y_bins (n_blocks,), table_x,
    threshold; all from env2d's geometry."""
    return SimpleNamespace(n_blocks=n_blocks, x_bins=X_BINS.copy(),
                           y_bins=layer_y(np.arange(n_blocks)),
                           table_x=TABLE_X, threshold=THRESHOLD)


# ---- Reference solutions: the library, in the students' signatures --------------------------
# Only make() functions call them, so that a student kit (stubs, recorded cases) never does.

def _ref_logp_entropy(out, actions, n_x):
    d = agent.ActionDist(out, n_x)
    return d.log_prob(actions), d.entropy()


def _ref_attention_backward(params, cache, dout):
    """agent.SelfAttention.backward on a forward's cache (as check_ex8 hands it to students)."""
    B, n, D = cache["x"].shape
    att = agent.SelfAttention(D, cache["heads"])
    att.params = {k: np.array(v, dtype=np.float64) for k, v in params.items()}
    att.x2, att.Y = cache["x"].reshape(B * n, D), cache["Y"].reshape(B * n, D)
    att.Q, att.K, att.V, att.attn = cache["Q"], cache["K"], cache["V"], cache["attn"]
    grads = att.backward(dout)
    return grads, att.dx


REFERENCE = dict(
    mlp_backward=agent.mlp_backward, logp_entropy=_ref_logp_entropy,
    logp_entropy_backward=lambda out, actions, n_x, a, c:
        agent.ActionDist(out, n_x).backward(actions, a, c),
    log_softmax=lambda z: agent.log_softmax(z),
    gae=agent.gae, ppo_loss=lambda *args, **kw: agent.ppo_loss(*args, **kw)[:2],
    alter=lambda goals, env, rng: taskexp.alter(goals, env, rng),
    select_goal=lambda ag, s0, sT, cands: taskexp.select_goal(ag, s0, sT, cands)[0],
    relabel=lambda traj, env: taskexp.relabel(traj, env),
    attention_backward=_ref_attention_backward)


# ---- Reporting ---------------------------------------------------------------------------------

class Report:
    """Collects failing cases; done() prints PASS, or raises AssertionError with the first
    failure in detail."""

    def __init__(self, name):
        self.name, self.failures, self.cases = name, [], 0

    def case(self, name, detail, problem, hint):
        """One case: its name, its inputs (shapes, seed), what went wrong (None: ok), a hint."""
        self.cases += 1
        if problem:
            self.failures.append((name, detail, problem, hint))

    def done(self, extra=""):
        if not self.failures:
            print(f"{self.name} PASS: {self.cases} case{'s' * (self.cases != 1)}{extra}")
            return
        name, detail, problem, hint = self.failures[0]
        lines = [f"{self.name} FAIL: case {name!r} ({detail})", f"  {problem}"]
        if hint and "NotImplementedError" not in problem:
            lines.append(f"  hint: {hint}")
        if len(self.failures) > 1:
            others = list(dict.fromkeys(f[0] for f in self.failures[1:]))
            lines.append(f"  ({len(self.failures)} of {self.cases} cases failed; "
                         f"also: {'; '.join(others[:5])})")
        raise AssertionError("\n".join(lines))


def graded(check):
    """What a graded notebook cell runs. nbgrader gives no points to a graded cell that writes to
    stderr, even when the check passes, so the check's warnings (numpy's, on a student's overflow)
    and anything written to sys.stderr go to stdout; a warning is reported once, as a note."""
    @functools.wraps(check)
    def run(*args, **kwargs):
        with warnings.catch_warnings(record=True) as caught, \
                contextlib.redirect_stderr(sys.stdout):
            warnings.simplefilter("always")
            try:
                check(*args, **kwargs)
            except AssertionError as failed:    # raised again here: a traceback of two frames,
                raise AssertionError(str(failed)) from None     # the cell's and this line
            finally:
                seen = list(dict.fromkeys(f"{w.category.__name__}: {w.message}" for w in caught))
                if seen:
                    print(f"  note: {len(caught)} warning{'s' * (len(caught) > 1)} while checking"
                          f", e.g. {seen[0]}")
    return run


def passes(check, *args, **kwargs):
    """check(*args) -> True if it passes, False if it fails (its message printed)."""
    try:
        check(*args, **kwargs)
        return True
    except AssertionError as e:
        print(e)
        return False


NOT_DONE = ("raised NotImplementedError: not done yet "
            "(replace `raise NotImplementedError()` by your code)")


def call(fn, *args, **kw):
    """fn(*args) -> (result, None), or (None, what it raised) -- a student's code may raise."""
    try:
        return fn(*copy.deepcopy(args), **kw), None    # copies: the student cannot spoil our inputs
    except NotImplementedError as e:                   # with a message: the exercise it needs
        return None, f"raised NotImplementedError: {e}" if str(e) else NOT_DONE
    except Exception as e:                          # point at the student's line, not at numpy's
        frames = [f for f in traceback.extract_tb(e.__traceback__)[1:]
                  if "site-packages" not in f.filename]
        at = f" at {frames[-1].filename}, line {frames[-1].lineno}" if frames else ""
        code = f": {frames[-1].line}" if frames and frames[-1].line else ""
        return None, f"raised {type(e).__name__}: {e}{at}{code}"


def diff(name, got, want, rtol=1e-6, atol=1e-8):
    """None when got matches want (shape and values), else one line: where, got vs expected."""
    want = np.asarray(want, dtype=np.float64)
    try:
        got = np.asarray(got, dtype=np.float64)
    except (TypeError, ValueError):
        return (f"{name}: got {type(got).__name__} {str(got)[:60]}, "
                f"expected an array of shape {want.shape}")
    if got.shape != want.shape:
        return f"{name}: shape {got.shape}, expected {want.shape}"
    bad = ~np.isclose(got, want, rtol=rtol, atol=atol)
    if not bad.any():
        return None
    i = tuple(int(k) for k in np.argwhere(bad)[0])
    sign = ("  (got = -expected: a sign error?)"
            if np.allclose(got, -want, rtol, atol) and want.any() else "")
    return (f"{name}: {bad.sum()} of {bad.size} entries differ; first at {i}: "
            f"got {got[i]:.6g}, expected {want[i]:.6g}{sign}")


def call_backward(fn, *args):
    """Call a student's backward pass -> (result, None), or (result, what is wrong): it raised,
    or it did not return a tuple (grads dict, dx)."""
    res, err = call(fn, *args)
    if err is None and not (isinstance(res, tuple) and len(res) == 2 and isinstance(res[0], dict)):
        err = f"returned {type(res).__name__}, expected a tuple (grads dict, dx)"
    return res, err


def first(*problems):
    return next((p for p in problems if p), None)


# ---- ex1: the MLP backward pass ------------------------------------------------------------------

def mlp_forward(params, x):
    """agent.MLP's forward pass (tanh hidden layers, linear output), for the finite differences."""
    L = len(params) // 2
    for k in range(L):
        x = x @ params[f"W{k}"] + params[f"b{k}"]
        x = np.tanh(x) if k < L - 1 else x
    return x


def _make_ex1(sizes, B, scale, seed):
    net = agent.MLP(sizes, seed=seed)
    rng = np.random.default_rng(seed)
    for k in range(net.n_layers):
        net.params[f"W{k}"] *= scale
        net.params[f"b{k}"] += 0.3 * rng.standard_normal(sizes[k + 1])
    x, dout = rng.standard_normal((B, sizes[0])), rng.standard_normal((B, sizes[-1]))
    net.forward(x)
    grads, dx = agent.mlp_backward(net.params, net.hs, dout)
    return dict(params=net.params, hs=net.hs, dout=dout, grads=grads, dx=dx)


@graded
def check_ex1(mlp_backward):
    """mlp_backward(params, hs, dout) -> (grads, dx), against agent.mlp_backward and finite
    differences."""
    rep = Report("ex1")
    tanh_hint = ("h_{k+1} = tanh(h_k W_k + b_k) except the last layer, which is linear: "
                 "tanh'(z) = 1 - h^2 with h = hs[k+1]; dW_k = hs[k]^T dz, "
                 "db_k = dz summed over the batch, dh_k = dz W_k^T")
    cases = [("one linear layer", [3, 2], 4, 1.0,
              "with no hidden layer: dW = x^T dout, db = dout.sum(0), "
              "dx = dout W^T (no tanh anywhere)"),
             ("two layers", [3, 5, 2], 6, 1.0, tanh_hint),
             ("one sample", [4, 3, 1], 1, 1.0, "B = 1: keep the batch axis; db sums over it"),
             ("four layers", [6, 8, 7, 5, 3], 9, 1.0,
              tanh_hint + "; loop over all layers, last to first"),
             ("saturated tanh (large weights)", [3, 4, 2], 5, 8.0,
              "1 - h^2 is near 0 where tanh saturates: "
              "use h = hs[k+1] (the tanh output), not z")]
    for seed, (name, sizes, B, scale, hint) in enumerate(cases):
        c = case(f"ex1/{seed}", lambda: _make_ex1(sizes, B, scale, seed))
        want, want_dx = c["grads"], c["dx"]
        detail = f"sizes {sizes}, B={B}, seed {seed}"
        res, err = call_backward(mlp_backward, c["params"], c["hs"], c["dout"])
        if err:
            rep.case(name, detail, err, hint)
            continue
        grads, dx = res
        missing = sorted(set(want) - set(grads))
        rep.case(name, detail, f"grads has no key {missing[0]!r}" if missing else
                 first(*(diff(f"grads[{k!r}]", grads[k], want[k]) for k in want),
                       diff("dx", dx, want_dx)), hint)
        if name == "two layers" and not rep.failures:     # and against the definition of a gradient
            params, x = copy.deepcopy(c["params"]), c["hs"][0]
            f = lambda: np.sum(mlp_forward(params, x) * c["dout"])   # dL/dout = dout
            rep.case("finite differences", detail,
                     first(*(diff(f"grads[{k!r}] vs finite differences", grads[k],
                                  numerical_grad(f, p), 1e-5, 1e-6)
                             for k, p in params.items())), hint)
    rep.done(" (agrees with the reference, agent.mlp_backward, and central finite differences)")


def numerical_grad(f, x, eps=1e-6):
    """Central differences of the scalar f() w.r.t. every entry of the array x (changed in
    place)."""
    g = np.zeros_like(x)
    for i in np.ndindex(x.shape):
        old = x[i]
        x[i] = old + eps
        fp = f()
        x[i] = old - eps
        g[i] = (fp - f()) / (2 * eps)
        x[i] = old
    return g


# ---- ex2: log-probability and entropy of pi(b, x, y) -------------------------------------------

def _make_ex2(B, n, n_x, n_y, scale, seed):
    rng = np.random.default_rng(seed)
    out = scale * rng.standard_normal((B, n, 1 + n_x + n_y))
    actions = np.stack([rng.integers(n, size=B), rng.integers(n_x, size=B),
                        rng.integers(n_y, size=B)], 1)
    a, c = rng.standard_normal(B), rng.standard_normal(B)
    logp, H = _ref_logp_entropy(out, actions, n_x)
    return dict(out=out, actions=actions, a=a, c=c, logp=logp, H=H,
                dout=agent.ActionDist(out, n_x).backward(actions, a, c),
                log_softmax=agent.log_softmax(out))


@graded
def check_ex2(logp_entropy, logp_entropy_backward, log_softmax=None):
    """logp_entropy(out, actions, n_x) -> (logp (B,), H (B,)); logp_entropy_backward(out, actions,
    n_x, a (B,), c (B,)) -> d/dout of sum_k a_k logp_k + c_k H_k (B, n, 1 + n_x + n_y); and, when
    given, log_softmax(z) over the last axis (exercises.action_dist samples with it)."""
    rep = Report("ex2")
    heads = ("log pi(b, x, y) = logsoftmax(l)[b] + logsoftmax(X_b)[x] + logsoftmax(Y_b)[y], "
             "with out[..., 0] = l, out[..., 1:1+n_x] = X, out[..., 1+n_x:] = Y; "
             "H = H(b) + sum_b pi(b) (H(X_b) + H(Y_b))")
    grad = ("per head d logsoftmax(z)[k]/dz = onehot(k) - p and dH/dz = -p (log p + H); "
            "the block logits also get pi(b) (K_b - sum_b' pi(b') K_b') from H's weights, "
            "with K_b = H(X_b) + H(Y_b)")
    cases = [("random", 5, 3, 4, 3, 1.0, heads), ("one block", 4, 1, 5, 2, 1.0, heads),
             ("one x-bin", 3, 4, 1, 3, 1.0, "a head with one logit has log-prob 0 and entropy 0"),
             ("uniform logits", 2, 3, 4, 3, 0.0, "all logits equal: H = log n + log n_x + log n_y"),
             ("one sample", 1, 6, 37, 6, 2.0, heads),
             ("extreme logits (+-1000)", 6, 3, 5, 4, 1000.0,
              "subtract the max before exp (log-sum-exp), "
              "and count p log p as 0 where p = 0: no inf or nan")]
    for seed, (name, B, n, n_x, n_y, scale, hint) in enumerate(cases):
        c = case(f"ex2/{seed}", lambda: _make_ex2(B, n, n_x, n_y, scale, 100 + seed))
        out, actions = c["out"], c["actions"]
        detail = f"B={B}, n={n}, n_x={n_x}, n_y={n_y}, seed {100 + seed}"
        res, err = call(logp_entropy, out, actions, n_x)
        if err is None and not (isinstance(res, tuple) and len(res) == 2):
            err = f"logp_entropy returned {type(res).__name__}, expected a tuple (logp, H)"
        rep.case(name, detail,
                 err or first(diff("logp", res[0], c["logp"]), diff("H", res[1], c["H"])), hint)
        d, err = call(logp_entropy_backward, out, actions, n_x, c["a"], c["c"])
        rep.case("backward, " + name, detail,
                 err and "logp_entropy_backward " + err or diff("dout", d, c["dout"]),
                 hint if scale > 100 else grad)
        if log_softmax is not None:
            ls, err = call(log_softmax, out)
            rep.case("log_softmax, " + name, detail,
                     err and "log_softmax " + err or diff("log_softmax(out)", ls,
                                                          c["log_softmax"]),
                     "log_softmax(z) = z - max(z) - log sum exp(z - max(z)), over the last axis")
    rep.done(" (logp, H and their gradient agree with the reference, agent.ActionDist)")


# ---- ex3: generalised advantage estimation -------------------------------------------------------

def _make_ex3(T, N, p_term, p_trunc, gamma, lam, seed):
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
    rec = ("delta_t = r_t + gamma V(s_{t+1}) - V(s_t) with V(s_{t+1}) = next_values[t]; "
           "A_t = delta_t + gamma lam A_{t+1}, computed from the last step backwards; "
           "returns = A + values")
    term = ("at a terminated step there is no next state: delta_t = r_t - V(s_t) "
            "(mask the bootstrap with terminated) and A_{t+1} belongs to the next episode "
            "(cut the recursion); use the flags of step t itself, not of t+1")
    trunc = ("a truncated episode was cut, not ended: still bootstrap from next_values[t], "
             "but cut the recursion (A_{t+1} belongs to the next episode) -- "
             "mask the bootstrap with terminated, the trace with terminated or truncated")
    cases = [("one episode, no ends", 6, 1, 0, 0, 0.99, 0.95, rec),
             ("batch, no ends", 7, 3, 0, 0, 0.9, 0.8, rec),
             ("terminations", 9, 3, 0.25, 0, 0.97, 0.9, term),
             ("truncations", 9, 3, 0, 0.25, 0.97, 0.9, trunc),
             ("terminations and truncations", 12, 4, 0.2, 0.2, 0.95, 0.9, trunc),
             ("length-1 episodes (every step terminated)", 5, 2, 1, 0, 0.9, 0.9, term),
             ("every step truncated", 5, 2, 0, 1, 0.9, 0.9, trunc),
             ("both flags at once (counts as terminated)", 6, 3, 0.5, 1, 0.9, 0.7, term),
             ("T = 1", 1, 5, 0.5, 0.3, 0.99, 0.95, term + "; T = 1 must work too"),
             ("gamma = 0", 6, 2, 0.2, 0.2, 0.0, 0.95, "gamma = 0: A_t = r_t - V(s_t)"),
             ("lam = 0 (one-step TD)", 6, 2, 0.2, 0.2, 0.9, 0.0, "lam = 0: A_t = delta_t"),
             ("lam = 1 (Monte Carlo)", 8, 2, 0.2, 0.2, 0.9, 1.0, rec)]
    for seed, (name, T, N, p_term, p_trunc, gamma, lam, hint) in enumerate(cases):
        c = case(f"ex3/{seed}", lambda: _make_ex3(T, N, p_term, p_trunc, gamma, lam, 200 + seed))
        res, err = call(gae, c["r"], c["v"], c["te"], c["tr"], c["nv"], gamma, lam)
        if err is None and not (isinstance(res, tuple) and len(res) == 2):
            err = f"returned {type(res).__name__}, expected a tuple (advantages, returns)"
        detail = f"T={T}, N={N}, gamma={gamma}, lam={lam}, seed {200 + seed}"
        rep.case(name, detail, err or first(diff("advantages", res[0], c["adv"]),
                                     diff("returns", res[1], c["ret"])), hint)
    rep.done(" (agrees with the reference, agent.gae)")


# ---- ex4: the PPO clipped surrogate --------------------------------------------------------------

def _make_ex4(B, n, n_x, n_y, lo, hi, clip, ent, seed):
    rng = np.random.default_rng(seed)
    out = rng.standard_normal((B, n, 1 + n_x + n_y))
    actions = np.stack([rng.integers(n, size=B), rng.integers(n_x, size=B),
                        rng.integers(n_y, size=B)], 1)
    r = rng.uniform(1 - lo, 1 + hi, B)                    # the ratios pi / pi_old
    if lo >= 0.5:
        r = np.where(rng.random(B) < 0.5, rng.uniform(1.3, 1.6, B), rng.uniform(0.4, 0.7, B))
    logp_old = agent.ActionDist(out, n_x).log_prob(actions) - np.log(r)
    adv = rng.standard_normal(B)
    L, dout = agent.ppo_loss(out, actions, logp_old, adv, n_x, clip, ent)[:2]
    return dict(out=out, actions=actions, logp_old=logp_old, adv=adv, L=L, dout=dout)


@graded
def check_ex4(ppo_loss):
    """ppo_loss(out, actions, logp_old, adv, n_x, clip, ent_coef) -> (L, dL/dout (B, n, D))."""
    rep = Report("ex4")
    loss = ("L = -mean_k min(r_k A_k, clip(r_k, 1-eps, 1+eps) A_k) - ent_coef mean_k H_k "
            "is minimised; dL/dlogp_k = -r_k A_k / B where the unclipped term is the min, "
            "else 0; then ActionDist.backward(actions, dL/dlogp, -ent_coef / B)")
    cases = [("ratio 1 (the first minibatch: logp_old = logp)", 6, 3, 4, 3, 0, 0, 0.2, 0.0,
              "at r = 1 both terms are equal: the gradient is r A there "
              "(take the unclipped term when it is <= the clipped one), "
              "or PPO's first step does nothing"),
             ("ratios inside the clip range", 8, 3, 5, 3, 0.15, 0.15, 0.2, 0.0, loss),
             ("ratios outside the clip range", 10, 4, 3, 4, 0.5, 0.5, 0.2, 0.0,
              "PPO takes the min of the two terms (a pessimistic bound); "
              "where the clipped term is the smaller one it is constant: "
              "no gradient (r > 1+eps with A > 0, r < 1-eps with A < 0)"),
             ("mixed ratios, entropy bonus", 12, 3, 4, 3, 0.6, 0.6, 0.2, 0.01,
              "the entropy bonus adds -ent_coef mean H to L: "
              "pass c = -ent_coef / B to ActionDist.backward"),
             ("one sample", 1, 6, 37, 6, 0.3, 0.3, 0.2, 0.003, loss),
             ("clip = 0.1", 9, 3, 4, 3, 0.3, 0.3, 0.1, 0.0,
              "use the clip argument, not a constant 0.2")]
    for seed, (name, B, n, n_x, n_y, lo, hi, clip, ent, hint) in enumerate(cases):
        c = case(f"ex4/{seed}", lambda: _make_ex4(B, n, n_x, n_y, lo, hi, clip, ent, 300 + seed))
        res, err = call(ppo_loss, c["out"], c["actions"], c["logp_old"], c["adv"], n_x, clip, ent)
        if err is None and not (isinstance(res, tuple) and len(res) >= 2):
            err = f"returned {type(res).__name__}, expected a tuple (L, dL/dout)"
        detail = (f"B={B}, n={n}, n_x={n_x}, n_y={n_y}, clip={clip}, ent_coef={ent}, "
                  f"seed {300 + seed}")
        problem = err or first(diff("L", res[0], c["L"]), diff("dL/dout", res[1], c["dout"]))
        hint = loss if problem and "sign error" in problem else hint
        rep.case(name, detail, problem, hint + ". (ActionDist runs your exercise 2: it must pass "
                 "check_ex2 first)")
    rep.done(" (L and dL/dout agree with the reference, agent.ppo_loss)")


# ---- ex5: one-alteration task sampling (sec 4.2) -------------------------------------------------

def as_goals(goals):
    """{block: (x, y)} with plain ints and floats, so dicts of numpy values compare with ==."""
    out = {int(b): tuple(map(float, p)) for b, p in goals.items()}
    if any(len(p) != 2 for p in out.values()):
        raise ValueError("a goal position is a pair (x, y)")
    return out


@graded
def check_ex5(alter, samples=400):
    """alter(goals, env, rng) -> a new goal dict: exactly one goal added or one goal modified."""
    rep = Report("ex5")
    grid = "goal positions lie on the action grid: (env.x_bins[i], env.y_bins[k]) for uniform i, k"
    cases = [("one goal, six blocks", 6, [2]), ("three goals, six blocks", 6, [0, 3, 5]),
             ("no free block (every block has a goal)", 6, range(6)),
             ("two blocks, one goal", 2, [1]), ("one block with a goal", 1, [0])]
    for seed, (name, n, blocks) in enumerate(cases):
        env, rng = tiny_env(n), np.random.default_rng(500 + seed)
        goals = {int(b): (float(env.x_bins[rng.integers(37)]), float(env.y_bins[rng.integers(n)]))
                 for b in blocks}
        free = [b for b in range(n) if b not in goals]
        shown = {b: (round(x, 3), round(y, 3)) for b, (x, y) in goals.items()}
        detail = f"goals {shown}, n_blocks={n}, seed {500 + seed}"
        kinds, added, modified, xs, ys, problem, hint = [], set(), set(), set(), set(), None, ""
        for i in range(samples):
            before = copy.deepcopy(goals)
            try:
                new = alter(goals, env, rng)
            except NotImplementedError:
                problem = NOT_DONE
                break
            except Exception as e:
                problem, hint = (f"raised {type(e).__name__}: {e}",
                                 "with no free block you can only modify")
                break
            if len(goals) != len(before) or any(not np.array_equal(goals.get(b), p)
                                                for b, p in before.items()):
                problem, hint = (f"changed its input to {goals}",
                                 "copy the dict first: new = dict(goals)")
                break
            if (not isinstance(new, dict) or not set(goals) <= set(new)
                    or not set(new) <= set(range(n))):
                problem, hint = (f"sample {i}: {new}",
                                 "keep every goal of the input; add only blocks 0..n-1")
                break
            # numpy positions are fine; compare them as floats
            try:
                new = as_goals(new)
            except (TypeError, ValueError):
                problem, hint = f"sample {i}: {new}", "a goal position is a pair of numbers (x, y)"
                break
            add = [b for b in new if b not in goals]
            mod = [b for b in goals if not np.allclose(new[b], goals[b])]
            pos = [new[b] for b in add + mod]
            if len(add) + len(mod) > 1:
                problem, hint = (f"sample {i}: {new} adds {add} and modifies {mod}",
                                 "one alteration: add ONE goal for a free block, "
                                 "or modify ONE existing goal")
                break
            if any(np.abs(env.x_bins - x).min() > 1e-9 or np.abs(env.y_bins - y).min() > 1e-9
                   for x, y in pos):
                problem, hint = f"sample {i}: {new} has a goal off the grid", grid
                break
            kinds.append("add" if add else "modify" if mod else "none")
            added.update(add), modified.update(mod)
            xs.update(np.round([x for x, _ in pos], 9)), ys.update(np.round([y for _, y in pos], 9))
        if problem is None:
            share = {k: kinds.count(k) / samples for k in ("add", "modify", "none")}
            if share["none"] > 0.05:
                problem, hint = (f"{share['none']:.0%} of samples change nothing",
                                 "a modification must move the goal "
                                 "(a uniform new position almost always does)")
            elif free and min(share["add"], share["modify"]) < 0.2:
                problem, hint = (f"adds {share['add']:.0%}, "
                                 f"modifies {share['modify']:.0%} of the time",
                                 "with a free block, choose add or modify at random (50/50), "
                                 "so both cases occur")
            elif set(free) - added or set(goals) - modified:
                problem, hint = (f"never added {sorted(set(free) - added)}, never modified "
                                 f"{sorted(set(goals) - modified)}", "choose the block uniformly")
            elif len(xs) < 30 or len(ys) < n:
                problem, hint = (f"used only {len(xs)} of 37 x-bins and {len(ys)} of {n} layers",
                                 grid)
        if problem is None:                             # reproducible: only the rng passed in
            draw = lambda: [as_goals(alter(goals, env, np.random.default_rng(seed)))
                            for _ in range(5)]
            if draw() != draw():
                problem, hint = ("two runs with the same seed differ",
                                 "draw only from rng, not np.random or random")
        rep.case(name, detail, problem, hint)
    rep.done(f" ({samples} samples each: one alteration, both kinds, every block, "
                    "the whole grid)")


# ---- ex6: goal selection by equation (1), relabelling on failure ---------------------------------

class DistanceCritic:
    """A stand-in for agent.Agent.value: V(s, g) = exp(-sum of goal distances / 0.3), which is high
    when the goals are near the blocks.  obs (n, 6) -> float, or (B, n, 6) -> (B,)."""

    def value(self, obs):
        o = np.asarray(obs, dtype=np.float64)
        v = np.exp(-(o[..., 5] * np.hypot(o[..., 3] - o[..., 0],
                                          o[..., 4] - o[..., 1])).sum(-1) / 0.3)
        return float(v) if o.ndim == 2 else v


def _scene(rng, n):
    """A state (n, 6): blocks on the table at distinct x-bins."""
    s = np.zeros((n, 6))
    s[:, 0], s[:, 1] = rng.choice(X_BINS[::4], n, replace=False), BLOCK_H / 2
    return s


def _trajectory(rng, n, T, goal_blocks, fall=False):
    """T random single-block moves onto the grid from a scattered scene; optionally one falls
    off."""
    states = [_scene(rng, n)]
    for t in range(T):
        s = states[-1].copy()
        b = int(rng.choice(goal_blocks)) if rng.random() < 0.6 else int(rng.integers(n))
        s[b, :2] = X_BINS[rng.integers(37)], (rng.integers(3) + 0.5) * BLOCK_H
        if fall and t == T - 1:
            s[b, :2] = 0.6, -0.475                       # off the edge, onto the catch floor
        states.append(s)
    goals = {int(b): (float(X_BINS[rng.integers(37)]), BLOCK_H / 2) for b in goal_blocks}
    return dict(goals=goals, states=np.stack(states), actions=rng.integers(0, 6, (T, 3)))


def _make_select(n, K, seed):
    """s0, sT and K candidates, each one alteration (taskexp.alter) of a one-goal task."""
    rng = np.random.default_rng(seed)
    s0, sT = _scene(rng, n), _scene(rng, n)
    cands = [taskexp.alter({int(rng.integers(n)): (0.0, BLOCK_H / 2)}, tiny_env(n), rng)
             for _ in range(K)]
    return dict(s0=s0, sT=sT, cands=cands[:8] * 2 if K == 16 and seed % 2 else cands)


def _make_relabel(n, T, blocks, fall, seed, still):
    traj = _trajectory(np.random.default_rng(seed), n, T, blocks, fall)
    if still:
        traj["states"][1:, blocks[0]] = traj["states"][0, blocks[0]]   # the goal block stays
    want = taskexp.relabel(taskexp.Trajectory(**traj, success=False), tiny_env(n))
    return dict(traj=traj, want=want and dict(goals=want.goals, states=want.states,
                                              actions=want.actions, success=want.success))


@graded
def check_ex6(select_goal, relabel):
    """select_goal(agent, s0, sT, candidates) -> index of g*;  relabel(traj, env) -> Trajectory
    or None."""
    rep, critic = Report("ex6"), DistanceCritic()
    for seed, K in enumerate([1, 2, 8, 8, 16, 16, 32]):
        n = 4 + seed % 3
        c = case(f"ex6/select/{seed}", lambda: _make_select(n, K, 600 + seed))
        s0, sT, cands = c["s0"], c["sT"], c["cands"]       # ties when K == 16 and seed is odd
        v0, vT = critic.value(np.stack([observation(s0, g) for g in cands])), critic.value(
            np.stack([observation(sT, g) for g in cands]))
        want = int(np.argmax(vT - v0))
        got, err = call(select_goal, critic, s0, sT, cands)
        hint = ("equation (1): g* = argmax_g V(s_T, g) - V(s_0, g), "
                "with V from agent.value(observation(s, g))"
                + ("; on ties the first index, as np.argmax" if K == 16 and seed % 2 else ""))
        wrong = [(np.argmax(vT), "argmax V(s_T, g) alone (end2new): also subtract V(s_0, g)"),
                 (np.argmin(v0), "argmin V(s_0, g) alone (init2new): also add V(s_T, g)"),
                 (np.argmax(v0 - vT), "argmax V(s_0, g) - V(s_T, g): the sign is reversed")]
        if err is None and got != want:
            err = f"got index {got}, expected {want} (scores {np.round(vT - v0, 3).tolist()})"
            guesses = [h for i, h in wrong if i == got]
            hint = "did you pick " + " -- or ".join(guesses) if guesses else hint
        rep.case(f"select_goal, K={K} candidates", f"n={n}, seed {600 + seed}", err, hint)
    fell = "return None when a block fell off the table (taskexp.on_table(s_T, env) is False)"
    cases = [("random", 4, 3, [1], False), ("random, two goal blocks", 5, 4, [0, 2], False),
             ("long, three goal blocks", 6, 6, [1, 2, 4], False), ("one step", 3, 1, [0], False),
             ("a block fell off the table", 4, 3, [1], True)] + [
                 ("random", 4 + s % 3, 2 + s % 4, [s % 4], False) for s in range(8)]
    for seed, (name, n, T, blocks, fall) in enumerate(cases):
        if seed == 6:
            name = "goal blocks end where they started"
        c = case(f"ex6/relabel/{seed}",
                 lambda: _make_relabel(n, T, blocks, fall, 650 + seed, seed == 6))
        want = c["want"]
        got, err = call(relabel, taskexp.Trajectory(**c["traj"], success=False), tiny_env(n))
        hint = {True: fell, False: "the new goals are where traj.goals' blocks rest in s_T "
                "(only those blocks); cut at the first t >= 1 where they hold: states[:t+1], "
                "actions[:t], success=True; return None if they already hold at s_0 "
                "(nothing achieved)"}[fall]
        if err is None and (got is None) != (want is None):
            err = (f"got {'None' if got is None else 'a trajectory'}, "
                   f"expected {'None' if want is None else 'one'}")
        elif err is None and want is not None:
            try:
                err = (f"goal blocks {sorted(got.goals)}, expected {sorted(want['goals'])}"
                       if sorted(got.goals) != sorted(want["goals"]) else
                       first(*(diff(f"goals[{b}]", got.goals[b], want["goals"][b])
                               for b in want["goals"]),
                             diff("states", got.states, want["states"]),
                             diff("actions", got.actions, want["actions"]),
                             None if bool(got.success)
                             else f"success={got.success!r}, expected True"))
            except Exception as e:
                err = f"the returned trajectory is malformed ({type(e).__name__}: {e})"
        rep.case(f"relabel, {name}", f"n={n}, T={T}, goal blocks {blocks}, seed {650 + seed}",
                 err, hint)
    rep.done(" (select_goal follows equation (1); relabel agrees with the reference, "
             "taskexp.relabel)")
