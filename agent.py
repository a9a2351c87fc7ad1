"""agent.py -- the goal-conditioned agent of task expansion: policy pi(a | s, g) and value V(s, g).

Paper: "Self-Generating Data for Goal-Conditioned Compositional Problems" (Yuan, Li, Wu).
Sec 3: a goal-conditioned policy and a universal value function over a set of blocks; an action
picks a block and a discrete target (x-bin, layer) for it. Sec 4.1 and 4.3: behaviour cloning on
demonstrations (base skills, self-distillation); PPO fine-tuning with a sparse success reward.

  ActionDist           the factorised action distribution pi(b, x, y) = pi(b) pi(x | b) pi(y | b)
  bc_loss, ppo_loss, value_loss, aux_loss, gae
                       the losses with their gradients w.r.t. the network outputs, and GAE
  Agent                two networks (taskexp_lib/nets.py) over block features
                       (taskexp_lib/features.py), BC, PPO and value regression

numpy with no autograd: every backward is checked against central finite differences in
tests/test_agent.py. The networks compute in the dtype they are made with (float64 for those
checks, float32 for training); losses, log-probs and returns are always float64. Randomness only
through a passed np.random.Generator (or an integer seed for initialisation). Checkpoints are
read and written by taskexp_lib/checkpoint.py.
"""
import warnings
from functools import partial

import numpy as np
from tqdm import tqdm

from taskexp_lib import checkpoint
from taskexp_lib.config import Config
from taskexp_lib.features import AUX_FACTS, featurize, relation_targets
from taskexp_lib.geometry import N_X, block_count
from taskexp_lib.nets import NETWORKS
from taskexp_lib.nn import Adam, check_finite, clip_grad_norm, mlp_backward
from taskexp_lib.shards import DataParallel

# Config.greedy: the rules of the deterministic action, ActionDist.mode ("joint") and
# ActionDist.block_mode ("block")
GREEDY = ("joint", "block")


class OtherWorldWarning(UserWarning):
    """An agent acts in a world of another number of blocks than it learnt in (Agent.features)."""

# ---- The factorised action distribution (sec 3):  pi(b, x, y) = pi(b) pi(x | b) pi(y | b) ----

def log_softmax(z):
    """Stable log softmax over the last axis: z - max - log sum exp(z - max)."""
    z = z - z.max(-1, keepdims=True)
    return z - np.log(np.exp(z).sum(-1, keepdims=True))


def entropy_of(logp):
    """H = -sum p log p over the last axis, from log-probs; 0 log 0 = 0 (finite for any logits)."""
    p = np.exp(logp)
    return -np.where(p > 0, p * logp, 0.0).sum(-1)


