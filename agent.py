"""Numpy agent for task expansion: MLPs with hand-written backward passes, a per-block set
network, the factorised action distribution, behaviour cloning, PPO and GAE.  (~570 lines)

Paper: "Self-Generating Data for Goal-Conditioned Compositional Problems" (Yuan, Li, Wu).
Sec 3: a goal-conditioned policy pi(a | s, g) and value V(s, g) over a set of blocks; an action
picks a block and a discrete target (x-bin, layer) for it.  Sec 4.1/4.3: behaviour cloning on
demonstrations (base skills, self-distillation); PPO fine-tuning with a sparse success reward.

Numpy with no autograd: each forward caches what its backward needs, and every backward is checked
against central finite differences in tests/test_agent.py.  The networks compute in the dtype they
are made with: float64 for those checks, float32 for training (taskexp.Config.dtype; twice as fast,
and the same learning); losses, log-probs and returns are always float64.
Randomness only through a passed np.random.Generator (or an integer seed for initialisation).
"""
import json
import math
import os
import zipfile

import numpy as np
from threadpoolctl import threadpool_limits

from env2d import BLOCK_H, BLOCK_W, GEOMETRY, TABLE_X, THRESHOLD, layer

# The networks' matmuls are tiny: with more than one BLAS thread they run 10-100x slower, and
# results change with the thread count. One thread, for every program that imports the agent.
threadpool_limits(limits=1)

FORMAT_VERSION = 3              # 2: the header records the world's GEOMETRY; 3: its features
N_RBF = 21                      # RBF centres spaced BLOCK_W / 2 across the table


# ---- Building blocks: MLP, Adam, gradient clipping ---------------------------------------

def mlp_backward(params, hs, dout):
    """The backward pass of MLP: params {"W0", "b0", ...}, hs the cached layer outputs
    [x, h_1, ..., out], dout (B, out) = dL/d(out)
    -> (grads {key: array like params}, dL/dx (B, in)).

    A function of its own so that a student's version (exercise 1) can be passed to MLP.
    """
    grads, d, n_layers = {}, dout, len(hs) - 1
    for k in reversed(range(n_layers)):
        if k < n_layers - 1:
            d = d * (1.0 - hs[k + 1] ** 2)                # tanh'(z) = 1 - tanh(z)^2
        grads[f"W{k}"] = hs[k].T @ d                      # dL/dW = h^T dz
        grads[f"b{k}"] = d.sum(0)
        d = d @ params[f"W{k}"].T                         # dL/dh = dz W^T
    return grads, d


class MLP:
    """tanh hidden layers, linear output.  h_{k+1} = tanh(h_k W_k + b_k); out = h_{L-1} W + b.

    W_k ~ N(0, 1/fan_in) keeps pre-activations O(1); the last layer is scaled by out_scale
    (0.01 for policy logits: a near-uniform initial policy explores every block and bin).
    backward_fn(params, hs, dout) -> (grads, dx) is the backward pass (default mlp_backward).
    The parameters are drawn in float64 and stored in `dtype`, so a float32 network starts from
    the same weights, rounded.
    """

    def __init__(self, sizes, seed=0, out_scale=1.0, backward_fn=mlp_backward, dtype=np.float64):
        rng = np.random.default_rng(seed)
        self.sizes, self.n_layers, self.params = list(sizes), len(sizes) - 1, {}
        self.backward_fn = backward_fn
        for k, (fan_in, fan_out) in enumerate(zip(sizes[:-1], sizes[1:])):
            scale = out_scale if k == self.n_layers - 1 else 1.0
            W = rng.standard_normal((fan_in, fan_out))
            self.params[f"W{k}"] = (W * (scale / np.sqrt(fan_in))).astype(dtype, copy=False)
            self.params[f"b{k}"] = np.zeros(fan_out, dtype)

    def forward(self, x):
        """x (B, in) -> (B, out).  Caches every layer's output for backward."""
        self.hs = [x]
        for k in range(self.n_layers):
            z = self.hs[-1] @ self.params[f"W{k}"] + self.params[f"b{k}"]
            self.hs.append(np.tanh(z) if k < self.n_layers - 1 else z)
        return self.hs[-1]

    def backward(self, dout):
        """dout (B, out) = dL/d(out) -> grads {key: array like params}; sets self.dx (B, in)."""
        grads, self.dx = self.backward_fn(self.params, self.hs, dout)
        return grads


class Adam:
    """Adam with bias correction; updates the arrays of `params` in place (so the networks,
    which hold the same arrays, see the new values).
        m = b1 m + (1-b1) g;  v = b2 v + (1-b2) g^2;  p -= lr mhat / (sqrt(vhat) + eps)
    """

    def __init__(self, params, lr=3e-4, betas=(0.9, 0.999), eps=1e-8):
        self.params, self.lr, (self.b1, self.b2), self.eps, self.t = params, lr, betas, eps, 0
        self.m = {k: np.zeros_like(p) for k, p in params.items()}
        self.v = {k: np.zeros_like(p) for k, p in params.items()}

    def step(self, grads):
        self.t += 1
        c1, c2 = 1.0 - self.b1 ** self.t, 1.0 - self.b2 ** self.t
        for k, g in grads.items():
            self.m[k] = self.b1 * self.m[k] + (1.0 - self.b1) * g
            self.v[k] = self.b2 * self.v[k] + (1.0 - self.b2) * g * g
            self.params[k] -= self.lr * (self.m[k] / c1) / (np.sqrt(self.v[k] / c2) + self.eps)


