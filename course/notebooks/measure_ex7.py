"""Measure the behavioural check of exercise 7: greedy success after BC and after PPO, with the
library's pieces (the reference) and with plausible mistakes plugged in.  The threshold and the
minimum gain in course.EX7 were chosen from these figures.  ~15 s per run on one
core.

    python course/notebooks/measure_ex7.py reference 0 1 2 3 4
    python course/notebooks/measure_ex7.py ppo_sign 0 1        # ... or any name in VARIANTS
"""
import sys

import numpy as np

import agent
import course as exercises

R = exercises.REFERENCE


def ppo_sign(*args, **kw):
    """Maximises the loss: L and its gradient with the wrong sign."""
    L, d = R["ppo_loss"](*args, **kw)
    return -L, -d


def ppo_mask_inverted(out, actions, logp_old, adv, n_x, clip=0.2, ent_coef=0.0):
    """Gradient only where the clipped term is the min (the mask inverted)."""
    dist, B = agent.ActionDist(out, n_x), len(actions)
    r = np.exp(dist.log_prob(actions) - logp_old)
    u, c = r * adv, np.clip(r, 1 - clip, 1 + clip) * adv
    L = -np.minimum(u, c).mean() - ent_coef * dist.entropy().mean()
    return L, dist.backward(actions, -np.where(u > c, u, 0.0) / B, -ent_coef / B)


def ppo_entropy_only(out, actions, logp_old, adv, n_x, clip=0.2, ent_coef=0.0):
    """Forgets the surrogate's gradient: only the entropy bonus moves the policy."""
    L, _ = R["ppo_loss"](out, actions, logp_old, adv, n_x, clip, ent_coef)
    return L, agent.ActionDist(out, n_x).backward(actions, 0.0, -ent_coef / len(actions))


def gae_delta_sign(r, v, te, tr, nv, gamma, lam):
    """delta_t = V(s_t) - r_t - gamma V(s_t+1): every advantage has the wrong sign."""
    adv, _ = R["gae"](-r, -v, te, tr, -nv, gamma, lam)
    return adv, adv + v


def gae_off_by_one(r, v, te, tr, nv, gamma, lam):
    """The trace is cut with the next step's done flag instead of this step's."""
    adv, last, done = np.zeros_like(r), np.zeros(r.shape[1:]), np.maximum(te, tr)
    for t in reversed(range(len(r))):
        delta = r[t] + gamma * nv[t] * (1 - te[t]) - v[t]
        last = delta + gamma * lam * (1 - (done[t + 1] if t + 1 < len(r) else 0.0)) * last
        adv[t] = last
    return adv, adv + v


def mlp_no_tanh(params, hs, dout):
    """Forgets tanh' in the hidden layers."""
    L, grads, d = len(params) // 2, {}, dout
    for k in reversed(range(L)):
        grads[f"W{k}"], grads[f"b{k}"] = hs[k].T @ d, d.sum(0)
        d = d @ params[f"W{k}"].T
    return grads, d


VARIANTS = dict(reference={}, ppo_sign=dict(ppo_loss=ppo_sign),
                ppo_mask_inverted=dict(ppo_loss=ppo_mask_inverted),
                ppo_entropy_only=dict(ppo_loss=ppo_entropy_only),
                gae_delta_sign=dict(gae=gae_delta_sign), gae_off_by_one=dict(gae=gae_off_by_one),
                mlp_no_tanh=dict(mlp_backward=mlp_no_tanh))

if __name__ == "__main__":
    name, seeds = sys.argv[1], [int(s) for s in sys.argv[2:]] or [exercises.EX7["seed"]]
    for seed in seeds:
        pieces = {f: R[f] for f in ("gae", "ppo_loss", "mlp_backward")}
        pieces.update(VARIANTS[name])
        before, after, secs = exercises.base_policy_success(seed=seed, **pieces)
        print(f"{name:18s} seed {seed}: BC {before:.3f} -> PPO {after:.3f}  ({secs:.0f} s)",
              flush=True)
