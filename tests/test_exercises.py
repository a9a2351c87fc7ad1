"""Tests of the problem set (course, course/notebooks/): the checks must be able
to fail.

Every reference solution passes its check (the library's and the instructor notebooks'); every
released stub fails it; plausible wrong answers -- a sign error, a missing mask, an off-by-one in
GAE, ... -- fail it with a hint that names the mistake, in the message of an AssertionError.  Also:
the student's ActionDist (exercise 2) behaves as the library's, the checks write nothing to stderr,
the CLI, and the instructor notebooks run top to bottom. tests/test_kit.py tests the student kit,
tests/test_grader.py grades with nbgrader."""
import copy
import json
import os
import re
import shutil
import subprocess
import sys

import nbclient
import nbformat
import numpy as np
import pytest

import agent
import course as exercises
import taskexp
from taskexp_lib import hindsight, nn
from taskexp_lib.geometry import BLOCK_H, BLOCK_W, is_success

R = exercises.REFERENCE
ROOT = exercises.kit.REPOSITORY                                                   # the repository
SIMPLE = ["ex1", "ex2", "ex3", "ex4", "ex5", "ex6", "ex8", "ex9", "ex10", "ex11"]   # not ex7


def instructor(ex):
    return os.path.join(exercises.NOTEBOOK_DIR, exercises.NOTEBOOKS[ex])


def run_check(ex, *fns):
    """True if the check passes; False if it raises AssertionError (its message printed)."""
    return exercises.passes(exercises.CHECKS[ex], *fns)


@pytest.fixture(scope="module")
def released(tmp_path_factory):
    """The student kit (its notebooks are the released ones; this process checks them with the
    repository's exercises package, on the full library)."""
    out = tmp_path_factory.mktemp("release")
    exercises.kit.release(str(out))
    return out


# ---- reference solutions pass, stubs fail --------------------------------------------------------

@pytest.mark.parametrize("ex", SIMPLE)
def test_library_reference_passes(ex, capsys):
    assert run_check(ex, *(R[f] for f in exercises.FUNCTIONS[ex]))
    assert f"{ex} PASS" in capsys.readouterr().out


@pytest.mark.parametrize("ex", SIMPLE)
def test_instructor_notebook_solution_passes(ex):
    assert run_check(ex, *exercises.functions(ex, instructor(ex)))


@pytest.mark.parametrize("ex", SIMPLE + ["ex7", "ex12"])
def test_released_stub_fails(ex, released, capsys):
    nb = os.path.join(released, exercises.NOTEBOOKS[ex])
    assert not run_check(ex, *exercises.functions(ex, nb))
    assert "NotImplementedError" in capsys.readouterr().out


# ---- plausible wrong answers fail, with a hint that points at the mistake ------------------------

def mlp_backward_variant(tanh_grad=lambda h: 1 - h ** 2, bias=lambda d: d.sum(0), last_tanh=False):
    def backward(params, hs, dout):
        L, grads, d = len(params) // 2, {}, dout
        for k in reversed(range(L)):
            if k < L - 1 or last_tanh:
                d = d * tanh_grad(hs[k + 1])
            grads[f"W{k}"], grads[f"b{k}"] = hs[k].T @ d, bias(d)
            d = d @ params[f"W{k}"].T
        return grads, d
    return backward


def naive_logp_entropy(out, actions, n_x):
    """exp without subtracting the max: overflows for extreme logits."""
    with np.errstate(all="ignore"):
        ls = lambda z: np.log(np.exp(z) / np.exp(z).sum(-1, keepdims=True))
        d = copy.copy(agent.ActionDist(out, n_x))
        d.lb, d.lx, d.ly = ls(out[..., 0]), ls(out[..., 1:1 + n_x]), ls(out[..., 1 + n_x:])
        d.pb = np.exp(d.lb)
        d.hb, d.hx, d.hy = (-(np.exp(lp) * lp).sum(-1) for lp in (d.lb, d.lx, d.ly))
        return d.log_prob(actions), d.entropy()


def unweighted_entropy(out, actions, n_x):
    """H(b) + mean over blocks of the heads' entropies: forgets the weights pi(b)."""
    d = agent.ActionDist(out, n_x)
    return d.log_prob(actions), d.hb + (d.hx + d.hy).mean(-1)


def backward_without_weight_term(out, actions, n_x, a, c):
    """Drops pi(b) (K_b - Kbar) from dH/dl."""
    d = agent.ActionDist(out, n_x)
    dout = d.backward(actions, a, c)
    K = d.hx + d.hy
    dout[..., 0] -= c[:, None] * d.pb * (K - (d.pb * K).sum(-1, keepdims=True))
    return dout


def gae_variant(bootstrap="term", trace="done", next_from="next_values", shift=0):
    def gae(r, v, te, tr, nv, gamma, lam):
        done = np.maximum(te, tr)
        mask_b = {"term": te, "done": done}[bootstrap]
        mask_t = {"done": done, "term": te}[trace]
        adv, last = np.zeros_like(r), np.zeros(r.shape[1:])
        for t in reversed(range(len(r))):
            nxt = (nv[t] if next_from == "next_values"
                   else (v[t + 1] if t + 1 < len(r) else 0 * v[t]))
            delta = r[t] + gamma * nxt * (1 - mask_b[t]) - v[t]
            m = mask_t[t + shift] if t + shift < len(r) else 0 * v[t]
            last = delta + gamma * lam * (1 - m) * last
            adv[t] = last
        return adv, adv + v
    return gae