def check_finite(where, **named):
    """Stop training at the first NaN or inf: FloatingPointError naming `where` (phase and step)
    and what went bad.  named: scalars, arrays, or dicts of arrays (a network's parameters).
    Without this a single overflow turns every weight into NaN and the run saves garbage."""
    for name, v in named.items():
        items = v.items() if isinstance(v, dict) else [("", v)]
        bad = [k for k, a in items if not np.isfinite(a).all()]
        if bad:
            raise FloatingPointError(f"{where}: non-finite {name} {' '.join(bad[:3])}".rstrip())


def clip_grad_norm(grads, max_norm):
    """Rescale all grads together so their global L2 norm is <= max_norm -> (grads, total_norm)."""
    total = float(np.sqrt(sum(float(np.sum(g * g)) for g in grads.values())))
    if max_norm is not None and total > max_norm:
        grads = {k: g * (max_norm / (total + 1e-12)) for k, g in grads.items()}
    return grads, total


# ---- Features and the set network (sec 3: one shared network per block, pooled context) ----

# The feature layout: (name, width) of each column group, in order; n_y is the number of layers.
# Tests and notebooks find a feature by name (feature_columns), never by its column number.
# The features: "plain" (what one block and its goal are) or "relations" (plus RELATIONS,
# stacking preconditions computed by hand, which a network over plain features must learn).
FEATURES = ("plain", "relations")


def feature_layout(n_y, features="relations"):
    plain = [("x", 1), ("y", 1), ("cos", 1), ("sin", 1), ("has_goal", 1), ("goal_x", 1),
             ("goal_y", 1), ("to_goal_x", 1), ("to_goal_y", 1), ("at_goal", 1),
             ("layer", n_y), ("goal_layer", n_y), ("x_rbf", N_RBF), ("goal_x_rbf", N_RBF)]
    if features == "plain":
        return plain
    return plain + [*[(name, 1) for name in RELATIONS], ("support_wanted_rbf", N_RBF)]


def feature_columns(n_y, features="relations"):
    """{feature name: slice of its columns} for features made with n_y layers."""
    out, start = {}, 0
    for name, width in feature_layout(n_y, features):
        out[name], start = slice(start, start + width), start + width
    return out


def featurize(obs, n_y=None, features="relations"):
    """obs (B, n, 6) [x, y, angle, goal_x, goal_y, has_goal] -> features (B, n, F), laid out as
    feature_layout(n_y, features) says (F = 10 + 2 n_y + 2 N_RBF plain, 15 + 2 n_y + 3 N_RBF
    with the relations).

    Besides normalised pose, goal and offset to goal, each block gets one-hot codes of its layer
    and goal layer and RBF codes of its x and goal x: what it is and where it wants to be, on
    its own. Which block rests under which, or whose goal lies on whose, is a relation between
    two blocks: features="relations" adds hand-computed ones (RELATIONS); with "plain" the
    network must find them itself (self-attention compares every pair of blocks).
    Goal columns are multiplied by has_goal, so "no goal" is all zeros. The world's geometry
    comes from env2d.
    """
    if features not in FEATURES:
        raise ValueError(f"features {features!r}: one of {FEATURES}")
    obs = np.asarray(obs, dtype=np.float64)
    if obs.ndim != 3 or obs.shape[-1] != 6:
        raise ValueError(f"obs must have shape (B, n, 6), got {obs.shape}")
    n_y = obs.shape[1] if n_y is None else n_y
    w, h = BLOCK_W, BLOCK_H
    half, mid = (TABLE_X[1] - TABLE_X[0]) / 2, (TABLE_X[1] + TABLE_X[0]) / 2
    x, y, ang, gx, gy, g = (obs[..., j] for j in range(6))
    g = (g > 0.5).astype(np.float64)
    dist = np.hypot(gx - x, gy - y)
    onehot_layer = lambda v: np.eye(n_y)[np.clip(layer(v), 0, n_y - 1)]    # (B, n) -> (B, n, n_y)
    centres = np.linspace(TABLE_X[0], TABLE_X[1], N_RBF)
    rbf = lambda v: np.exp(-0.5 * ((v[..., None] - centres) / (w / 4)) ** 2)
    at_goal = g * (dist < THRESHOLD)
    cols = [(x - mid) / half, y / (n_y * h), np.cos(ang), np.sin(ang), g,
            g * (gx - mid) / half, g * gy / (n_y * h), g * (gx - x) / w, g * (gy - y) / h, at_goal]
    plain = [np.stack(cols, -1), onehot_layer(y), g[..., None] * onehot_layer(gy), rbf(x),
             g[..., None] * rbf(gx)]
    if features == "plain":
        return np.concatenate(plain, axis=-1)
    rel = relations(x, y, gx, gy, g, at_goal)
    return np.concatenate([*plain, np.stack([rel[name] for name in RELATIONS], -1),
                           rel["needs_support"][..., None] * rbf(gx)], axis=-1)


# Hand-computed stacking preconditions: what self-attention over blocks would have to learn.
RELATIONS = ("blocked", "supported", "wait", "first", "covered")


