"""exercises/checks.py -- the checks of exercises 1-6, and the reporting they share.  ~420 lines.

Each check_exN(student functions) runs them on fixed random inputs of varied shapes plus edge cases,
compares with the library (REFERENCE), prints PASS or FAIL (the case, expected vs got, a hint), and
returns True/False.  Every case has its own seed, so a check is deterministic.
"""
import copy
import traceback
from types import SimpleNamespace

import numpy as np

import agent
import taskexp
from env2d import BLOCK_H, TABLE_X, THRESHOLD, X_BINS, layer_y, observation


def tiny_env(n_blocks):
    """What ex5/ex6 may use of a BlockWorld: n_blocks, x_bins (37,), y_bins (n_blocks,), table_x,
    threshold; all from env2d's geometry."""
    return SimpleNamespace(n_blocks=n_blocks, x_bins=X_BINS.copy(),
                           y_bins=layer_y(np.arange(n_blocks)),
                           table_x=TABLE_X, threshold=THRESHOLD)


# ---- Reference solutions: the library, in the students' signatures --------------------------

def _ref_logp_entropy(out, actions, n_x):
    d = agent.ActionDist(out, n_x)
    return d.log_prob(actions), d.entropy()


REFERENCE = dict(
    mlp_backward=agent.mlp_backward, logp_entropy=_ref_logp_entropy,
    logp_entropy_backward=lambda out, actions, n_x, a, c:
        agent.ActionDist(out, n_x).backward(actions, a, c),
    gae=agent.gae, ppo_loss=lambda *args, **kw: agent.ppo_loss(*args, **kw)[:2],
    alter=lambda goals, env, rng: taskexp.alter(goals, env, rng),
    select_goal=lambda ag, s0, sT, cands: taskexp.select_goal(ag, s0, sT, cands)[0],
    relabel=taskexp.relabel)


# ---- Reporting ---------------------------------------------------------------------------------

class Report:
    """Collects failing cases; prints PASS, or FAIL with the first failure in detail."""

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
            return True
        name, detail, problem, hint = self.failures[0]
        print(f"{self.name} FAIL: case {name!r} ({detail})\n  {problem}")
        if hint and "NotImplementedError" not in problem:
            print(f"  hint: {hint}")
        if len(self.failures) > 1:
            others = list(dict.fromkeys(f[0] for f in self.failures[1:]))
            print(f"  ({len(self.failures)} of {self.cases} cases failed; "
                  f"also: {'; '.join(others[:5])})")
        return False


NOT_DONE = ("raised NotImplementedError: not done yet "
            "(replace `raise NotImplementedError()` by your code)")


def call(fn, *args, **kw):
    """fn(*args) -> (result, None), or (None, what it raised) -- a student's code may raise."""
    try:
        return fn(*copy.deepcopy(args), **kw), None    # copies: the student cannot spoil our inputs
    except NotImplementedError:
        return None, NOT_DONE
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


def first(*problems):
    return next((p for p in problems if p), None)


# ---- ex1: the MLP backward pass ------------------------------------------------------------------

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
        net = agent.MLP(sizes, seed=seed)
        rng = np.random.default_rng(seed)
        for k in range(net.n_layers):
            net.params[f"W{k}"] *= scale
            net.params[f"b{k}"] += 0.3 * rng.standard_normal(sizes[k + 1])
        x, dout = rng.standard_normal((B, sizes[0])), rng.standard_normal((B, sizes[-1]))
        net.forward(x)
        want, want_dx = agent.mlp_backward(net.params, net.hs, dout)
        detail = f"sizes {sizes}, B={B}, seed {seed}"
        res, err = call(mlp_backward, net.params, net.hs, dout)
        if err is None and not (isinstance(res, tuple) and len(res) == 2
                                and isinstance(res[0], dict)):
            err = f"returned {type(res).__name__}, expected a tuple (grads dict, dx)"
        if err:
            rep.case(name, detail, err, hint)
            continue
        grads, dx = res
        missing = sorted(set(want) - set(grads))
        rep.case(name, detail, f"grads has no key {missing[0]!r}" if missing else
                 first(*(diff(f"grads[{k!r}]", grads[k], want[k]) for k in want),
                       diff("dx", dx, want_dx)), hint)
        if name == "two layers" and not rep.failures:     # and against the definition of a gradient
            f = lambda: np.sum(net.forward(x) * dout)      # L = sum(out * dout) has dL/dout = dout
            rep.case("finite differences", detail,
                     first(*(diff(f"grads[{k!r}] vs finite differences", grads[k],
                                  numerical_grad(f, p), 1e-5, 1e-6)
                             for k, p in net.params.items())), hint)
    return rep.done(" (agrees with agent.mlp_backward and central finite differences)")


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