def ppo_variant(sign=1.0, tie="<=", through_clip=False, outer=np.minimum):
    def ppo_loss(out, actions, logp_old, adv, n_x, clip=0.2, ent_coef=0.0):
        dist, B = agent.ActionDist(out, n_x), len(actions)
        r = np.exp(dist.log_prob(actions) - logp_old)
        u, c = r * adv, np.clip(r, 1 - clip, 1 + clip) * adv
        L = -sign * outer(u, c).mean() - ent_coef * dist.entropy().mean()
        use_u = u <= c if tie == "<=" else u < c
        if outer is np.maximum:
            use_u = u >= c
        g = np.where(use_u, u, c if through_clip else 0.0)   # the clipped term has no gradient
        return L, dist.backward(actions, -sign * g / B, -ent_coef / B)
    return ppo_loss


def others_spots(goals, b):
    return [p for other, p in goals.items() if other != b]


def alter_always_add(goals, env, rng):
    new, free = dict(goals), [b for b in range(env.n_blocks) if b not in goals]
    b = int(rng.choice(free)) if free else int(rng.choice(list(goals)))
    new[b] = taskexp.random_position(env, rng, others_spots(goals, b))
    return new


def alter_mostly_add(goals, env, rng):
    """Adds three times in four where a block is free: both kinds occur, not half the time each."""
    new, free = dict(goals), [b for b in range(env.n_blocks) if b not in goals]
    b = int(rng.choice(free)) if free and rng.random() < 0.75 else int(rng.choice(list(goals)))
    new[b] = taskexp.random_position(env, rng, others_spots(goals, b))
    return new


def alter_on_any_spot(goals, env, rng):
    """A new position anywhere on the grid, another goal's spot included."""
    new, free = dict(goals), [b for b in range(env.n_blocks) if b not in goals]
    b = int(rng.choice(free)) if free and rng.random() < 0.5 else int(rng.choice(list(goals)))
    new[b] = float(env.x_bins[rng.integers(37)]), float(env.y_bins[rng.integers(env.n_blocks)])
    return new


def alter_two_changes(goals, env, rng):
    new = R["alter"](goals, env, rng)
    return R["alter"](new, env, rng)


def alter_in_place(goals, env, rng):
    new = R["alter"](goals, env, rng)
    goals.update(new)
    return goals


def alter_off_grid(goals, env, rng):
    """Continuous x instead of the grid's bins."""
    new, free = dict(goals), [b for b in range(env.n_blocks) if b not in goals]
    b = int(rng.choice(free)) if free and rng.random() < 0.5 else int(rng.choice(list(goals)))
    new[b] = float(rng.uniform(-0.45, 0.45)), float(env.y_bins[rng.integers(env.n_blocks)])
    return new


def alter_global_rng(goals, env, rng):
    return R["alter"](goals, env, np.random.default_rng(np.random.randint(2 ** 31)))


def select_end2new(ag, s0, sT, cands):
    return int(np.argmax(ag.value(np.stack([taskexp.observation(sT, g) for g in cands]))))


def select_reversed(ag, s0, sT, cands):
    obs = lambda s: np.stack([taskexp.observation(s, g) for g in cands])
    return int(np.argmax(ag.value(obs(s0)) - ag.value(obs(sT))))


def relabel_no_cut(traj, env):
    r = R["relabel"](traj, env)
    return r and taskexp.Trajectory(r.goals, traj.states, traj.actions, True)


def relabel_variant(blocks="goal", check_table=True):
    def relabel(traj, env):
        sT = traj.states[-1]
        if check_table and not taskexp.on_table(sT, env):
            return None
        goals = {b: (float(sT[b, 0]), float(sT[b, 1]))
                 for b in (traj.goals if blocks == "goal" else range(len(sT)))}
        if is_success(traj.states[0], goals, env.threshold):
            return None
        T = next(t for t in range(1, len(traj.states))
                 if is_success(traj.states[t], goals, env.threshold))
        return taskexp.Trajectory(goals, traj.states[:T + 1], traj.actions[:T], True)
    return relabel


def expansion_variant(mistake):
    """An expansion step (exercise 9) with one classic mistake."""
    def expansion_step(agent, found, cfg, env, short_envs, rng, pieces, bar=None):
        asked = [taskexp.candidates(t, env, rng, cfg, pieces.alter) for t in found]
        chosen = []
        for t, cands in zip(found, asked):
            s0, sT = t.states[0], t.states[-1]
            if mistake == "s0 and sT swapped":
                s0, sT = sT, s0
            chosen.append(cands[pieces.select_goal(agent, s0, sT, cands)])
        start = [(t.states[0] if mistake == "run from s0" else t.states[-1], g)
                 for t, g in zip(found, chosen)]
        runs = taskexp.run_episodes(agent, start, short_envs, rng, values=False)
        demos = []
        for t, g, more in zip(found, chosen, runs):
            joined = {"no prefix": lambda: taskexp.Trajectory(g, more.states, more.actions,
                                                              more.success),
                      "sT twice": lambda: taskexp.Trajectory(
                          g, np.concatenate([t.states, more.states]),
                          np.concatenate([t.actions, more.actions]), more.success)}.get(
                mistake, lambda: R["join"](t, more, g, more.success))()
            demo = joined if more.success else pieces.relabel(
                t if mistake == "relabel the first trajectory" else joined, env)
            if demo is not None or mistake == "keeps None":
                demos.append(demo)
        reached = [True] * len(runs) if mistake == "reached always" else [r.success for r in runs]
        return demos, reached
    return expansion_step


