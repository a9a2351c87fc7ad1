"""Tests of agent.py's self-attention network: every backward against central finite differences
(float64), that the comparison catches the classic attention-backward mistakes, permutation
equivariance, attention rows summing to 1, float32, and use as a drop-in for nets.SetNet."""
import numpy as np
import pytest

from course.grader import numerical_grad  # central differences, step 1e-6
from taskexp_lib import nn
from taskexp_lib.nets import AttentionNet
from taskexp_lib.nn import LayerNorm, SelfAttention, softmax

TOL = 1e-6


def rel_err(a, b):
    return np.linalg.norm(a - b) / max(np.linalg.norm(a) + np.linalg.norm(b), 1e-12)


def gradient_errors(module, x, seed=0):
    """Backward of `module` for the loss L = sum(R * module(x)), R random, against central
    differences -> {param key or "dx": relative error}.  The same helper judges the real
    modules and the deliberately broken ones below."""
    R = np.random.default_rng(seed).standard_normal(module.forward(x).shape)
    loss = lambda: float(np.sum(module.forward(x) * R))
    module.forward(x)
    grads = module.backward(R)
    assert list(grads) == list(module.params)
    errs = {k: rel_err(grads[k], numerical_grad(loss, p)) for k, p in module.params.items()}
    module.forward(x)
    module.backward(R)
    errs["dx"] = rel_err(module.dx, numerical_grad(loss, x))
    return errs, grads


def assert_gradients_match(module, x, zero=()):
    """Every relative error < TOL, except params in `zero`, whose true gradient is 0: there the
    analytic one must be ~0 (a relative error of two round-off numbers means nothing)."""
    errs, grads = gradient_errors(module, x)
    for k, e in errs.items():
        if k in zero:
            assert np.abs(grads[k]).max() < 1e-12, k
        else:
            assert e < TOL, (k, e)
    return errs


# ----------------------------------------------------------------------------- gradients

@pytest.mark.parametrize("heads", [1, 2])
def test_self_attention_backward_matches_finite_differences(heads):
    rng = np.random.default_rng(heads)
    att = SelfAttention(8, heads=heads, seed=[heads, 0])
    for c in "qkvo":                               # nonzero biases, so their grads are tested
        att.params[f"b{c}"] += 0.3 * rng.standard_normal(8)
    x = 2.0 * rng.standard_normal((3, 4, 8))
    att.forward(x)
    rowmax = att.attn.max(-1)                      # rows neither uniform (1/4) nor one-hot
    assert rowmax.min() > 0.3 and rowmax.mean() < 0.8, (rowmax.min(), rowmax.mean())
    assert_gradients_match(att, x, zero=["bk"])    # softmax ignores a shift of its whole row


def test_layer_norm_backward_matches_finite_differences():
    rng = np.random.default_rng(3)
    ln = LayerNorm(8)
    ln.params["gain"][:] = rng.standard_normal(8)
    ln.params["bias"][:] = rng.standard_normal(8)
    x = 2.0 + 3.0 * rng.standard_normal((3, 4, 8))
    assert_gradients_match(ln, x)


@pytest.mark.parametrize("layers", [1, 2])
def test_attention_net_backward_matches_finite_differences(layers):
    rng = np.random.default_rng(10 + layers)
    net = AttentionNet(7, 8, 5, seed=layers, out_scale=0.5, heads=2, layers=layers)
    for k, p in net.params.items():
        p += 0.2 * rng.standard_normal(p.shape)    # LN gains away from 1, biases away from 0
    f = rng.standard_normal((3, 4, 7))
    zero = [f"block{k}.attn.bk" for k in range(layers)]
    errs = assert_gradients_match(net, f, zero=zero)
    assert len(errs) == len(net.params) + 1


# ------------------------------------------------------- the check catches classic mistakes