def check_ex2(logp_entropy, logp_entropy_backward):
    """logp_entropy(out, actions, n_x) -> (logp (B,), H (B,)); logp_entropy_backward(out, actions,
    n_x, a (B,), c (B,)) -> d/dout of sum_k a_k logp_k + c_k H_k (B, n, 1 + n_x + n_y)."""
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
        rng = np.random.default_rng(100 + seed)
        out = scale * rng.standard_normal((B, n, 1 + n_x + n_y))
        actions = np.stack([rng.integers(n, size=B), rng.integers(n_x, size=B),
                            rng.integers(n_y, size=B)], 1)
        a, c = rng.standard_normal(B), rng.standard_normal(B)
        detail = f"B={B}, n={n}, n_x={n_x}, n_y={n_y}, seed {100 + seed}"
        want_lp, want_h = _ref_logp_entropy(out, actions, n_x)
        res, err = call(logp_entropy, out, actions, n_x)
        if err is None and not (isinstance(res, tuple) and len(res) == 2):
            err = f"logp_entropy returned {type(res).__name__}, expected a tuple (logp, H)"
        rep.case(name, detail,
                 err or first(diff("logp", res[0], want_lp), diff("H", res[1], want_h)), hint)
        d, err = call(logp_entropy_backward, out, actions, n_x, a, c)
        want_d = agent.ActionDist(out, n_x).backward(actions, a, c)
        rep.case("backward, " + name, detail,
                 err and "logp_entropy_backward " + err or diff("dout", d, want_d),
                 hint if scale > 100 else grad)
    return rep.done(" (logp, H and their gradient agree with agent.ActionDist)")


# ---- ex3: generalised advantage estimation -------------------------------------------------------

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
        rng = np.random.default_rng(200 + seed)
        r, v, nv = rng.random((T, N)), rng.standard_normal((T, N)), rng.standard_normal((T, N))
        te, tr = (rng.random((T, N)) < p_term) * 1.0, (rng.random((T, N)) < p_trunc) * 1.0
        want_adv, want_ret = agent.gae(r, v, te, tr, nv, gamma, lam)
        res, err = call(gae, r, v, te, tr, nv, gamma, lam)
        if err is None and not (isinstance(res, tuple) and len(res) == 2):
            err = f"returned {type(res).__name__}, expected a tuple (advantages, returns)"
        detail = f"T={T}, N={N}, gamma={gamma}, lam={lam}, seed {200 + seed}"
        rep.case(name, detail, err or first(diff("advantages", res[0], want_adv),
                                     diff("returns", res[1], want_ret)), hint)
    return rep.done(" (agrees with agent.gae)")