def join_without_prefix(first, second, goals, success):
    return taskexp.Trajectory(goals, second.states, second.actions, success)


def distillation_data_variant(mistake):
    """BC's data (exercise 10) with one mistake."""
    def distillation_data(run, demos, cfg):
        taught = demos if mistake == "demos only" else hindsight.learnt_from(demos)
        obs, actions = taskexp.demo_arrays(taught)
        if mistake == "new only":
            return obs[-cfg.buffer_size:], actions[-cfg.buffer_size:]
        obs, actions = (np.concatenate(p) for p in ((run.buffer_obs, obs),
                                                    (run.buffer_act, actions)))
        keep = slice(None, cfg.buffer_size) if mistake == "oldest kept" else \
            slice(-cfg.buffer_size, None)
        return obs[keep], actions[keep]
    return distillation_data


def distillation_tasks_variant(mistake):
    """PPO's tasks (exercise 10) with one mistake."""
    def distillation_tasks(run, demos, rng):
        parts = lambda d: {"no parts": [], "other orders too": [
            o for o in [d.other_order] if o is not None] + d.parts}.get(mistake, d.parts)
        new = [(t.states[-1 if mistake == "last state" else 0], t.goals)
               for d in demos for t in (d, *parts(d))]
        if mistake == "new only":
            return new, []
        pool = run.prev_tasks if mistake == "from the last round only" else run.all_tasks
        rng = np.random.default_rng(0) if mistake == "own seed" else rng
        idx = (rng.permutation(len(pool))[:len(new)] if mistake == "without replacement"
               else rng.integers(len(pool), size=len(new)))
        return new, [pool[i] for i in idx]
    return distillation_tasks


def select_modes_variant(mistake):
    """select_goal with modes (exercise 11) with one mistake."""
    def select_goal(ag, s0, sT, cands, mode="ours"):
        v = lambda s: ag.value(np.stack([taskexp.observation(s, g) for g in cands]))
        if mistake == "ours is end2new" and mode == "ours":
            mode = "end2new"
        if mode == "end2new":
            return int(np.argmax(v(sT)))
        if mode == "init2new":
            return int(np.argmax(v(s0)) if mistake == "init2new easiest" else np.argmin(v(s0)))
        return int(np.argmax(v(sT) - v(s0)))
    return select_goal


def one_drop_variant(mistake):
    """one_drop_away (exercise 11) with one mistake."""
    def one_drop_away(state, goals, threshold):
        for b, (gx, gy) in goals.items():
            met = np.hypot(state[b, 0] - gx, state[b, 1] - gy) < threshold
            if met and mistake != "met goals judged too":
                continue
            near = lambda j, dx, dy: abs(state[j, 0] - gx) < dx and abs(state[j, 1] - dy) < \
                0.95 * BLOCK_H * (dy == gy) + BLOCK_H / 2 * (dy != gy)
            others = [j for j in range(len(state)) if j != b]
            blocked = any(near(j, 0.95 * BLOCK_W, gy) for j in others)
            held = gy < BLOCK_H or any(near(j, BLOCK_W / 2, gy - BLOCK_H) for j in others)
            if (blocked and mistake != "ignores blocks in the way") or \
                    (not held and mistake != "ignores support"):
                return False
        return True
    return one_drop_away


