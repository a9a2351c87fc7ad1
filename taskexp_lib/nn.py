"""taskexp_lib/nn.py -- the layers of the agent's networks, each forward next to its backward.

numpy only, no autograd: a forward caches what its backward needs, and every backward is checked
against central finite differences (tests/test_agent.py, tests/test_attention.py).

  mlp_backward, MLP        tanh hidden layers, linear output
  softmax, softmax_backward
  SelfAttention            multi-head self-attention over tokens (the paper's network, sec 3)
  LayerNorm
  Adam, clip_grad_norm     the optimiser and the global gradient-norm clip
  check_finite             stop training at the first NaN or inf

A layer computes in the dtype it is made with: float64 for the finite-difference checks, float32
for training (Config.dtype).
"""
import math

import numpy as np


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
            z = self.hs[-1] @ self.params[f"W{k}"]
            z += self.params[f"b{k}"]                     # in place: no second array
            self.hs.append(np.tanh(z, out=z) if k < self.n_layers - 1 else z)
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