def relations(x, y, gx, gy, g, at_goal):
    """Pairwise facts about blocks and goals, pooled over the other blocks j (what attention finds).

    All inputs (B, n).  Returns {name: (B, n)} for the RELATIONS and needs_support:
      blocked     another block overlaps my goal spot now (placing me there would be a no-op)
      supported   my goal is on the table, or another block rests right under my goal spot now
      wait        another unreached goal lies under mine: that block must go first
      first       my goal lies under another block's goal: I am its support
      covered     a block rests on me now
      needs_support  has goal, not reached, not supported: a free block must go under it, and
                  the RBF code of its goal x (pooled) tells the free blocks where
    """
    w, h = BLOCK_W, BLOCK_H
    other = 1.0 - np.eye(x.shape[1])                                   # (n, n): j != i
    # (B, i, j): is |a_j - b_i| < tol
    near = lambda a, b, tol: (np.abs(a[:, None, :] - b[:, :, None]) < tol)
    any_j = lambda m: (m * other).max(-1)
    pending = g * (1.0 - at_goal)                                      # goals not reached yet
    out = dict(
        blocked=g * any_j(near(x, gx, w * 0.95) & near(y, gy, h * 0.95)),
        supported=g * np.maximum(gy < h, any_j(near(x, gx, w / 2) & near(y, gy - h, h / 2))),
        wait=g * any_j(pending[:, None, :] * (near(gx, gx, w) & near(gy, gy - h, h / 2))),
        first=g * any_j(g[:, None, :] * (near(gx, gx, w) & near(gy - h, gy, h / 2))),
        covered=any_j(near(x, x, w) & near(y - h, y, h / 2)))
    out["needs_support"] = pending * (1.0 - out["supported"])
    return out


class SetNet:
    """Deep set over blocks:  e_i = phi(f_i);  c = [mean_i e_i, max_i e_i];  o_i = rho([e_i, c]).

    Permutation-equivariant, so one network serves every block.  phi = MLP([F, H, H]),
    rho = MLP([3H, H, out]).  `params` holds the MLPs' own arrays under prefixed keys.
    """

    def __init__(self, n_features, hidden, out, seed=0, out_scale=1.0, mlp_backward=mlp_backward,
                 dtype=np.float64):
        self.dtype = np.dtype(dtype)
        self.phi = MLP([n_features, hidden, hidden], seed=[*np.atleast_1d(seed), 0],
                       backward_fn=mlp_backward, dtype=dtype)
        self.rho = MLP([3 * hidden, hidden, out], seed=[*np.atleast_1d(seed), 1],
                       out_scale=out_scale, backward_fn=mlp_backward, dtype=dtype)
        self.params = {f"{name}.{k}": p for name in ("phi", "rho")
                       for k, p in getattr(self, name).params.items()}

    def forward(self, f):
        """f (B, n, F) -> o (B, n, out), in the network's dtype."""
        f = f.astype(self.dtype, copy=False)
        B, n, F = f.shape
        e = self.phi.forward(f.reshape(B * n, F)).reshape(B, n, -1)
        self.argmax = e.argmax(axis=1)                                         # (B, H)
        c = np.concatenate([e.mean(1), np.take_along_axis(e, self.argmax[:, None], 1)[:, 0]], -1)
        z = np.concatenate([e, np.broadcast_to(c[:, None], (B, n, c.shape[-1]))], -1)
        return self.rho.forward(z.reshape(B * n, -1)).reshape(B, n, -1)

    def backward(self, dout):
        """dout (B, n, out) -> grads {"phi.W0": ..., "rho.b1": ...} for the last forward."""
        dout = dout.astype(self.dtype, copy=False)          # float64 losses, float32 network
        B, n, _ = dout.shape
        g_rho = self.rho.backward(dout.reshape(B * n, -1))
        dz = self.rho.dx.reshape(B, n, -1)
        H = dz.shape[-1] // 3
        de = dz[..., :H].copy()
        dc = dz[..., H:].sum(1)                                # c is shared by all n blocks
        de += dc[:, None, :H] / n                              # d mean / d e_i = 1/n
        dmax = np.zeros_like(de)                               # d max / d e_i: only the argmax
        np.put_along_axis(dmax, self.argmax[:, None], dc[:, None, H:], axis=1)
        g_phi = self.phi.backward((de + dmax).reshape(B * n, H))
        return {**{f"phi.{k}": v for k, v in g_phi.items()},
                **{f"rho.{k}": v for k, v in g_rho.items()}}


# ---- Self-attention over blocks: the paper's network (sec 3), an option for now --------------
#
# A transformer encoder over block tokens, as in the authors' code: every block looks at every
# other block, so relations such as "a block rests under my goal" can be learned instead of
# computed by hand (featurize's RELATIONS). Agent(network="attention") uses it in place of SetNet;
# it becomes the default once it learns as well (an open issue). No positional encoding: it is
# permutation-equivariant over the blocks, as SetNet is.

def softmax(s):
    """p = exp(s - max s) / sum exp(s - max s) over the last axis (the max keeps exp finite)."""
    e = np.exp(s - s.max(-1, keepdims=True))
    return e / e.sum(-1, keepdims=True)


def softmax_backward(p, dp):
    """dL/ds from p = softmax(s) and dp = dL/dp, row by row over the last axis.

    The Jacobian of one row is dp_i/ds_j = p_i (delta_ij - p_j), so
        ds_j = sum_i dp_i p_i (delta_ij - p_j) = p_j (dp_j - sum_i p_i dp_i).
    """
    # Softmax Jacobian: diag(p) - p p^T.  NOT p (1 - p) dp elementwise, which keeps only the
    # diagonal and forgets that raising one logit lowers every other probability in the row.
    return p * (dp - (p * dp).sum(-1, keepdims=True))