class ElementwiseSoftmax(SelfAttention):
    """softmax'(s) = p (1 - p) elementwise: only the diagonal of the Jacobian."""

    def backward(self, dout):
        right = nn.softmax_backward
        nn.softmax_backward = lambda p, dp: p * (1 - p) * dp
        try:
            return super().backward(dout)
        finally:
            nn.softmax_backward = right


class UnscaledBackward(SelfAttention):
    """Forward divides by sqrt(d), backward forgets to."""

    def backward(self, dout):
        right, self.scale = self.scale, 1.0
        try:
            return super().backward(dout)
        finally:
            self.scale = right


@pytest.mark.parametrize("broken, wrong", [(ElementwiseSoftmax, ["Wq", "Wk", "bq", "dx"]),
                                           (UnscaledBackward, ["Wq", "Wk", "bq", "dx"])])
def test_gradient_check_detects_broken_backward(broken, wrong):
    rng = np.random.default_rng(5)
    att = broken(8, heads=2, seed=5)
    for p in att.params.values():
        p += 0.3 * rng.standard_normal(p.shape)
    errs, _ = gradient_errors(att, rng.standard_normal((3, 4, 8)))
    for k in wrong:
        assert errs[k] > 1e-2, (k, errs[k])
    for k in ["Wv", "bv", "Wo", "bo"]:             # untouched by the mistake: still right
        assert errs[k] < TOL, (k, errs[k])


def test_softmax_backward_is_full_jacobian():
    rng = np.random.default_rng(6)
    s, dp = rng.standard_normal(5), rng.standard_normal(5)
    p = softmax(s)
    J = np.diag(p) - np.outer(p, p)                # dp_i/ds_j
    assert np.allclose(nn.softmax_backward(p, dp), J.T @ dp)


# ----------------------------------------------------------------------------- behaviour

def test_permutation_equivariance():
    rng = np.random.default_rng(7)
    net = AttentionNet(7, 8, 5, seed=1, heads=2, layers=2)
    f = rng.standard_normal((3, 5, 7))
    perm = rng.permutation(5)
    out, attn = net.forward(f), net.attn
    assert np.allclose(net.forward(f[:, perm]), out[:, perm], atol=1e-12)
    for a, a_perm in zip(attn, net.attn):          # query and key axes both permute
        assert np.allclose(a_perm, a[:, :, perm][..., perm], atol=1e-12)


def test_attention_weights_are_distributions_over_keys():
    rng = np.random.default_rng(8)
    att = SelfAttention(8, heads=2, seed=0)
    att.forward(3.0 * rng.standard_normal((3, 4, 8)))
    assert att.attn.shape == (3, 2, 4, 4)
    assert (att.attn >= 0).all() and np.allclose(att.attn.sum(-1), 1.0)
    net = AttentionNet(7, 8, 5, layers=2)
    net.forward(rng.standard_normal((3, 4, 7)))
    assert all(np.allclose(a.sum(-1), 1.0) for a in net.attn)


def test_softmax_stable_for_large_logits():
    p = softmax(np.array([[1000.0, 0.0, -1000.0]]))
    assert np.isfinite(p).all() and np.allclose(p, [[1, 0, 0]])


def test_init_scales_and_seeds():
    att = SelfAttention(128, heads=2, seed=[3, 0])
    assert abs(att.params["Wq"].std() - 1 / np.sqrt(128)) < 0.05 / np.sqrt(128)
    assert not any(att.params[f"b{c}"].any() for c in "qkvo")
    assert np.array_equal(att.params["Wk"], SelfAttention(128, 2, seed=[3, 0]).params["Wk"])
    # every weight matrix of an actor- and a critic-seeded net starts different from the others
    nets = [AttentionNet(8, 8, 8, seed=[0, 0]), AttentionNet(8, 8, 8, seed=[0, 1])]
    firsts = [p.ravel()[0] for net in nets for k, p in net.params.items() if "W" in k]
    assert len(set(firsts)) == len(firsts)
    again = AttentionNet(8, 8, 8, seed=[0, 1])
    assert all(np.array_equal(p, again.params[k]) for k, p in nets[1].params.items())
    with pytest.raises(ValueError):
        SelfAttention(10, heads=3)