def attention_variant(jacobian="full", scale=True, dq="dS K", dk="dS^T Q", dx_from="qkv",
                      dv="A^T dY"):
    """The backward of check_ex8 with one classic mistake (the defaults are right)."""
    def attention_backward(params, cache, dout):
        x, h = cache["x"], cache["heads"]
        B, n, D = x.shape
        A, Q, K, V = cache["attn"], cache["Q"], cache["K"], cache["V"]
        split = lambda z: z.reshape(B, n, h, D // h).transpose(0, 2, 1, 3)
        merge = lambda z: z.transpose(0, 2, 1, 3).reshape(B * n, D)
        g, x2 = dout.reshape(B * n, D), x.reshape(B * n, D)
        grads = {"Wo": cache["Y"].reshape(B * n, D).T @ g, "bo": g.sum(0)}
        dY = split(g @ params["Wo"].T)
        dA = dY @ V.swapaxes(-1, -2)
        dV = A.swapaxes(-1, -2) @ dY if dv == "A^T dY" else A @ dY
        if jacobian == "full":
            dS = A * (dA - (A * dA).sum(-1, keepdims=True))
        elif jacobian == "elementwise":
            dS = A * (1 - A) * dA                        # the diagonal of the Jacobian only
        else:
            dS = dA                                      # no softmax at all
        dS = dS * {True: cache["scale"], False: 1.0, "D": 1 / np.sqrt(D)}[scale]
        dQ = dS @ K if dq == "dS K" else dS.swapaxes(-1, -2) @ K
        dK = dS.swapaxes(-1, -2) @ Q if dk == "dS^T Q" else dS @ Q
        dx = np.zeros((B * n, D))
        for c, dz in zip("qkv", (dQ, dK, dV)):
            dz = merge(dz)
            grads["W" + c], grads["b" + c] = x2.T @ dz, dz.sum(0)
            if c in dx_from:
                dx += dz @ params["W" + c].T
        return grads, dx.reshape(B, n, D)
    return attention_backward


WRONG = {   # (exercise, the student's functions with one mistake, a phrase the check must print)
    "ex1 1 - h instead of 1 - h^2":
        ("ex1", [mlp_backward_variant(tanh_grad=lambda h: 1 - h)], "1 - h^2"),
    "ex1 bias grad averaged": ("ex1", [mlp_backward_variant(bias=lambda d: d.mean(0))], "grads['b"),
    "ex1 tanh' on the linear output": ("ex1", [mlp_backward_variant(last_tanh=True)], "no tanh"),
    "ex2 softmax without max":
        ("ex2", [naive_logp_entropy, R["logp_entropy_backward"]], "log-sum-exp"),
    "ex2 entropy unweighted":
        ("ex2", [unweighted_entropy, R["logp_entropy_backward"]], "sum_b pi(b)"),
    "ex2 backward drops K_b - Kbar":
        ("ex2", [R["logp_entropy"], backward_without_weight_term], "K_b"),
    "ex3 no bootstrap on truncation": ("ex3", [gae_variant(bootstrap="done")], "still bootstrap"),
    "ex3 trace not cut at truncation": ("ex3", [gae_variant(trace="term")], "cut the recursion"),
    "ex3 off by one: next step's done": ("ex3", [gae_variant(shift=1)], "flags of step t"),
    "ex3 values[t+1] for V(s_t+1)": ("ex3", [gae_variant(next_from="values")], "next_values"),
    "ex4 sign error": ("ex4", [ppo_variant(sign=-1.0)], "is minimised"),
    "ex4 strict < at ratio 1": ("ex4", [ppo_variant(tie="<")], "at r = 1"),
    "ex4 gradient through the clipped term":
        ("ex4", [ppo_variant(through_clip=True)], "no gradient"),
    "ex4 max instead of min": ("ex4", [ppo_variant(outer=np.maximum)], "min of the two"),
    "ex5 always add": ("ex5", [alter_always_add], "50/50"),
    "ex5 adds three times in four": ("ex5", [alter_mostly_add], "half the time each"),
    "ex5 a goal on another goal's spot": ("ex5", [alter_on_any_spot], "on_same_spot"),
    "ex5 two alterations": ("ex5", [alter_two_changes], "ONE"),
    "ex5 changes its input": ("ex5", [alter_in_place], "dict(goals)"),
    "ex5 off the grid": ("ex5", [alter_off_grid], "grid"),
    "ex5 global random state": ("ex5", [alter_global_rng], "draw only from rng"),
    "ex6 end2new": ("ex6", [select_end2new, R["relabel"]], "end2new"),
    "ex6 sign reversed": ("ex6", [select_reversed, R["relabel"]], "reversed"),
    "ex6 relabel without the cut": ("ex6", [R["select_goal"], relabel_no_cut], "cut at the first"),
    "ex6 relabel every block":
        ("ex6", [R["select_goal"], relabel_variant(blocks="all")], "only those blocks"),
    "ex6 relabel ignores falls":
        ("ex6", [R["select_goal"], relabel_variant(check_table=False)], "fell off"),
    "ex8 softmax derivative p (1 - p)":
        ("ex8", [attention_variant(jacobian="elementwise")], "softmax Jacobian"),
    "ex8 no softmax derivative": ("ex8", [attention_variant(jacobian="none")], "softmax Jacobian"),
    "ex8 no 1/sqrt(d) in the backward": ("ex8", [attention_variant(scale=False)], "1/sqrt(d)"),
    "ex8 1/sqrt(D) instead of 1/sqrt(d)": ("ex8", [attention_variant(scale="D")], "d = D / heads"),
    "ex8 transposed keys": ("ex8", [attention_variant(dq="dS^T K", dk="dS Q")], "transposed keys"),
    "ex8 dQ with dS^T": ("ex8", [attention_variant(dq="dS^T K")], "dQ = dS K"),
    "ex8 dK with dS": ("ex8", [attention_variant(dk="dS Q")], "dK = dS^T Q"),
    "ex8 dx through V only": ("ex8", [attention_variant(dx_from="v")], "x feeds Q, K and V"),
    "ex8 dx through Q only": ("ex8", [attention_variant(dx_from="q")], "x feeds Q, K and V"),
    "ex8 dV = A dY": ("ex8", [attention_variant(dv="A dY")], "dV = A^T dY"),
    "ex9 join without the prefix":
        ("ex9", [join_without_prefix, R["expansion_step"]], "starts at s0"),
    "ex9 demonstration without the prefix":
        ("ex9", [R["join"], expansion_variant("no prefix")], "joined trajectory"),
    "ex9 s_T twice": ("ex9", [R["join"], expansion_variant("sT twice")], "appears once"),
    "ex9 relabel the first trajectory":
        ("ex9", [R["join"], expansion_variant("relabel the first trajectory")], "joined"),
    "ex9 s0 and sT swapped": ("ex9", [R["join"], expansion_variant("s0 and sT swapped")],
                              "select_goal"),
    "ex9 run from s0": ("ex9", [R["join"], expansion_variant("run from s0")], "joined"),
    "ex9 keeps None": ("ex9", [R["join"], expansion_variant("keeps None")], "leave it out"),
    "ex9 reached always": ("ex9", [R["join"], expansion_variant("reached always")], "reached"),
    "ex10 the demonstrations alone": ("ex10", [distillation_data_variant("demos only"),
                                               R["distillation_tasks"]], "other order"),
    "ex10 new steps only": ("ex10", [distillation_data_variant("new only"),
                                     R["distillation_tasks"]], "kept buffer"),
    "ex10 the oldest steps kept": ("ex10", [distillation_data_variant("oldest kept"),
                                            R["distillation_tasks"]], "newest"),
    "ex10 new tasks only, no old ones": ("ex10", [R["distillation_data"],
                                                  distillation_tasks_variant("new only")],
                                         "as many old tasks"),
    "ex10 no parts": ("ex10", [R["distillation_data"], distillation_tasks_variant("no parts")],
                      "parts"),
    "ex10 other orders as tasks": ("ex10", [R["distillation_data"],
                                            distillation_tasks_variant("other orders too")],
                                   "same task again"),
    "ex10 the last state as s0": ("ex10", [R["distillation_data"],
                                           distillation_tasks_variant("last state")], "s0"),
    "ex10 old tasks of the last round only":
        ("ex10", [R["distillation_data"], distillation_tasks_variant("from the last round only")],
         "every earlier"),
    "ex10 a seed of its own": ("ex10", [R["distillation_data"],
                                        distillation_tasks_variant("own seed")], "rng passed in"),
    "ex10 without replacement": ("ex10", [R["distillation_data"],
                                          distillation_tasks_variant("without replacement")],
                                 "with replacement"),
    "ex11 ours is end2new": ("ex11", [select_modes_variant("ours is end2new"),
                                      R["one_drop_away"]], "end2new"),
    "ex11 init2new picks the easiest": ("ex11", [select_modes_variant("init2new easiest"),
                                                 R["one_drop_away"]], "argmin_g V(s_0"),
    "ex11 a block in the way ignored": ("ex11", [R["select_goal"],
                                                 one_drop_variant("ignores blocks in the way")],
                                        "overlaps its spot"),
    "ex11 support ignored": ("ex11", [R["select_goal"], one_drop_variant("ignores support")],
                             "holds it up"),
    "ex11 met goals judged too": ("ex11", [R["select_goal"],
                                           one_drop_variant("met goals judged too")],
                                  "needs no drop"),
}


@pytest.mark.parametrize("name", list(WRONG))
def test_wrong_answer_fails_with_a_hint(name, capsys):
    ex, fns, phrase = WRONG[name]
    assert not run_check(ex, *fns), name
    out = capsys.readouterr().out
    assert f"{ex} FAIL" in out, out
    assert phrase in out, out


def test_ex7_sign_error_in_ppo_fails(capsys):
    """The behavioural check measures PPO's gain: a sign-flipped loss (which makes BC's policy
    worse) must fail it.  One training run (~15-60 s)."""
    assert not run_check("ex7", R["mlp_backward"], R["gae"], ppo_variant(sign=-1.0))
    assert "after PPO" in capsys.readouterr().out


@pytest.mark.parametrize("piece", ["mlp_backward", "gae", "ppo_loss", "dist"])
def test_ex7_trains_with_the_students_functions(piece, monkeypatch):
    """Exercise 7 hands the student's functions (and ActionDist) to the training code: a
    student's function that raises stops training, and the library's module globals are never
    touched."""
    def boom(*args, **kwargs):
        raise RuntimeError(f"the student's {piece} was called")
    library = nn.mlp_backward, agent.gae, agent.ppo_loss, agent.ActionDist, taskexp.Pieces()
    monkeypatch.setitem(exercises.EX7, "demos", 50)
    monkeypatch.setitem(exercises.EX7, "ppo_steps", 200)
    with pytest.raises(RuntimeError, match=f"student's {piece} was called"):
        exercises.base_policy_success(**{piece: boom})
    assert (nn.mlp_backward, agent.gae, agent.ppo_loss, agent.ActionDist,
            taskexp.Pieces()) == library


CAPSTONE_PIECES = exercises.ARGUMENTS["ex12"]      # check_ex12's arguments, before the dist


def capstone_reference(**mine):
    """The arguments of check_ex12: the reference solutions, with `mine` in their place."""
    return [mine.get(f, R.get(f)) for f in CAPSTONE_PIECES] + [mine.get("dist")]


def test_ex12_fails_when_the_expansion_step_drops_the_prefix(capsys):
    """A demonstration that starts at s_T rather than s0 (the verification run alone) passes no
    check of exercise 9 by luck, and the capstone sees it too: its tasks do not grow (it stops
    after round 1). Half a minute."""
    assert not run_check("ex12", *capstone_args("no prefix"))
    out = capsys.readouterr().out
    assert "moves per demonstration" in out and "round 2 not run" in out, out


def capstone_args(mistake):
    return capstone_reference(expansion_step=expansion_variant(mistake))


@pytest.mark.parametrize("piece", [p for p in CAPSTONE_PIECES if p != "join"] + ["dist"])
def test_ex12_runs_the_students_pieces(piece, monkeypatch):
    """The capstone hands every piece the student wrote to the library's code (a tiny budget
    here): one that raises stops the rounds, and the library's module globals are never
    touched. (join runs inside the student's expansion_step, which calls it by name.)"""
    class Boom(Exception):
        pass

    def boom(*args, **kwargs):
        raise Boom(f"the student's {piece} was called")
    library = (nn.mlp_backward, agent.gae, agent.ppo_loss, agent.ActionDist,
               nn.SelfAttention.backward, taskexp.Pieces())
    for key, value in dict(base_tasks=40, expand_episodes=24, candidates=4, ppo_steps=300,
                           eval_episodes=2).items():
        monkeypatch.setitem(exercises.CAPSTONE, key, value)
    args = capstone_reference(**{piece: boom})
    pieces = exercises.capstone_pieces(*(args[CAPSTONE_PIECES.index(f)] for f in (
        "gae", "ppo_loss", "alter", "select_goal", "relabel", "expansion_step",
        "distillation_data", "distillation_tasks")))
    with pytest.raises(Boom, match=f"student's {piece} was called"):
        exercises.grow(pieces, log=lambda *a: None, mlp_backward=args[0],
                       attention_backward=args[6], dist=args[-1])
    assert library == (nn.mlp_backward, agent.gae, agent.ppo_loss, agent.ActionDist,
                       nn.SelfAttention.backward, taskexp.Pieces())


def test_ex11_takes_values_computed_one_candidate_at_a_time():
    """A right select_goal that asks the critic for one candidate at a time (float32 sums in
    another order than the reference's two batches) still passes exercise 11, whose measure allows
    for near-ties; so does a one_drop_away that returns numpy's bool."""
    def select_goal(ag, s0, sT, cands, mode="ours"):
        v = lambda s: np.array([float(ag.value(taskexp.observation(s, g)[None])[0])
                                for g in cands])
        score = {"ours": v(sT) - v(s0), "end2new": v(sT), "init2new": -v(s0)}[mode]
        return int(np.argmax(score))

    def one_drop_away(state, goals, threshold):
        return np.bool_(R["one_drop_away"](state, goals, threshold))
    assert run_check("ex11", select_goal, one_drop_away)


def test_ex5_takes_numpy_positions(capsys):
    """A right answer that stores positions as numpy arrays passes; one that also changes its input
    in place fails with the hint rather than crashing the check."""
    def alter_numpy(goals, env, rng):
        return {b: np.array(p) for b, p in R["alter"](goals, env, rng).items()}

    def alter_numpy_in_place(goals, env, rng):
        goals.update(alter_numpy(goals, env, rng))
        return goals
    assert run_check("ex5", alter_numpy)
    assert not run_check("ex5", alter_numpy_in_place)
    assert "dict(goals)" in capsys.readouterr().out


def test_checks_are_deterministic(capsys):
    for _ in range(2):
        run_check("ex3", gae_variant(shift=1))
        run_check("ex5", alter_always_add)
    out = capsys.readouterr().out.splitlines()
    assert out[: len(out) // 2] == out[len(out) // 2:]



def test_a_failed_check_raises_an_assertion_error_that_says_what_failed():
    with pytest.raises(AssertionError) as failed:
        exercises.check_ex3(gae_variant(shift=1))
    message = str(failed.value)
    assert message.startswith("ex3 FAIL: case 'terminations'") and "hint:" in message, message
    assert exercises.check_ex3(R["gae"]) is None       # None, not True: nbgrader reads a cell's
    #                                                    value as partial credit


@pytest.mark.parametrize("ex", SIMPLE)
def test_a_blank_and_a_solved_check_count_the_same_cases(ex, capsys):
    """Exercise 1 once said "5 of 5 cases failed" when blank and "PASS: 6 cases" when solved: its
    finite-difference comparison counted as a case only when the earlier cases passed. A check
    counts the same cases whatever the answer."""
    def blank(*args, **kwargs):
        raise NotImplementedError()
    with pytest.raises(AssertionError) as failed:
        exercises.CHECKS[ex](*[blank] * len(exercises.FUNCTIONS[ex]))
    counts = re.search(r"\((\d+) of (\d+) cases failed", str(failed.value))
    assert counts, str(failed.value)
    assert run_check(ex, *(R[f] for f in exercises.FUNCTIONS[ex]))
    solved = re.search(rf"{ex} PASS: (\d+) cases", capsys.readouterr().out)
    assert counts.group(1) == counts.group(2) == solved.group(1), (str(failed.value), solved)


def test_ex6_introduction_says_when_relabel_returns_none_in_a_sentence(tmp_path):
    """The introduction once read "There is no usable demonstration, return `None`, when ...":
    the student notebook (blanked from the instructor's) says it in one clear sentence."""
    released = os.path.join(tmp_path, exercises.NOTEBOOKS["ex6"])
    assert released in exercises.write_notebooks(str(tmp_path))
    for path in (instructor("ex6"), released):
        with open(path) as f:
            intro = "".join(json.load(f)["cells"][0]["source"])
        assert "no usable demonstration, return" not in intro, path
        assert re.search(r"Return `None` when the trajectory is no usable demonstration: a "
                         r"block fell off the table", " ".join(intro.split())), intro
        assert "states[:t+1]" not in intro, "the contract, not the line that meets it"


def test_checks_write_nothing_to_stderr(capsys):
    """nbgrader gives 0 points to a graded cell with stderr output: a student's warnings and
    prints to stderr come out on stdout, as a note, and a right answer still passes."""
    def noisy_gae(*args):
        print("debugging", file=sys.stderr)
        np.exp(np.array([1000.0]))                            # RuntimeWarning: overflow
        return R["gae"](*args)
    assert run_check("ex3", noisy_gae)
    out, err = capsys.readouterr()
    assert err == "" and "ex3 PASS" in out and "debugging" in out, (out, err)
    assert "note:" in out and "RuntimeWarning: overflow" in out, out


# ---- the student's ActionDist (exercise 2), which exercises 4 and 7 use -------------------------

def test_student_action_dist_behaves_as_the_library_s():
    Dist = exercises.student_action_dist(R["logp_entropy"], R["logp_entropy_backward"],
                                         R["log_softmax"])
    rng = np.random.default_rng(5)
    out = rng.standard_normal((7, 4, 1 + 5 + 4)).astype(np.float32)      # float32 as a net may
    actions = np.stack([rng.integers(4, size=7), rng.integers(5, size=7),
                        rng.integers(4, size=7)], 1)
    mine, lib = Dist(out, 5), agent.ActionDist(out, 5)
    assert np.allclose(mine.log_prob(actions), lib.log_prob(actions))
    assert np.allclose(mine.entropy(), lib.entropy())
    a, c = rng.standard_normal(7), rng.standard_normal(7)
    assert np.allclose(mine.backward(actions, a, c), lib.backward(actions, a, c))
    assert np.allclose(mine.backward(actions, -0.5, 0.0), lib.backward(actions, -0.5, 0.0))
    assert (mine.sample(np.random.default_rng(1)) == lib.sample(np.random.default_rng(1))).all()
    assert (mine.mode() == lib.mode()).all()


def test_ex4_says_when_its_action_dist_needs_exercise_2():
    """A right ppo_loss whose ActionDist runs an unfinished exercise 2 fails, naming exercise 2
    rather than saying the student's ppo_loss is not done."""
    def stub(*args):
        raise NotImplementedError()
    Dist = exercises.student_action_dist(stub, stub, stub, where="exercise 2 (ex02_x.ipynb)")

    def ppo_loss(out, actions, logp_old, adv, n_x, clip=0.2, ent_coef=0.0):
        dist = Dist(out, n_x)
        return dist.entropy().mean(), dist.backward(actions, adv, 0.0)
    with pytest.raises(AssertionError, match=r"ActionDist runs your exercise 2 \(ex02_x.ipynb\)"):
        exercises.check_ex4(ppo_loss)


# ---- release and CLI -----------------------------------------------------------------------------

SOLUTION = re.compile(r"^[ \t]*### BEGIN SOLUTION.*?### END SOLUTION[^\n]*\n?", re.M | re.S)
STUB = re.compile(r"^[ \t]*(# YOUR CODE HERE\n[ \t]*raise NotImplementedError\(\)|YOUR ANSWER HERE)"
                  r"\n?", re.M)


def test_release_blanks_every_solution_and_keeps_the_rest(released):
    for ex, name in exercises.NOTEBOOKS.items():
        with open(os.path.join(exercises.NOTEBOOK_DIR, name)) as f:
            src = json.load(f)
        with open(os.path.join(released, name)) as f:
            out = json.load(f)
        assert len(src["cells"]) == len(out["cells"]) and src["metadata"] == out["metadata"]
        for a, b in zip(src["cells"], out["cells"]):
            sa, sb = "".join(a["source"]), "".join(b["source"])
            assert a["metadata"] == b["metadata"] and a["cell_type"] == b["cell_type"]
            assert "BEGIN SOLUTION" not in sb and "END SOLUTION" not in sb
            assert len(SOLUTION.findall(sa)) == len(STUB.findall(sb))      # one stub per solution
            assert SOLUTION.sub("", sa) == STUB.sub("", sb)                 # nothing else changed
            if b["cell_type"] == "code":
                assert b["outputs"] == [] and b["execution_count"] is None
        solutions = [c for c in src["cells"] if c["metadata"]["nbgrader"]["solution"]]
        assert all("### BEGIN SOLUTION" in "".join(c["source"]) for c in solutions)
        assert ex in exercises.BEHAVIOURAL or solutions
        checks = [c for c in src["cells"] if c["metadata"]["nbgrader"]["grade"]
                  and c["cell_type"] == "code"]
        assert len(checks) == 1 and checks[0]["metadata"]["nbgrader"]["points"] > 0
        assert f"check_{ex}" in "".join(checks[0]["source"])


def test_blank_keeps_the_indentation():
    src = "def f(x):\n    y = 1\n    ### BEGIN SOLUTION\n    return x\n    ### END SOLUTION\n"
    assert exercises.blank(src) == ("def f(x):\n    y = 1\n    # YOUR CODE HERE\n"
                                    "    raise NotImplementedError()\n")


def cli(*args, cwd=ROOT):
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    return subprocess.run([sys.executable, "-m", "course", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300)


def test_cli_passes_on_the_instructor_notebook_and_fails_on_a_stub(released):
    ok = cli("ex3", instructor("ex3"))
    assert ok.returncode == 0 and "ex3 PASS" in ok.stdout, ok.stdout + ok.stderr
    bad = cli("ex3", str(released / exercises.NOTEBOOKS["ex3"]))
    assert bad.returncode == 1 and "ex3 FAIL" in bad.stdout and "NotImplementedError" in bad.stdout
    assert cli("ex9").returncode == 2 and cli().returncode == 2


@pytest.mark.parametrize("cmd", ["ex3", "ex7", "all"])
def test_cli_without_a_path_asks_which_notebook(cmd):
    """Not the instructor's notebook in the repository: the student's."""
    res = cli(cmd)
    assert res.returncode == 2 and res.stdout == "", res.stdout
    assert res.stderr.startswith("which notebook?" if cmd == "ex3" else "which folder?")


def mixed_folder(folder, blank, released):
    """The instructor notebooks, except the exercises in `blank`: the released stubs."""
    for ex, name in exercises.NOTEBOOKS.items():
        shutil.copy(released / name if ex in blank else instructor(ex), folder / name)
    return folder


def test_cli_all_ends_with_the_total_and_ex7_names_what_is_missing(released, tmp_path):
    """ex4 not done: ex4 fails, and so do ex7 and ex12 before training, naming ex4 and nothing
    else."""
    res = cli("all", str(mixed_folder(tmp_path, ["ex4"], released)))
    lines = res.stdout.strip().splitlines()
    assert res.returncode == 1
    P = exercises.POINTS
    assert lines[-1] == (f"total: {sum(P.values()) - P['ex4'] - P['ex7'] - P['ex12']}/"
                         f"{sum(P.values())} points; {len(P) - 3} of {len(P)} exercises pass "
                         "(fail: ex4, ex7, ex12)"), lines[-1]
    ex7 = res.stdout[res.stdout.index("ex7 FAIL"):]
    assert "not done yet" in ex7 and "ex4 (ppo_loss in ex04_ppo_loss.ipynb)" in ex7, ex7
    assert not any(f"{ex} (" in ex7 for ex in ["ex1", "ex2", "ex3"]), ex7
    assert "BC on" not in res.stdout                      # no minute of training for nothing
    ex12 = res.stdout[res.stdout.index("ex12 FAIL"):]
    assert "not done yet" in ex12 and "ex4 (ppo_loss in ex04_ppo_loss.ipynb)" in ex12, ex12
    assert "two rounds of" not in res.stdout


def test_ex7_says_that_exercise_2_is_missing_through_ex4(released, tmp_path):
    """ex2 not done: exercise 4's ppo_loss runs it (its ActionDist), so ex7 names ex2, not ex4."""
    fns = exercises.functions("ex7", str(mixed_folder(tmp_path, ["ex2"], released)))
    assert exercises.unfinished(*fns) == ["ex2"]


def test_points_are_those_of_the_graded_cells():
    for ex, name in exercises.NOTEBOOKS.items():
        with open(instructor(ex)) as f:
            cells = json.load(f)["cells"]
        graded = lambda kind: [c["metadata"]["nbgrader"]["points"] for c in cells
                               if c["metadata"]["nbgrader"]["grade"] and c["cell_type"] == kind]
        assert graded("code") == [exercises.POINTS[ex]], name
        assert sum(graded("markdown")) == exercises.MANUAL.get(ex, 0), name


GAE_BY_SUMS = """
    # A_t = sum_k (gamma lam)^k delta_{t+k}, summed forwards until the episode ends
    T, N = np.shape(rewards)
    delta = rewards + gamma * next_values * (1 - terminated) - values
    adv = np.zeros((T, N))
    for n in range(N):
        for t in range(T):
            w = 1.0
            for u in range(t, T):
                adv[t, n] += w * delta[u, n]
                if terminated[u, n] or truncated[u, n]:
                    break
                w *= gamma * lam
    return adv, adv + values
"""


def test_a_student_who_fills_in_a_different_correct_answer_passes(released, tmp_path):
    """Release -> the student replaces the stub (here by GAE as explicit sums, not the recursion)
    -> pass."""
    with open(released / exercises.NOTEBOOKS["ex3"]) as f:
        nb = json.load(f)
    for cell in nb["cells"]:
        src = "".join(cell["source"])
        if "raise NotImplementedError()" in src:
            cell["source"] = src.replace("    # YOUR CODE HERE\n    raise NotImplementedError()",
                                         GAE_BY_SUMS)
    path = tmp_path / "my_ex3.ipynb"
    path.write_text(json.dumps(nb))
    res = cli("ex3", str(path))
    assert res.returncode == 0 and "ex3 PASS" in res.stdout, res.stdout + res.stderr


# ---- the instructor notebooks run top to bottom -------------------------------------------------

# ex7's and ex12's notebooks have no solution cell: nbgrader runs them as released, with every
# other solution pasted in (tests/test_grader.py: full marks), and the kit's `all` does too
# (tests/test_kit.py: full marks); their training, a minute each, is not run a third time here
@pytest.mark.parametrize("ex", [e for e in exercises.NOTEBOOKS if e not in exercises.BEHAVIOURAL])
def test_instructor_notebook_executes(ex, monkeypatch):
    # the kernel runs in course/notebooks/, and `course` is not installed (pyproject installs the
    # library only): the repository goes on its path, as for an instructor working in a checkout
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        p for p in (ROOT, os.environ.get("PYTHONPATH")) if p))
    path = os.path.join(exercises.NOTEBOOK_DIR, exercises.NOTEBOOKS[ex])
    nb = nbformat.read(path, as_version=4)
    nbclient.NotebookClient(nb, timeout=300, kernel_name="python3",
                            resources={"metadata": {"path": exercises.NOTEBOOK_DIR}}).execute()
    text = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code"
                   for o in c.get("outputs", []))
    assert f"{ex} PASS" in text, text