class SelfAttention:
    """Multi-head self-attention.  x (B, n, D) -> (B, n, D), heads of size d = D / heads.

        Q = x Wq + bq,  K = x Wk + bk,  V = x Wv + bv            split into heads (B, h, n, d)
        S = Q K^T / sqrt(d);  A = softmax(S) over keys             (B, h, n, n), rows sum to 1
        Y = A V;  out = concat_h(Y) Wo + bo

    1/sqrt(d) keeps the logits S O(1) when q, k have O(1) entries (q.k sums d products), so the
    softmax does not start saturated.  self.attn holds A of the last forward, for plotting.
    bk never gets a gradient: it adds q_i.bk to a whole row of S, and softmax ignores a constant
    shift of its row.  It is kept so that Q, K, V have the same form.
    Weights ~ N(0, 1/D) (variance-preserving for x with O(1) entries), biases 0.
    """

    NAMES = ("q", "k", "v", "o")

    def __init__(self, dim, heads=1, seed=0, dtype=np.float64):
        if dim % heads:
            raise ValueError(f"dim {dim} is not divisible by heads {heads}")
        rng = np.random.default_rng(seed)
        self.dim, self.heads, self.d, self.dtype = dim, heads, dim // heads, np.dtype(dtype)
        self.scale = 1.0 / math.sqrt(self.d)      # a Python float: keeps float32 arrays float32
        self.params = {}
        for c in self.NAMES:
            w = rng.standard_normal((dim, dim)) / np.sqrt(dim)
            self.params[f"W{c}"] = w.astype(self.dtype)
        for c in self.NAMES:
            self.params[f"b{c}"] = np.zeros(dim, self.dtype)

    def _split(self, z, B, n):
        """(B n, D) -> (B, h, n, d): head k owns columns k d .. (k+1) d of Q, K, V."""
        return z.reshape(B, n, self.heads, self.d).transpose(0, 2, 1, 3)

    def _merge(self, z):
        """(B, h, n, d) -> (B n, D), the inverse of _split (concat_h)."""
        B, h, n, d = z.shape
        return z.transpose(0, 2, 1, 3).reshape(B * n, h * d)

    def forward(self, x):
        """x (B, n, D) -> (B, n, D).  Caches x, Q, K, V, A, Y; keeps A in self.attn."""
        x = np.asarray(x, dtype=self.dtype)
        B, n, D = x.shape
        P = self.params
        self.x2 = x.reshape(B * n, D)                 # 2-D: one BLAS call, not B small ones
        self.Q, self.K, self.V = (self._split(self.x2 @ P[f"W{c}"] + P[f"b{c}"], B, n)
                                  for c in "qkv")                              # (B, h, n, d)
        S = (self.Q @ self.K.swapaxes(-1, -2)) * self.scale       # S = Q K^T / sqrt(d)
        self.attn = softmax(S)                                    # A, softmax over keys j
        self.Y = self._merge(self.attn @ self.V)                  # concat_h(A V)  (B n, D)
        return (self.Y @ P["Wo"] + P["bo"]).reshape(B, n, D)

    def backward(self, dout):
        """dout (B, n, D) -> grads {Wq, Wk, Wv, Wo, bq, bk, bv, bo}; sets self.dx (B, n, D)."""
        B, n, D = np.shape(dout)
        P, A, grads = self.params, self.attn, {}
        d2 = np.asarray(dout, dtype=self.dtype).reshape(B * n, D)
        grads["Wo"], grads["bo"] = self.Y.T @ d2, d2.sum(0)       # out = Y Wo + bo
        dY = self._split(d2 @ P["Wo"].T, B, n)                    # (B, h, n, d)
        # Y = A V.  dA = dY V^T and dV = A^T dY: the transposes move the sum to the shared
        # index (dA_ij = dy_i . v_j;  dv_j = sum_i A_ij dy_i, summed over the queries i).
        dA = dY @ self.V.swapaxes(-1, -2)                         # (B, h, n, n)
        dV = A.swapaxes(-1, -2) @ dY                              # (B, h, n, d)
        dS = softmax_backward(A, dA)                              # full Jacobian, see above
        # S = Q K^T / sqrt(d): the same 1/sqrt(d) of the forward scales dQ and dK.
        dS = dS * self.scale
        dQ = dS @ self.K                                          # dq_i = sum_j dS_ij k_j
        dK = dS.swapaxes(-1, -2) @ self.Q                         # dk_j = sum_i dS_ij q_i
        dx = np.zeros_like(self.x2)
        for c, dz in zip("qkv", (dQ, dK, dV)):
            dz = self._merge(dz)                                  # (B n, D)
            grads[f"W{c}"], grads[f"b{c}"] = self.x2.T @ dz, dz.sum(0)
            dx += dz @ P[f"W{c}"].T                               # x feeds Q, K and V
        self.dx = dx.reshape(B, n, D)
        return {k: grads[k] for k in self.params}


class LayerNorm:
    """Per token over the last axis:  y = (x - mu) / sqrt(var + eps) * gain + bias.

    Backward, with xhat = (x - mu) rstd, rstd = 1/sqrt(var + eps) and g = dy * gain:
        dx = rstd (g - mean(g) - xhat mean(g xhat))
    the mean(g) term because mu depends on every x_j, the xhat term because var does.
    """

    def __init__(self, dim, eps=1e-5, dtype=np.float64):
        self.eps, self.dtype = float(eps), np.dtype(dtype)
        self.params = {"gain": np.ones(dim, self.dtype), "bias": np.zeros(dim, self.dtype)}

    def forward(self, x):
        """x (..., D) -> (..., D)."""
        x = np.asarray(x, dtype=self.dtype)
        xc = x - x.mean(-1, keepdims=True)
        self.rstd = 1.0 / np.sqrt((xc * xc).mean(-1, keepdims=True) + self.eps)
        self.xhat = xc * self.rstd
        return self.xhat * self.params["gain"] + self.params["bias"]

    def backward(self, dout):
        """dout (..., D) -> grads {gain, bias}; sets self.dx (..., D)."""
        dout = np.asarray(dout, dtype=self.dtype)
        D = dout.shape[-1]
        g = dout * self.params["gain"]
        self.dx = self.rstd * (g - g.mean(-1, keepdims=True)
                               - self.xhat * (g * self.xhat).mean(-1, keepdims=True))
        return {"gain": (dout * self.xhat).reshape(-1, D).sum(0),
                "bias": dout.reshape(-1, D).sum(0)}