class ActionDist:
    """The policy at a batch of states, from actor outputs out (B, n, 1 + n_x + n_y):
    per block i a block logit l_i, x-logits X_i (n_x,), layer logits Y_i (n_y,).

        log pi(b, x, y) = logsoftmax(l)[b] + logsoftmax(X_b)[x] + logsoftmax(Y_b)[y]
        H = H(b) + sum_b pi(b) (H(X_b) + H(Y_b))          (exact, no sampling)
    """

    def __init__(self, out, n_x):
        out = np.asarray(out, dtype=np.float64)          # probabilities in float64 whatever the net
        self.shape = out.shape
        self.lb = log_softmax(out[..., 0])                     # (B, n)
        self.lx = log_softmax(out[..., 1:1 + n_x])             # (B, n, n_x)
        self.ly = log_softmax(out[..., 1 + n_x:])              # (B, n, n_y)
        self.pb = np.exp(self.lb)
        self.hb, self.hx, self.hy = entropy_of(self.lb), entropy_of(self.lx), entropy_of(self.ly)

    def log_prob(self, actions):
        """actions (B, 3) int -> log pi (B,)."""
        i, (b, x, y) = np.arange(len(actions)), np.asarray(actions, dtype=np.int64).T
        return self.lb[i, b] + self.lx[i, b, x] + self.ly[i, b, y]

    def entropy(self):
        """-> H (B,)."""
        return self.hb + (self.pb * (self.hx + self.hy)).sum(-1)

    def sample(self, rng):
        """-> actions (B, 3) int64: block first, then its x-bin and layer (inverse CDF)."""
        i = np.arange(self.shape[0])
        b = _categorical(self.pb, rng)
        return np.stack([b, _categorical(np.exp(self.lx[i, b]), rng),
                         _categorical(np.exp(self.ly[i, b]), rng)], -1)

    def mode(self):
        """-> the most likely joint action (B, 3): argmax_b [log pi(b) + max_x .. + max_y ..]."""
        return self._with_best_place((self.lb + self.lx.max(-1) + self.ly.max(-1)).argmax(-1))

    def block_mode(self):
        """-> the most likely block, then its most likely x-bin and layer (B, 3): each head's
        argmax in the order the policy samples, as the authors' greedy action takes it. Unlike
        mode(), a block whose destination is spread (a block to clear away: many x are right)
        is not passed over for one whose destination is certain."""
        return self._with_best_place(self.lb.argmax(-1))

    def _with_best_place(self, b):
        """blocks b (B,) -> actions (B, 3): each block with its most likely x-bin and layer."""
        i = np.arange(self.shape[0])
        return np.stack([b, self.lx[i, b].argmax(-1), self.ly[i, b].argmax(-1)], -1)

    def backward(self, actions, a, c):
        """d/d(out) of sum_k (a_k log pi(actions_k) + c_k H_k);  a, c scalars or (B,) -> (B, n, D).

        Per categorical with logits z and log-probs lp:  d lp[k]/dz = onehot(k) - p,
        dH/dz = -p (lp + H).  With K_b = H(X_b) + H(Y_b) and Kbar = sum_b pi(b) K_b:
          dH/dl = -pi(b) (lb + H(b)) + pi(b) (K_b - Kbar);  dH/dX_b = pi(b) dH(X_b)/dX_b.
        """
        B, n, _ = self.shape
        a, c = np.broadcast_to(a, (B,))[:, None], np.broadcast_to(c, (B,))[:, None]
        i, (b, x, y) = np.arange(B), np.asarray(actions, dtype=np.int64).T
        px, py = np.exp(self.lx), np.exp(self.ly)
        K = self.hx + self.hy
        Kbar = (self.pb * K).sum(-1, keepdims=True)
        dl = -self.pb * (self.lb + self.hb[:, None]) + self.pb * (K - Kbar)
        dX = -self.pb[..., None] * px * (self.lx + self.hx[..., None])
        dY = -self.pb[..., None] * py * (self.ly + self.hy[..., None])
        dout = c[..., None] * np.concatenate([dl[..., None], dX, dY], -1)
        # log-prob part: only the chosen block's x and y heads get gradient
        dout[..., 0] += a * (np.eye(n)[b] - self.pb)
        dout[i, b, 1:1 + px.shape[-1]] += a * (np.eye(px.shape[-1])[x] - px[i, b])
        dout[i, b, 1 + px.shape[-1]:] += a * (np.eye(py.shape[-1])[y] - py[i, b])
        return dout


def _categorical(p, rng):
    """p (B, K) rows summing to 1 -> one index per row (int64, B,), via one uniform each."""
    u = rng.random(len(p))[:, None]
    return np.minimum((np.cumsum(p, -1) < u).sum(-1), p.shape[-1] - 1)


# ---- Losses with their gradients w.r.t. the network outputs ------------------------------

def bc_loss(out, actions, n_x, action_dist=None):
    """L_BC = -mean log pi(a | s, g)  -> (L, dL/d out (B, n, D)).  action_dist: the
    distribution's class (default ActionDist)."""
    dist = (action_dist or ActionDist)(out, n_x)
    B = len(actions)
    return -dist.log_prob(actions).mean(), dist.backward(actions, -1.0 / B, 0.0)