# ---- ex4: the PPO clipped surrogate --------------------------------------------------------------

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
        rng = np.random.default_rng(300 + seed)
        out = rng.standard_normal((B, n, 1 + n_x + n_y))
        actions = np.stack([rng.integers(n, size=B), rng.integers(n_x, size=B),
                            rng.integers(n_y, size=B)], 1)
        r = rng.uniform(1 - lo, 1 + hi, B)
        if lo >= 0.5:
            r = np.where(rng.random(B) < 0.5, rng.uniform(1.3, 1.6, B), rng.uniform(0.4, 0.7, B))
        logp_old = agent.ActionDist(out, n_x).log_prob(actions) - np.log(r)
        adv = rng.standard_normal(B)
        want_l, want_d = agent.ppo_loss(out, actions, logp_old, adv, n_x, clip, ent)[:2]
        res, err = call(ppo_loss, out, actions, logp_old, adv, n_x, clip, ent)
        if err is None and not (isinstance(res, tuple) and len(res) >= 2):
            err = f"returned {type(res).__name__}, expected a tuple (L, dL/dout)"
        detail = (f"B={B}, n={n}, n_x={n_x}, n_y={n_y}, clip={clip}, ent_coef={ent}, "
                  f"seed {300 + seed}")
        problem = err or first(diff("L", res[0], want_l), diff("dL/dout", res[1], want_d))
        rep.case(name, detail, problem, loss if problem and "sign error" in problem else hint)
    return rep.done(" (L and dL/dout agree with agent.ppo_loss)")


# ---- ex5: one-alteration task sampling (sec 4.2) -------------------------------------------------

def as_goals(goals):
    """{block: (x, y)} with plain ints and floats, so dicts of numpy values compare with ==."""
    out = {int(b): tuple(map(float, p)) for b, p in goals.items()}
    if any(len(p) != 2 for p in out.values()):
        raise ValueError("a goal position is a pair (x, y)")
    return out


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
    return rep.done(f" ({samples} samples each: one alteration, both kinds, every block, "
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
    return taskexp.Trajectory(goals, np.stack(states), rng.integers(0, 6, (T, 3)), False)


def check_ex6(select_goal, relabel):
    """select_goal(agent, s0, sT, candidates) -> index of g*;  relabel(traj, env) -> Trajectory
    or None."""
    rep, critic = Report("ex6"), DistanceCritic()
    for seed, K in enumerate([1, 2, 8, 8, 16, 16, 32]):
        rng, n = np.random.default_rng(600 + seed), 4 + seed % 3
        s0, sT = _scene(rng, n), _scene(rng, n)
        cands = [taskexp.alter({int(rng.integers(n)): (0.0, BLOCK_H / 2)}, tiny_env(n), rng)
                 for _ in range(K)]
        if K == 16 and seed % 2:
            cands = cands[:8] * 2                         # ties: argmax takes the first
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
        rng = np.random.default_rng(650 + seed)
        traj = _trajectory(rng, n, T, blocks, fall)
        if seed == 6:
            traj.states[1:, blocks[0]] = traj.states[0, blocks[0]]   # the goal block never moves
            name = "goal blocks end where they started"
        want = taskexp.relabel(traj, tiny_env(n))
        got, err = call(relabel, traj, tiny_env(n))
        hint = {True: fell, False: "the new goals are where traj.goals' blocks rest in s_T "
                "(only those blocks); cut at the first t >= 1 where they hold: states[:t+1], "
                "actions[:t], success=True; return None if they already hold at s_0 "
                "(nothing achieved)"}[fall]
        if err is None and (got is None) != (want is None):
            err = (f"got {'None' if got is None else 'a trajectory'}, "
                   f"expected {'None' if want is None else 'one'}")
        elif err is None and want is not None:
            try:
                err = (f"goal blocks {sorted(got.goals)}, expected {sorted(want.goals)}"
                       if sorted(got.goals) != sorted(want.goals) else
                       first(*(diff(f"goals[{b}]", got.goals[b], want.goals[b])
                               for b in want.goals),
                             diff("states", got.states, want.states),
                             diff("actions", got.actions, want.actions),
                             None if bool(got.success)
                             else f"success={got.success!r}, expected True"))
            except Exception as e:
                err = f"the returned trajectory is malformed ({type(e).__name__}: {e})"
        rep.case(f"relabel, {name}", f"n={n}, T={T}, goal blocks {blocks}, seed {650 + seed}",
                 err, hint)
    return rep.done(" (select_goal follows equation (1); relabel agrees with taskexp.relabel)")
