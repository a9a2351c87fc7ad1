"""taskexp_lib/nets.py -- the two networks over block tokens (sec 3), each forward next to its
backward: one shared network per block, so they serve any order of the blocks.

  AttentionNet   self-attention between every pair of blocks: the paper's network (the default)
  SetNet         a deep set: blocks see each other only through pooled summaries

Both map features (B, n, F) to per-block outputs (B, n, out); the Agent reads the policy's logits
and, averaged over blocks, the value from them. Their layers are in nn.py.
"""
import numpy as np

from .nn import MLP, LayerNorm, SelfAttention, mlp_backward


class AttentionNet:
    """Transformer encoder over block tokens, with the interface of SetNet (below).

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
    tanh in the FFN (the authors use ReLU): it is nn.MLP, whose backward is already checked,
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

    def encode(self, f):
        """f (B, n, F) -> the tokens LN_f(x) (B, n, H) that the head reads: what each block knows
        of the others after the attention layers (lab/bench/probe.py asks what that is)."""
        m = self.modules
        x = self._tokens(m["embed"], np.asarray(f, dtype=self.dtype))
        for k in range(self.layers):
            b = f"block{k}."
            x = x + m[b + "attn"].forward(m[b + "ln1"].forward(x))
            x = x + self._tokens(m[b + "ffn"], m[b + "ln2"].forward(x))
        return m["ln_f"].forward(x)

    def forward(self, f):
        """f (B, n, F) -> o (B, n, out)."""
        return self._tokens(self.modules["head"], self.encode(f))

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


NETWORKS = {"setnet": SetNet, "attention": AttentionNet}