def aux_loss(out, targets):
    """Auxiliary loss (not in the paper): each token's logits z (B, n, K) predict K facts t in
    {0, 1} about its block (features.AUX_FACTS), by cross-entropy with logits, a mean over all:
        L = mean [log(1 + e^z) - t z];   dL/dz = (sigmoid(z) - t) / (B n K)
    -> (L, dL/d out)."""
    z, t = np.asarray(out, dtype=np.float64), np.asarray(targets, dtype=np.float64)
    loss = np.mean(np.logaddexp(0.0, z) - t * z)               # log(1 + e^z), stable for any z
    return loss, (0.5 * (1.0 + np.tanh(0.5 * z)) - t) / z.size     # sigmoid(z), stable


def ppo_loss(out, actions, logp_old, adv, n_x, clip, ent_coef):
    """Clipped surrogate with entropy bonus (Schulman et al. 2017); adv already normalised.

        r = exp(logp - logp_old);  L = -mean min(r A, clip(r, 1-eps, 1+eps) A) - c_ent mean H
    d/dlogp of min(..) is r A where the unclipped term is the min, else 0 (the clipped term is
    constant).  -> (L, dL/d out).
    """
    dist = ActionDist(out, n_x)
    B = len(actions)
    r = np.exp(dist.log_prob(actions) - logp_old)
    unclipped, clipped = r * adv, np.clip(r, 1 - clip, 1 + clip) * adv
    l_clip = -np.minimum(unclipped, clipped).mean()
    H = dist.entropy()
    a = -np.where(unclipped <= clipped, unclipped, 0.0) / B    # d L / d logp
    dout = dist.backward(actions, a, -ent_coef / B)
    return l_clip - ent_coef * H.mean(), dout


def ppo_stats(dist, actions, logp_old, adv, clip):
    """What a PPO minibatch update logs, from the policy `dist` it started from:
    (L_clip, mean entropy, approx KL, clip fraction). The KL estimate mean (r - 1) - log r is
    unbiased and non-negative."""
    log_ratio = dist.log_prob(actions) - logp_old
    r = np.exp(log_ratio)
    l_clip = -np.minimum(r * adv, np.clip(r, 1 - clip, 1 + clip) * adv).mean()
    return l_clip, dist.entropy().mean(), np.mean(r - 1 - np.log(r)), np.mean(np.abs(r - 1) > clip)


def value_loss(out, returns):
    """V = mean_i o_i;  L = mean 0.5 (V - R)^2  -> (L, dL/d out (B, n, 1), V (B,))."""
    B, n, _ = out.shape
    V = out[..., 0].mean(-1)
    dout = np.broadcast_to(((V - returns) / (B * n))[:, None, None], out.shape).copy()
    return 0.5 * np.mean((V - returns) ** 2), dout, V


def pair_value_loss(out, returns, weight):
    """Value loss on pairs of states under one goal: out (2B, n, 1) holds the states a, then the
    states b; returns (B, 2) their targets. Equation (1) ranks by V(sT, g) - V(s0, g), so the
    difference of each pair is regressed on the difference of its targets too:
        L = mean 0.5 (V_a - R_a)^2 + 0.5 (V_b - R_b)^2 + weight 0.5 ((V_a - V_b) - (R_a - R_b))^2
    -> (L, dL/d out (2B, n, 1), V (2B,))."""
    B2, n, _ = out.shape
    B = B2 // 2
    V = out[..., 0].mean(-1)
    ea, eb = V[:B] - returns[:, 0], V[B:] - returns[:, 1]
    r = ea - eb                                      # (V_a - V_b) - (R_a - R_b)
    loss = 0.5 * np.mean(ea ** 2) + 0.5 * np.mean(eb ** 2) + weight * 0.5 * np.mean(r ** 2)
    dV = np.concatenate([ea + weight * r, eb - weight * r]) / B
    return loss, np.broadcast_to((dV / n)[:, None, None], out.shape).copy(), V