def test_out_scale_shrinks_initial_outputs():
    f = np.random.default_rng(9).standard_normal((4, 6, 7))
    big = AttentionNet(7, 16, 5, seed=0).forward(f)
    small = AttentionNet(7, 16, 5, seed=0, out_scale=0.01).forward(f)
    assert np.allclose(small, 0.01 * big, atol=1e-12)    # biases start at 0


def test_float32_keeps_dtype_and_matches_float64():
    rng = np.random.default_rng(10)
    f, R = rng.standard_normal((3, 4, 7)), rng.standard_normal((3, 4, 5))   # float64 inputs
    net32 = AttentionNet(7, 16, 5, seed=2, dtype=np.float32)
    net64 = AttentionNet(7, 16, 5, seed=2)
    out = net32.forward(f)
    grads = net32.backward(R)
    assert out.dtype == np.float32 and net32.dx.dtype == np.float32
    assert all(p.dtype == np.float32 for p in net32.params.values())
    assert all(g.dtype == np.float32 for g in grads.values())
    assert all(a.dtype == np.float32 for a in net32.attn)
    assert np.allclose(out, net64.forward(f), atol=1e-4)
    g64 = net64.backward(R)
    assert max(rel_err(grads[k], g64[k]) for k in g64 if not k.endswith(".bk")) < 1e-4
    att = SelfAttention(8, 2, dtype=np.float32)
    assert att.forward(rng.standard_normal((3, 4, 8))).dtype == np.float32
    assert LayerNorm(8, dtype=np.float32).forward(np.ones((2, 8))).dtype == np.float32


# ------------------------------------------------------------------ drop-in for SetNet

def test_params_are_the_modules_arrays_and_adam_trains_in_place():
    from agent import Adam, value_loss
    rng = np.random.default_rng(11)
    net = AttentionNet(7, 16, 1, seed=0)
    assert sum(p.size for p in net.params.values()) == sum(
        p.size for m in net.modules.values() for p in m.params.values())
    assert net.params["block1.attn.Wv"] is net.modules["block1.attn"].params["Wv"]
    f = rng.standard_normal((32, 4, 7))
    target = np.tanh(f[..., 0].sum(-1))           # a set function of the blocks
    opt, losses = Adam(net.params, lr=3e-3), []
    for _ in range(60):
        loss, dout, _ = value_loss(net.forward(f), target)
        opt.step(net.backward(dout))
        losses.append(loss)
    assert losses[-1] < 0.2 * losses[0]


def test_agent_with_attention_trains_saves_and_loads(tmp_path):
    """Agent(network="attention") trains with the project's own BC loop, and its checkpoint
    says which network it holds."""
    from agent import Agent
    agent = Agent(n_blocks=3, n_x=7, hidden=16, seed=0, network="attention", dtype="float32")
    assert isinstance(agent.actor, AttentionNet) and isinstance(agent.critic, AttentionNet)
    rng = np.random.default_rng(12)
    obs = np.zeros((64, 3, 6))
    obs[..., 0] = rng.uniform(-0.45, 0.45, (64, 3))
    obs[..., 1] = 0.025
    actions = np.stack([np.zeros(64, int), rng.integers(0, 7, 64), np.zeros(64, int)], -1)
    losses = agent.bc(obs, actions, epochs=8, batch_size=16, lr=3e-3, rng=rng)
    assert np.isfinite(losses).all() and losses[-1] < losses[0]
    agent.save(tmp_path / "a.npz")
    back = Agent.load(tmp_path / "a.npz")
    assert back.network == "attention"
    assert np.array_equal(back.act(obs, deterministic=True), agent.act(obs, deterministic=True))
    with pytest.raises(ValueError, match="network 'mlp'"):
        Agent(network="mlp")