class AttentionNet:
    """Transformer encoder over block tokens, with the interface of agent.SetNet.

        x_i = phi(f_i)                 phi = MLP([F, H, H])   (tanh hidden, linear out)
        for each layer l:
            x = x + Attn_l(LN1_l(x))   multi-head self-attention, `heads` heads
            x = x + FFN_l(LN2_l(x))    FFN = MLP([H, H, H])   (tanh hidden, linear out)
        o_i = rho(LN_f(x_i))           rho = MLP([H, H, out]), last layer scaled by out_scale

    Pre-LN (LN inside the residual branch, Xiong et al. 2020) rather than the post-LN of the
    original transformer and of the authors' code: the residual stream x is an identity path
    from every block's output to the embedding, so gradients reach the early layers unscaled
    and training is stable at a fixed Adam learning rate without warm-up, which is how the
    agent trains.  The stream itself is never normalised, hence LN_f before the head.
    (The authors' encoder, policies/attention_discrete.py, is post-LN: x = LN(x + Attn(x)),
    then x = LN(FFN(x)) with no residual around the FFN; their critic mean-pools the token
    features before an MLP, where here, as with SetNet, per-token values are mean-pooled.)
    tanh in the FFN (the authors use ReLU): it is agent.MLP, whose backward is already checked,
    it is smooth, so finite-difference checks have no kinks to straddle, and LN in front keeps
    its inputs O(1), away from saturation.

    `params` holds the sub-modules' own arrays under prefixed keys ("embed.W0",
    "block1.attn.Wq", "block0.ln2.gain", "ln_f.bias", "head.W1", ...), so an optimiser updating
    them in place updates the network.  dtype=np.float32 keeps params, outputs and grads float32
    (inputs are cast); initial values are the float64 ones rounded, for any dtype.
    """

    def __init__(self, n_features, hidden, out, seed=0, out_scale=1.0, heads=2, layers=2,
                 mlp_backward=mlp_backward, dtype=np.float64):
        self.dtype, self.layers = np.dtype(dtype), int(layers)
        # Sub-module seeds [*seed, k(, k + 1)] with k >= 1: SeedSequence ignores trailing zeros
        # ([s, 0] is the stream of s itself), so no appended index is 0.
        s = [*np.atleast_1d(seed)]
        mlp = lambda sizes, seed, out_scale=1.0: MLP(sizes, seed, out_scale, mlp_backward, dtype)
        self.modules = {"embed": mlp([n_features, hidden, hidden], [*s, 1])}
        for k in range(self.layers):
            self.modules[f"block{k}.ln1"] = LayerNorm(hidden, dtype=self.dtype)
            self.modules[f"block{k}.attn"] = SelfAttention(hidden, heads, [*s, 2, k + 1],
                                                           self.dtype)
            self.modules[f"block{k}.ln2"] = LayerNorm(hidden, dtype=self.dtype)
            self.modules[f"block{k}.ffn"] = mlp([hidden] * 3, [*s, 3, k + 1])
        self.modules["ln_f"] = LayerNorm(hidden, dtype=self.dtype)
        self.modules["head"] = mlp([hidden, hidden, out], [*s, 4], out_scale)
        self.params = {f"{name}.{k}": p for name, m in self.modules.items()
                       for k, p in m.params.items()}

    @property
    def attn(self):
        """Attention weights of the last forward, one (B, heads, n, n) array per layer."""
        return [self.modules[f"block{k}.attn"].attn for k in range(self.layers)]

    def _tokens(self, mlp, x):
        """Apply an MLP (which takes (rows, in)) to every token of x (B, n, in)."""
        B, n, _ = x.shape
        return mlp.forward(x.reshape(B * n, -1)).reshape(B, n, -1)

    def _tokens_backward(self, mlp, dout):
        """Backward of _tokens -> (grads, dL/dx (B, n, in))."""
        B, n, _ = dout.shape
        grads = mlp.backward(dout.reshape(B * n, -1))
        return grads, mlp.dx.reshape(B, n, -1)

    def forward(self, f):
        """f (B, n, F) -> o (B, n, out)."""
        m = self.modules
        x = self._tokens(m["embed"], np.asarray(f, dtype=self.dtype))
        for k in range(self.layers):
            b = f"block{k}."
            x = x + m[b + "attn"].forward(m[b + "ln1"].forward(x))
            x = x + self._tokens(m[b + "ffn"], m[b + "ln2"].forward(x))
        return self._tokens(m["head"], m["ln_f"].forward(x))

    def backward(self, dout):
        """dout (B, n, out) -> grads {"embed.W0": ..., "head.b1": ...}; sets self.dx (B, n, F)."""
        m, grads = self.modules, {}
        grads["head"], dz = self._tokens_backward(m["head"], np.asarray(dout, dtype=self.dtype))
        grads["ln_f"] = m["ln_f"].backward(dz)
        dx = m["ln_f"].dx
        for k in reversed(range(self.layers)):
            b = f"block{k}."
            # x_out = x + branch(x): the identity passes dx through, the branch adds its own.
            grads[b + "ffn"], dh = self._tokens_backward(m[b + "ffn"], dx)
            grads[b + "ln2"] = m[b + "ln2"].backward(dh)
            dx = dx + m[b + "ln2"].dx
            grads[b + "attn"] = m[b + "attn"].backward(dx)
            grads[b + "ln1"] = m[b + "ln1"].backward(m[b + "attn"].dx)
            dx = dx + m[b + "ln1"].dx
        grads["embed"], self.dx = self._tokens_backward(m["embed"], dx)
        return {f"{name}.{k}": grads[name][k] for name in m for k in m[name].params}


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
        i = np.arange(self.shape[0])
        b = (self.lb + self.lx.max(-1) + self.ly.max(-1)).argmax(-1)
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