def gae(rewards, values, terminated, truncated, next_values, gamma, lam):
    """Generalised advantage estimation; all inputs (T, N) with time on axis 0.

        delta_t = r_t + gamma V(s_{t+1}) (1 - term_t) - V(s_t)
        A_t     = delta_t + gamma lam (1 - done_t) A_{t+1},   done = term or trunc
    next_values[t] = V(s_{t+1}) of the real next state, so a truncated step bootstraps from it
    while a terminated one does not.  -> advantages (T, N), returns = A + V (T, N).
    """
    r, v, te, tr, nv = (np.asarray(z, dtype=np.float64)
                        for z in (rewards, values, terminated, truncated, next_values))
    if not r.shape == v.shape == te.shape == tr.shape == nv.shape:
        raise ValueError(f"gae: shapes differ {[z.shape for z in (r, v, te, tr, nv)]}")
    adv, last = np.zeros_like(r), np.zeros(r.shape[1:])
    for t in reversed(range(len(r))):
        delta = r[t] + gamma * nv[t] * (1.0 - te[t]) - v[t]
        last = delta + gamma * lam * (1.0 - np.maximum(te[t], tr[t])) * last
        adv[t] = last
    return adv, adv + v


# ---- The agent ---------------------------------------------------------------------------

class Agent:
    """Policy pi(b, x, y | s, g) and value V(s, g): two networks (AttentionNets, or SetNets with
    network="setnet") with separate Adam states, over featurize's plain features or, with
    features="relations", the hand-computed relations too ("relations+leave": and the spot a
    block in the way must leave; "relations+leave+stay": and whether a block is a support in
    place).

    The defaults are Config's: attention over plain features in float32, for the world that drops
    blocks, whose action has no layer (n_y = 1). For the world that places blocks in layers, n_y
    is the number of layers (n_blocks). It learns in a world of n_blocks blocks and acts in one of
    any number with the same weights (features). A run builds its agent from its Config with
    taskexp.make_agent.

    mlp_backward(params, hs, dout) -> (grads, dx) is the backward pass of every MLP in them, and
    action_dist the class of the policy's distribution (default ActionDist): the library's, or a
    student's (exercise 7 trains with them).

    aux > 0 (Config.aux_relations, not in the paper) gives the actor's head len(AUX_FACTS) more
    outputs per token, which BC and PPO train, with weight aux, to predict its block's stacking
    relations (aux_loss); the policy never reads them. They make the tokens that the policy
    heads read carry the relations (lab/bench/probe.py found training took them away).
    """

    def __init__(self, n_blocks=Config.n_blocks, n_x=N_X, n_y=1, hidden=Config.hidden,
                 seed=Config.seed, mlp_backward=mlp_backward, dtype=Config.dtype,
                 action_dist=None, network=Config.network, features=Config.features,
                 greedy=Config.greedy, aux=Config.aux_relations):
        self.n_blocks, self.n_x, self.hidden = int(n_blocks), int(n_x), int(hidden)
        self.n_y = int(n_y)
        if greedy not in GREEDY:
            raise ValueError(f"greedy {greedy!r}: one of {GREEDY}")
        self.greedy = greedy        # the deterministic action's rule (Config.greedy); not saved
        self.dtype, self.action_dist = np.dtype(dtype), action_dist or ActionDist
        if self.dtype not in (np.float32, np.float64):
            raise ValueError(f"dtype {dtype!r}: the networks compute in float32 or float64")
        if network not in NETWORKS:
            raise ValueError(f"network {network!r}: one of {sorted(NETWORKS)}")
        self.network, Net = network, NETWORKS[network]
        self.feature_set = features
        F = self.features(np.zeros((1, self.n_blocks, 6))).shape[-1]
        if not aux >= 0:
            raise ValueError(f"aux {aux!r}: the auxiliary loss's weight is 0 (off) or more")
        self.aux = float(aux)
        # the actor's outputs per token: the block logit, x-logits, layer logits (the policy's
        # P columns), then, with aux > 0, one logit per fact of AUX_FACTS
        self.n_policy = 1 + self.n_x + self.n_y
        n_aux = len(AUX_FACTS) if self.aux > 0 else 0
        self.actor = Net(F, hidden, self.n_policy + n_aux, seed=[seed, 0], out_scale=0.01,
                         mlp_backward=mlp_backward, dtype=self.dtype)
        self.critic = Net(F, hidden, 1, seed=[seed, 1], mlp_backward=mlp_backward,
                          dtype=self.dtype)
        self.actor_opt, self.critic_opt = Adam(self.actor.params), Adam(self.critic.params)
        self.rng = np.random.default_rng([seed, 2])     # only when a caller passes no Generator
        self.threads = 1        # threads for a minibatch's parts (shards.py): same results for any

    @property
    def drops(self):
        """True when made for the world that drops (one y choice: physics finds the height)."""
        return self.n_y == 1

    def features(self, obs):
        """obs (B, n, 6) -> (B, n, F) in the networks' dtype.

        The agent learnt in a world of n_blocks blocks, and acts and values in one of any n in
        2..MAX_BLOCKS with the same weights: self-attention takes any number of block tokens,
        and heights are scaled by the n_blocks layers it learnt with, whatever the world. It says
        so with an OtherWorldWarning, which the warnings module shows once per n: by default it
        shows a warning once per place and message, and this one is always raised from the same
        line (until its filters change, as when a catch_warnings block ends). A caller that asked
        for another world on purpose silences it with warnings.catch_warnings.
        """
        obs = np.asarray(obs, dtype=np.float64)
        if obs.ndim != 3 or obs.shape[-1] != 6:
            raise ValueError(f"obs must have shape (B, n, 6), got {obs.shape}")
        n = block_count(obs.shape[1], name="the blocks n of obs (B, n, 6)")
        if n != self.n_blocks:     # raised from this line, whoever asks: once per n (docstring)
            warnings.warn(f"this agent learnt in a world of {self.n_blocks} blocks; it acts in "
                          f"one of {n} with the same weights", OtherWorldWarning)
        return featurize(obs, self.n_blocks, self.feature_set).astype(self.dtype, copy=False)

    def policy(self, f):
        """The action distribution at features f (B, n, F). In a world that places, with fewer
        layers than the agent learnt (n < n_y), only the layers that world has."""
        out = self.actor.forward(f)[..., :self.n_policy]
        if not self.drops and f.shape[1] < self.n_y:
            out = out[..., :1 + self.n_x + f.shape[1]]
        return self.action_dist(out, self.n_x)

    def _batched(self, obs):
        obs = np.asarray(obs, dtype=np.float64)
        return (obs[None], True) if obs.ndim == 2 else (obs, False)

    def act(self, obs, deterministic=False, rng=None):
        """obs (n, 6) -> action (3,) int64, or (B, n, 6) -> (B, 3).  Samples with rng (default:
        the agent's own seeded Generator), or when deterministic takes the greedy action by the
        rule self.greedy: the joint mode, or the block's mode and then its x's (block_mode)."""
        obs, single = self._batched(obs)
        dist = self.policy(self.features(obs))
        if not deterministic:
            a = dist.sample(self.rng if rng is None else rng)
        else:
            a = dist.block_mode() if self.greedy == "block" else dist.mode()
        return a[0] if single else a

    def value(self, obs):
        """obs (n, 6) -> float, or (B, n, 6) -> V (B,)."""
        obs, single = self._batched(obs)
        v = np.concatenate([self.critic.forward(self.features(obs[i:i + 4096]))[..., 0].mean(-1)
                            for i in range(0, max(len(obs), 1), 4096)])    # chunks bound memory
        return float(v[0]) if single else v

    def sample(self, obs, rng=None):
        """obs (B, n, 6) -> actions (B, 3) int64, logp (B,), values (B,)  (for rollouts)."""
        f = self.features(obs)
        dist = self.policy(f)
        a = dist.sample(self.rng if rng is None else rng)
        return a, dist.log_prob(a), self.critic.forward(f)[..., 0].mean(-1)

    def bc(self, obs, actions, epochs, batch_size, lr, rng, max_grad_norm=None, bar=None):
        """Behaviour cloning (sec 4.1, 4.3): minimise L_BC = -mean log pi(a | s, g) by Adam.

        obs (N, n, 6), actions (N, 3).  -> list of the mean minibatch loss of each epoch.
        bar: a progress bar factory (tqdm) to show the minibatches done; default none.
        """
        actions = np.asarray(actions, dtype=np.int64)
        self._check_actions(actions)
        loss = lambda out, a: bc_loss(out, a, self.n_x, self.action_dist)
        if self.aux > 0:        # L_BC + aux L_aux: the targets are the actions and the facts
            actions, loss = (actions, relation_targets(obs)), self._with_aux(loss)
        return self._fit("BC", self.actor, self.actor_opt, loss, obs, actions, epochs,
                         batch_size, lr, rng, max_grad_norm, bar=bar)

    def _with_aux(self, policy_loss):
        """policy_loss(out, a) -> (L, dL/dout) on the policy's columns  ->  the loss of the whole
        head on targets (a, facts) (_add_aux)."""
        def loss(out, targets):
            a, facts = targets
            return self._add_aux(out, facts, *policy_loss(out[..., :self.n_policy], a))
        return loss

    def _add_aux(self, out, facts, loss, dout):
        """The whole actor head's outputs `out`, the policy's loss and its gradient `dout` w.r.t.
        the policy's columns -> (L + aux L_aux, the gradient w.r.t. every column): aux_loss on
        the fact columns, which the policy never reads."""
        la, da = aux_loss(out[..., self.n_policy:], facts)
        return loss + self.aux * la, np.concatenate([dout, self.aux * da], -1)

    def fit_value(self, obs, returns, epochs, batch_size, lr, rng, max_grad_norm=None, bar=None):
        """Regress V(s, g) on returns (e.g. of demonstrations): L = mean 0.5 (V - R)^2.

        obs (N, n, 6), returns (N,).  -> list of the mean minibatch loss of each epoch.
        """
        returns = np.asarray(returns, np.float64)
        return self._fit("value fit", self.critic, self.critic_opt, value_loss, obs, returns,
                         epochs, batch_size, lr, rng, max_grad_norm, bar=bar)

    def fit_value_pairs(self, obs, returns, weight, epochs, batch_size, lr, rng,
                        max_grad_norm=None, bar=None):
        """Regress V on pairs of states under one goal, their difference too (pair_value_loss):
        obs (N, 2, n, 6), returns (N, 2); a minibatch holds both states of each of its pairs.
        -> list of the mean minibatch loss of each epoch."""
        loss = lambda out, R: pair_value_loss(out, R, weight)
        both = lambda o: np.concatenate([o[:, 0], o[:, 1]])          # the states a, then b
        return self._fit("pair value fit", self.critic, self.critic_opt, loss, obs,
                         np.asarray(returns, np.float64), epochs, batch_size, lr, rng,
                         max_grad_norm, inputs=both, bar=bar)

    def _fit(self, phase, net, opt, loss_fn, obs, targets, epochs, batch_size, lr, rng,
             max_grad_norm, inputs=lambda o: o, bar=None):
        """Minibatch Adam on loss_fn(out, targets) -> (L, dL/dout, ...), a mean over the samples.
        inputs(obs[idx]) gives the network's observations of a minibatch; bar(total, desc) a
        progress bar, one tick a minibatch. -> the mean minibatch loss of each epoch."""
        obs, opt.lr, losses = np.asarray(obs, dtype=np.float64), lr, []

        def loss_and_grads(net, idx):
            """One minibatch idx -> (L, dL/dtheta). net: the network to run (a copy of it that
            shares its parameters, when the minibatch is split over the cores)."""
            # features per minibatch: for all N at once, (N, n, F) float64 would need ~300 MB
            # for N = 100k
            f = self.features(inputs(obs[idx]))
            out = net.forward(f)
            # targets, or a tuple of target arrays (BC with the auxiliary facts), of minibatch idx
            batch = tuple(t[idx] for t in targets) if isinstance(targets, tuple) else targets[idx]
            loss, dout = loss_fn(out, batch)[:2]                    # L and dL/dout
            return loss, net.backward(dout)                         # dL/dtheta, by backprop

        steps = epochs * -(-len(obs) // batch_size)
        progress = (bar or _no_bar)(total=steps, desc=phase)
        with self.data_parallel(net) as both_cores, progress:
            for e in range(epochs):
                epoch = []
                for i, idx in enumerate(_minibatches(len(obs), batch_size, rng)):
                    # = loss_and_grads(net, idx) up to rounding: the means over its two halves,
                    # one on each core, weighted by their sizes (the same bytes on one core)
                    loss, grads = both_cores(loss_and_grads, idx)
                    # g <- g min(1, max_norm / |g|): one global L2 norm over all parameters
                    grads, norm = clip_grad_norm(grads, max_grad_norm)
                    check_finite(f"{phase} epoch {e + 1} minibatch {i + 1}", loss=loss,
                                 gradient_norm=norm)
                    opt.step(grads)              # Adam: theta -= lr mhat / (sqrt(vhat) + eps)
                    epoch.append(loss)
                    progress.update(1)
                check_finite(f"{phase} epoch {e + 1}", parameters=net.params)
                losses.append(float(np.mean(epoch)))
        return losses

    def ppo_update(self, obs, actions, logp_old, adv, returns, *, epochs, minibatch, clip,
                   ent_coef, vf_coef, lr, max_grad_norm, rng=None, ppo_loss=ppo_loss):
        """PPO epochs over one batch of N transitions: obs (N, n, 6), actions (N, 3), logp_old,
        raw GAE advantages adv and returns (N,).  The advantages are normalised here, once over
        the whole batch.  Actor: L = L_clip - c_ent H;  critic: c_v 0.5 (V - R)^2.  The two
        networks share nothing, so each has its own Adam and its own gradient-norm clip (with
        Adam, vf_coef matters only through that clip).  The hyperparameters have no defaults:
        taskexp.Config holds them.  ppo_loss: the loss function (the library's, or a student's).

        -> metrics, means over all minibatch updates unless noted:
           policy_loss  L_clip (without the entropy term)
           value_loss   0.5 (V - R)^2 (without vf_coef)
           entropy      exact H of pi
           approx_kl    mean (r - 1) - log r, an unbiased, non-negative estimate of KL(old || new)
           clip_frac    fraction of samples with |r - 1| > clip
           explained_variance  1 - Var(R - V) / Var(R) over the batch, V the rollout's values
                        (the critic before the update; nan when Var(R) = 0)
        """
        rng = self.rng if rng is None else rng
        obs, actions = np.asarray(obs, dtype=np.float64), np.asarray(actions, dtype=np.int64)
        self._check_actions(actions)
        logp_old, returns = np.asarray(logp_old, np.float64), np.asarray(returns, np.float64)
        adv = np.asarray(adv, dtype=np.float64)
        check_finite("PPO update: inputs", logp_old=logp_old, advantages=adv, returns=returns)
        features = self.features(obs)               # once: they do not change within the update
        facts = relation_targets(obs) if self.aux > 0 else None           # aux_loss's targets
        P = self.n_policy
        # the critic that computed the rollout's values V is the one before the update, and
        # GAE's returns are R = A + V, so R - V = A
        var_r = np.var(returns)
        ev = float(1.0 - np.var(adv) / var_r) if var_r > 0 else float("nan")
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)               # A <- (A - mean) / std
        self.actor_opt.lr = self.critic_opt.lr = lr

        def loss_and_grads(actor, critic, idx):
            """One minibatch idx -> (L_clip - c_ent H, 0.5 (V - R)^2, the actor's and the critic's
            gradients, the figures logged). actor, critic: the networks to run (copies of them
            that share their parameters, when the minibatch is split over the cores)."""
            f, a, lp, A = features[idx], actions[idx], logp_old[idx], adv[idx]
            out = actor.forward(f)               # logits of pi(b, x, y), then those of the facts
            # r = exp(log pi - log pi_old);  L = -mean min(r A, clip(r, 1-eps, 1+eps) A) - c_ent H
            pl, dout = ppo_loss(out[..., :P], a, lp, A, self.n_x, clip, ent_coef)
            if self.aux > 0:          # + aux L_aux, as in BC; pl, logged, stays the policy's
                dout = self._add_aux(out, facts[idx], pl, dout)[1]
            vl, dv, _ = value_loss(critic.forward(f), returns[idx])  # 0.5 mean (V - R)^2
            # the loss returns (L, dL/dout) only, as exercise 4 asks: the logged figures come
            # from the distribution again (a few element-wise operations)
            stats = (*ppo_stats(self.action_dist(out[..., :P], self.n_x), a, lp, A, clip), vl)
            # backprop; the critic's loss is weighted by c_v:  d(c_v 0.5 (V - R)^2)/dout
            return (pl, vl, actor.backward(dout), critic.backward(vf_coef * dv),
                    np.array(stats))

        stats = []
        with self.data_parallel(self.actor, self.critic) as both_cores:
            for e in range(epochs):
                for i, idx in enumerate(_minibatches(len(obs), minibatch, rng)):
                    # = loss_and_grads(self.actor, self.critic, idx) up to rounding: its two
                    # halves on both cores, weighted by their sizes (as in _fit)
                    pl, vl, g_actor, g_critic, s = both_cores(loss_and_grads, idx)
                    # each network its own clip, g <- g min(1, max_norm / |g|) (a global norm)
                    g_actor, norm_actor = clip_grad_norm(g_actor, max_grad_norm)
                    g_critic, norm_critic = clip_grad_norm(g_critic, max_grad_norm)
                    check_finite(f"PPO update epoch {e + 1} minibatch {i + 1}", policy_loss=pl,
                                 value_loss=vl, actor_gradient_norm=norm_actor,
                                 critic_gradient_norm=norm_critic)
                    self.actor_opt.step(g_actor)                    # Adam, each its own state
                    self.critic_opt.step(g_critic)
                    stats.append(s)
                check_finite(f"PPO update epoch {e + 1}", actor_parameters=self.actor.params,
                             critic_parameters=self.critic.params)
        names = ("policy_loss", "entropy", "approx_kl", "clip_frac", "value_loss")
        return {**dict(zip(names, np.mean(stats, 0).tolist())), "explained_variance": ev}

    def data_parallel(self, *nets):
        """The updates' minibatch on both cores (taskexp_lib/shards.py): a context manager
        `both_cores` with both_cores(loss_and_grads, idx) = loss_and_grads(*nets, idx) up to
        rounding, the minibatch cut into SHARDS parts that run on replicas of the networks in
        self.threads threads, their results weighted by their share of it. The same bytes for
        any number of threads; the update methods stay one plain minibatch step."""
        return DataParallel(nets, self.threads)

    def _check_actions(self, actions):
        hi = np.array([self.n_blocks, self.n_x, self.n_y])
        if actions.ndim != 2 or actions.shape[1] != 3:
            raise ValueError(f"actions must have shape (N, 3), got {actions.shape}")
        bad = ((actions < 0) | (actions >= hi)).any(1)
        if bad.any():
            raise ValueError(f"actions must be ints below {hi.tolist()}, "
                             f"got {actions[bad][:5].tolist()}")

    # -------------------------------------------------------------------------- persistence

    def state_dict(self):
        """{"actor.embed.W0": array, ...}: every parameter, no optimiser state."""
        return {f"{net}.{k}": p for net in ("actor", "critic")
                for k, p in getattr(self, net).params.items()}

    def save(self, path, extra=None):
        """Write the agent, and any `extra` arrays, as a plain .npz checkpoint whose header says
        how to rebuild it (checkpoint.save_agent)."""
        checkpoint.save_agent(self, path, extra)

    @classmethod
    def load(cls, path, extra=()):
        """Read a checkpoint written by save -> Agent (or (Agent, {key: array}) for the keys in
        `extra`); ValueError naming the file and what does not match (checkpoint.load_agent)."""
        return checkpoint.load_agent(cls, path, extra)


_no_bar = partial(tqdm, disable=True)


def _minibatches(N, size, rng):
    """A random permutation of range(N) cut into index arrays of at most `size`."""
    perm = rng.permutation(N)
    return [perm[i:i + size] for i in range(0, N, size)]