def test_cells_carry_valid_nbgrader_metadata():
    """nbgrader's schema-3 rules (nbgrader/nbgraderformat/v3.py and v3.json), checked without
    nbgrader: known keys only; an id of [A-Za-z0-9_-] on every graded, solution or locked cell,
    unique per notebook; points on graded cells; no markdown cell that is only graded or only a
    solution."""
    keys = {"schema_version", "grade", "locked", "solution", "task", "grade_id", "points"}
    for name in exercises.NOTEBOOKS.values():
        with open(os.path.join(exercises.NOTEBOOK_DIR, name)) as f:
            cells = json.load(f)["cells"]
        ids = [c["metadata"]["nbgrader"].get("grade_id") for c in cells]
        assert len(ids) == len(set(ids)), name
        for cell in cells:
            m = cell["metadata"]["nbgrader"]
            assert set(m) <= keys and m["schema_version"] == 3, (name, m)
            assert all(isinstance(m[k], bool) for k in ("grade", "locked", "solution", "task"))
            assert re.fullmatch(r"[A-Za-z0-9_\-]+", m["grade_id"]), (name, m)
            assert not m["grade"] or m["points"] >= 0
            assert cell["cell_type"] == "code" or m["grade"] == m["solution"], (name, m)
            assert not (m["solution"] and m["locked"]), (name, m)    # the student must edit it