def ppo_loss(out, actions, logp_old, adv, n_x, clip, ent_coef):
    """Clipped surrogate with entropy bonus (Schulman et al. 2017); adv already normalised.

        r = exp(logp - logp_old);  L = -mean min(r A, clip(r, 1-eps, 1+eps) A) - c_ent mean H
    d/dlogp of min(..) is r A where the unclipped term is the min, else 0 (the clipped term is
    constant).  -> (L, dL/d out, info dict with the policy loss, entropy, ratios).
    """
    dist = ActionDist(out, n_x)
    B = len(actions)
    r = np.exp(dist.log_prob(actions) - logp_old)
    unclipped, clipped = r * adv, np.clip(r, 1 - clip, 1 + clip) * adv
    l_clip = -np.minimum(unclipped, clipped).mean()
    H = dist.entropy()
    a = -np.where(unclipped <= clipped, unclipped, 0.0) / B    # d L / d logp
    dout = dist.backward(actions, a, -ent_coef / B)
    return l_clip - ent_coef * H.mean(), dout, dict(policy_loss=l_clip, entropy=H.mean(), ratio=r)


def value_loss(out, returns):
    """V = mean_i o_i;  L = mean 0.5 (V - R)^2  -> (L, dL/d out (B, n, 1), V (B,))."""
    B, n, _ = out.shape
    V = out[..., 0].mean(-1)
    dout = np.broadcast_to(((V - returns) / (B * n))[:, None, None], out.shape).copy()
    return 0.5 * np.mean((V - returns) ** 2), dout, V


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

NETWORKS = {"setnet": SetNet, "attention": AttentionNet}


class Agent:
    """Policy pi(b, x, y | s, g) and value V(s, g): two networks (SetNets, or AttentionNets with
    network="attention") with separate Adam states, over featurize's plain features or, with
    features="relations", the hand-computed relations too.

    n_y is the size of the policy's y head: the world's layers (the default), or 1 for a world
    that drops blocks (env2d.BlockWorld(drop=True)). The features always code n_blocks layers.
    The defaults are the deep set with hand relations that the exercises train; a run builds its
    agent from its Config with taskexp.make_agent.

    mlp_backward(params, hs, dout) -> (grads, dx) is the backward pass of every MLP in them, and
    action_dist the class of the policy's distribution (default ActionDist): the library's, or a
    student's (exercise 7 trains with them).
    """

    def __init__(self, n_blocks=6, n_x=37, n_y=None, hidden=128, seed=0, mlp_backward=mlp_backward,
                 dtype="float64", action_dist=None, network="setnet", features="relations"):
        self.n_blocks, self.n_x, self.hidden = int(n_blocks), int(n_x), int(hidden)
        self.n_y = self.n_blocks if n_y is None else int(n_y)
        self.dtype, self.action_dist = np.dtype(dtype), action_dist or ActionDist
        if self.dtype not in (np.float32, np.float64):
            raise ValueError(f"dtype {dtype!r}: the networks compute in float32 or float64")
        if network not in NETWORKS:
            raise ValueError(f"network {network!r}: one of {sorted(NETWORKS)}")
        self.network, Net = network, NETWORKS[network]
        self.feature_set = features
        F = self.features(np.zeros((1, self.n_blocks, 6))).shape[-1]
        self.actor = Net(F, hidden, 1 + self.n_x + self.n_y, seed=[seed, 0], out_scale=0.01,
                         mlp_backward=mlp_backward, dtype=self.dtype)
        self.critic = Net(F, hidden, 1, seed=[seed, 1], mlp_backward=mlp_backward,
                          dtype=self.dtype)
        self.actor_opt, self.critic_opt = Adam(self.actor.params), Adam(self.critic.params)
        self.rng = np.random.default_rng([seed, 2])     # only when a caller passes no Generator

    def features(self, obs):
        """obs (B, n, 6) -> (B, n, F) in the networks' dtype; checks the number of blocks."""
        obs = np.asarray(obs, dtype=np.float64)
        if obs.ndim != 3 or obs.shape[1:] != (self.n_blocks, 6):
            raise ValueError(f"obs must have shape (B, {self.n_blocks}, 6), got {obs.shape}")
        return featurize(obs, self.n_blocks, self.feature_set).astype(self.dtype, copy=False)

    def _batched(self, obs):
        obs = np.asarray(obs, dtype=np.float64)
        return (obs[None], True) if obs.ndim == 2 else (obs, False)

    def act(self, obs, deterministic=False, rng=None):
        """obs (n, 6) -> action (3,) int64, or (B, n, 6) -> (B, 3).  Samples with rng (default:
        the agent's own seeded Generator), or takes the joint mode when deterministic."""
        obs, single = self._batched(obs)
        dist = self.action_dist(self.actor.forward(self.features(obs)), self.n_x)
        a = dist.mode() if deterministic else dist.sample(self.rng if rng is None else rng)
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
        dist = self.action_dist(self.actor.forward(f), self.n_x)
        a = dist.sample(self.rng if rng is None else rng)
        return a, dist.log_prob(a), self.critic.forward(f)[..., 0].mean(-1)

    def bc(self, obs, actions, epochs, batch_size, lr, rng, max_grad_norm=None):
        """Behaviour cloning (sec 4.1, 4.3): minimise L_BC = -mean log pi(a | s, g) by Adam.

        obs (N, n, 6), actions (N, 3).  -> list of the mean minibatch loss of each epoch.
        """
        actions = np.asarray(actions, dtype=np.int64)
        self._check_actions(actions)
        loss = lambda out, a: bc_loss(out, a, self.n_x, self.action_dist)
        return self._fit("BC", self.actor, self.actor_opt, loss, obs, actions, epochs,
                         batch_size, lr, rng, max_grad_norm)

    def fit_value(self, obs, returns, epochs, batch_size, lr, rng, max_grad_norm=None):
        """Regress V(s, g) on returns (e.g. of demonstrations): L = mean 0.5 (V - R)^2.

        obs (N, n, 6), returns (N,).  -> list of the mean minibatch loss of each epoch.
        """
        returns = np.asarray(returns, np.float64)
        return self._fit("value fit", self.critic, self.critic_opt, value_loss, obs, returns,
                         epochs, batch_size, lr, rng, max_grad_norm)

    def _fit(self, phase, net, opt, loss_fn, obs, targets, epochs, batch_size, lr, rng,
             max_grad_norm):
        """Minibatch Adam on loss_fn(out, targets) -> (L, dL/dout, ...); features are computed
        per minibatch, as (N, n, F) float64 for N = 100k would need ~300 MB."""
        obs, opt.lr, losses = np.asarray(obs, dtype=np.float64), lr, []
        for e in range(epochs):
            epoch = []
            for i, idx in enumerate(_minibatches(len(obs), batch_size, rng)):
                loss, dout = loss_fn(net.forward(self.features(obs[idx])), targets[idx])[:2]
                grads, norm = clip_grad_norm(net.backward(dout), max_grad_norm)
                check_finite(f"{phase} epoch {e + 1} minibatch {i + 1}", loss=loss,
                             gradient_norm=norm)
                opt.step(grads)
                epoch.append(loss)
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
           explained_variance  1 - Var(R - V) / Var(R) over the batch, V before the update
                        (nan when Var(R) = 0)
        """
        rng = self.rng if rng is None else rng
        obs, actions = np.asarray(obs, dtype=np.float64), np.asarray(actions, dtype=np.int64)
        self._check_actions(actions)
        logp_old, returns = np.asarray(logp_old, np.float64), np.asarray(returns, np.float64)
        adv = np.asarray(adv, dtype=np.float64)
        check_finite("PPO update: inputs", logp_old=logp_old, advantages=adv, returns=returns)
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)
        features = self.features(obs)               # once: they do not change within the update
        v_before = self.critic.forward(features)[..., 0].mean(-1)
        var_r = np.var(returns)
        ev = float(1.0 - np.var(returns - v_before) / var_r) if var_r > 0 else float("nan")
        self.actor_opt.lr = self.critic_opt.lr = lr
        stats = []
        for e in range(epochs):
            for i, idx in enumerate(_minibatches(len(obs), minibatch, rng)):
                f = features[idx]
                pl, dout, info = ppo_loss(self.actor.forward(f), actions[idx], logp_old[idx],
                                          adv[idx], self.n_x, clip, ent_coef)
                g_actor, norm_actor = clip_grad_norm(self.actor.backward(dout), max_grad_norm)
                vl, dv, _ = value_loss(self.critic.forward(f), returns[idx])
                g_critic, norm_critic = clip_grad_norm(self.critic.backward(vf_coef * dv),
                                                       max_grad_norm)
                check_finite(f"PPO update epoch {e + 1} minibatch {i + 1}", policy_loss=pl,
                             value_loss=vl, actor_gradient_norm=norm_actor,
                             critic_gradient_norm=norm_critic)
                self.actor_opt.step(g_actor)
                self.critic_opt.step(g_critic)
                r = info["ratio"]
                stats.append((info["policy_loss"], vl, info["entropy"], np.mean(r - 1 - np.log(r)),
                              np.mean(np.abs(r - 1) > clip)))
            check_finite(f"PPO update epoch {e + 1}", actor_parameters=self.actor.params,
                         critic_parameters=self.critic.params)
        names = ("policy_loss", "value_loss", "entropy", "approx_kl", "clip_frac")
        return {**dict(zip(names, np.mean(stats, 0).tolist())), "explained_variance": ev}

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
        """{"actor.phi.W0": array, ...}: every parameter, no optimiser state."""
        return {f"{net}.{k}": p for net in ("actor", "critic")
                for k, p in getattr(self, net).params.items()}

    def training_state(self):
        """What decides future updates besides the parameters, for resuming a run exactly:
        both Adam states (m, v, t) and the agent's own Generator (its state as JSON text)."""
        out = {"rng": np.array(json.dumps(self.rng.bit_generator.state))}
        for name in ("actor_opt", "critic_opt"):
            opt = getattr(self, name)
            out[f"{name}.t"] = np.array(opt.t, dtype=np.int64)
            out.update({f"{name}.{mv}.{k}": a for mv in "mv" for k, a in getattr(opt, mv).items()})
        return out

    def load_training_state(self, data, path):
        """Inverse of training_state, from the arrays `data` of file `path` (named in errors)."""
        for key, want in self.training_state().items():
            have = data.get(key)
            if have is None or have.shape != want.shape or have.dtype.kind != want.dtype.kind:
                raise ValueError(f"{path}: {key} missing or not like {want.dtype} {want.shape}")
        self.rng.bit_generator.state = json.loads(str(data["rng"]))
        for name in ("actor_opt", "critic_opt"):
            opt = getattr(self, name)
            opt.t = int(data[f"{name}.t"])
            for mv in "mv":
                getattr(opt, mv).update({k: data[f"{name}.{mv}.{k}"].copy() for k in opt.params})

    def save(self, path, extra=None):
        """Write the parameters plus a header and any `extra` arrays as a plain .npz (save_npz).
        The header is what load needs to rebuild the agent: "format_version", "sizes" (n_blocks,
        n_x, n_y, hidden), "dtype" (float32 or float64), "network", "features" and "geometry",
        the world's env2d.GEOMETRY that the features assume."""
        save_npz(path, {**self.header(), **self.state_dict(), **(extra or {})})

    def header(self):
        return {"format_version": np.array(FORMAT_VERSION, dtype=np.int64),
                "sizes": np.array([self.n_blocks, self.n_x, self.n_y, self.hidden], dtype=np.int64),
                "dtype": np.array(self.dtype.name),
                "network": np.array(self.network),
                "features": np.array(self.feature_set),
                "geometry": np.array(list(GEOMETRY.values()), dtype=np.float64)}

    @classmethod
    def load(cls, path, extra=()):
        """Read a file written by save -> Agent (or (Agent, {key: array}) for the keys in `extra`).
        ValueError naming the file on a corrupt or truncated file, a wrong format version, a world
        of another geometry, or keys/shapes that do not match the sizes."""
        data = load_npz(path)
        if "state_version" in data and "state_version" not in extra:
            raise ValueError(f"{path}: a run's resume state, not an agent checkpoint; load one of "
                             "the run's round{k}.npz files")
        if "format_version" not in data or "sizes" not in data:
            raise ValueError(f"{path}: not an agent checkpoint (no format_version and sizes)")
        version, sizes = data["format_version"], data["sizes"]
        if version.shape != () or version.dtype.kind not in "iu" or int(version) != FORMAT_VERSION:
            raise ValueError(f"{path}: format_version {version}, expected {FORMAT_VERSION}")
        if sizes.shape != (4,) or sizes.dtype.kind not in "iu" or (sizes < 1).any():
            raise ValueError(f"{path}: sizes {sizes}, expected 4 positive ints "
                             "(n_blocks, n_x, n_y, hidden)")
        geometry = data.get("geometry", np.zeros(0))
        if geometry.shape != (len(GEOMETRY),) or (geometry != list(GEOMETRY.values())).any():
            saved = dict(zip(GEOMETRY, geometry.tolist()))
            diff = {k: (saved.get(k), v) for k, v in GEOMETRY.items() if saved.get(k) != v}
            raise ValueError(f"{path}: made for a world of other geometry than env2d's "
                             f"(saved, now): {diff}")
        n_blocks, n_x, n_y, hidden = (int(k) for k in sizes)
        dtype = str(data.get("dtype", ""))
        if dtype not in ("float32", "float64"):
            raise ValueError(f"{path}: dtype {dtype!r}, expected float32 or float64")
        network = str(data.get("network", ""))
        if network not in NETWORKS:
            raise ValueError(f"{path}: network {network!r}, expected one of {sorted(NETWORKS)}")
        features = str(data.get("features", ""))
        if features not in FEATURES:
            raise ValueError(f"{path}: features {features!r}, expected one of {FEATURES}")
        agent = cls(n_blocks, n_x, n_y, hidden, dtype=dtype, network=network, features=features)
        params, extra = agent.state_dict(), set(extra)
        missing = extra - set(data)
        if missing:
            raise ValueError(f"{path}: missing {sorted(missing)}")
        stored = set(data) - set(agent.header()) - extra
        if set(params) != stored:
            raise ValueError(f"{path}: keys do not match sizes {sizes.tolist()}: "
                             f"{sorted(set(params) ^ stored)}")
        for k, p in params.items():
            have = data[k]
            if have.shape != p.shape or have.dtype != p.dtype or not np.isfinite(have).all():
                raise ValueError(f"{path}: {k} is {data[k].dtype} {data[k].shape}, expected finite "
                                 f"{p.dtype} {p.shape} for sizes {sizes.tolist()}")
            p[...] = data[k]                      # in place: the networks and Adam share p
        return (agent, {k: data[k] for k in extra}) if extra else agent


def save_npz(path, arrays):
    """Write {name: array} as a plain .npz (no pickle).  Atomic -- a temporary file, then
    os.replace -- so a run killed mid-write leaves the previous file intact; byte-identical for
    identical arrays (fixed zip timestamps, sorted keys), so runs can be compared file to file."""
    tmp = f"{path}.tmp{os.getpid()}"
    try:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_STORED) as zf:
            for key in sorted(arrays):
                info = zipfile.ZipInfo(key + ".npy", date_time=(1980, 1, 1, 0, 0, 0))
                with zf.open(info, "w", force_zip64=True) as fh:
                    np.lib.format.write_array(fh, np.asarray(arrays[key]), allow_pickle=False)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def load_npz(path):
    """Read a .npz without pickle -> {name: array}; ValueError naming the file if unreadable."""
    try:
        z = np.load(path, allow_pickle=False)
        if not isinstance(z, np.lib.npyio.NpzFile):       # a bare .npy array, not named arrays
            raise ValueError("a single array")
        with z:
            return {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as e:
        # numpy's own message for a file that is no zip suggests allow_pickle: never do that here
        why = "not a zip of arrays" if "pickle" in str(e) else f"{type(e).__name__}: {e}"
        raise ValueError(f"{path}: not a readable .npz file, so not a checkpoint ({why})") from e


def _minibatches(N, size, rng):
    """A random permutation of range(N) cut into index arrays of at most `size`."""
    perm = rng.permutation(N)
    return [perm[i:i + size] for i in range(0, N, size)]
