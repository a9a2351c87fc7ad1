"""Tests of agent.py: every backward pass against central finite differences, GAE against a
plain reference, numerical stability, sampling, the Agent API, persistence, and learning."""
import numpy as np
import pytest

from agent import (
    ActionDist,
    Agent,
    OtherWorldWarning,
    aux_loss,
    bc_loss,
    entropy_of,
    gae,
    log_softmax,
    pair_value_loss,
    ppo_loss,
    value_loss,
)
from course.grader import numerical_grad  # central differences, step 1e-6
from taskexp_lib.features import (
    AUX_FACTS,
    RELATIONS,
    feature_columns,
    featurize,
    relation_targets,
    relations,
)
from taskexp_lib.geometry import GEOMETRY
from taskexp_lib.nets import SetNet
from taskexp_lib.nn import MLP, Adam, clip_grad_norm

TOL = 1e-5
# The deep set over the hand relations in float64, for the world that places blocks in layers:
# the agent these tests were written for (Agent()'s defaults are the run's: attention, plain).
DEEP_SET = dict(network="setnet", features="relations", dtype="float64")


def rel_err(a, b):
    return np.linalg.norm(a - b) / max(np.linalg.norm(a) + np.linalg.norm(b), 1e-12)


def random_obs(rng, B, n=6, goals=1):
    """B observations: blocks on the table at random x, `goals` random blocks with goals."""
    obs = np.zeros((B, n, 6))
    obs[..., 0] = rng.uniform(-0.45, 0.45, (B, n))
    obs[..., 1] = 0.025 + 0.05 * rng.integers(0, 2, (B, n))
    for k in range(B):
        for b in rng.choice(n, goals, replace=False):
            obs[k, b, 3:] = rng.uniform(-0.45, 0.45), 0.025 + 0.05 * rng.integers(n), 1.0
    return obs


# ----------------------------------------------------------------------------- gradients

def test_mlp_backward_matches_finite_differences():
    rng = np.random.default_rng(0)
    net = MLP([5, 7, 6, 3], seed=1, out_scale=0.5)
    x, R = rng.standard_normal((4, 5)), rng.standard_normal((4, 3))
    loss = lambda: np.sum(net.forward(x) * R)
    net.forward(x)
    grads = net.backward(R)
    for k, p in net.params.items():
        assert rel_err(grads[k], numerical_grad(loss, p)) < TOL, k
    assert rel_err(net.dx, numerical_grad(loss, x)) < TOL


def test_mlp_init_scales():
    net = MLP([400, 300, 50], seed=0, out_scale=0.01)
    assert abs(net.params["W0"].std() - 1 / np.sqrt(400)) < 0.01 / np.sqrt(400) * 5
    assert abs(net.params["W1"].std() - 0.01 / np.sqrt(300)) < 0.0005 / np.sqrt(300) * 5
    assert not net.params["b0"].any() and not net.params["b1"].any()


def test_setnet_backward_matches_finite_differences_including_max_pool():
    rng = np.random.default_rng(1)
    net = SetNet(7, 6, 5, seed=2)
    f, R = rng.standard_normal((3, 4, 7)), rng.standard_normal((3, 4, 5))
    loss = lambda: np.sum(net.forward(f) * R)
    net.forward(f)
    assert len(np.unique(net.argmax)) > 1                     # max routes to several blocks
    grads = net.backward(R)
    assert set(grads) == set(net.params)
    for k, p in net.params.items():
        assert rel_err(grads[k], numerical_grad(loss, p)) < TOL, k


def action_setup(seed=3, B=6, n=4, n_x=7, n_y=3, scale=2.0):
    rng = np.random.default_rng(seed)
    out = scale * rng.standard_normal((B, n, 1 + n_x + n_y))
    actions = np.stack([rng.integers(n, size=B), rng.integers(n_x, size=B),
                        rng.integers(n_y, size=B)], 1)
    return rng, out, actions, n_x


def test_logprob_entropy_backward_matches_finite_differences():
    rng, out, actions, n_x = action_setup()
    a, c = rng.standard_normal(len(out)), rng.standard_normal(len(out))
    f = lambda: np.sum(a * ActionDist(out, n_x).log_prob(actions)
                       + c * ActionDist(out, n_x).entropy())
    dout = ActionDist(out, n_x).backward(actions, a, c)
    assert rel_err(dout, numerical_grad(f, out)) < TOL


def test_entropy_is_exact_sum_over_joint_actions():
    _, out, _, n_x = action_setup(B=2, n=3, n_x=4, n_y=2)
    dist = ActionDist(out, n_x)
    joint = np.array(np.meshgrid(range(3), range(4), range(2), indexing="ij")).reshape(3, -1).T
    for k in range(2):
        lp = ActionDist(np.repeat(out[k:k + 1], len(joint), 0), n_x).log_prob(joint)
        assert abs(np.exp(lp).sum() - 1) < 1e-12
        assert abs(-(np.exp(lp) * lp).sum() - dist.entropy()[k]) < 1e-12


def test_bc_loss_backward():
    _, out, actions, n_x = action_setup(seed=4)
    L, dout = bc_loss(out, actions, n_x)
    assert rel_err(dout, numerical_grad(lambda: bc_loss(out, actions, n_x)[0], out)) < TOL


def test_ppo_loss_backward_with_clipped_and_unclipped_ratios():
    rng, out, actions, n_x = action_setup(seed=5, B=16)
    logp = ActionDist(out, n_x).log_prob(actions)
    logp_old = logp + rng.uniform(-0.5, 0.5, len(out))
    adv = rng.standard_normal(len(out))
    _, dout = ppo_loss(out, actions, logp_old, adv, n_x, clip=0.2, ent_coef=0.03)
    r = np.exp(logp - logp_old)
    clipped = np.where(adv > 0, r > 1.2, r < 0.8)             # these get no surrogate gradient
    assert clipped.any() and (~clipped).any() and (np.abs(r - 1) > 0.2).sum() > clipped.sum()
    f = lambda: ppo_loss(out, actions, logp_old, adv, n_x, clip=0.2, ent_coef=0.03)[0]
    assert rel_err(dout, numerical_grad(f, out)) < TOL


def test_value_loss_backward():
    rng = np.random.default_rng(6)
    out, R = rng.standard_normal((5, 4, 1)), rng.standard_normal(5)
    L, dout, V = value_loss(out, R)
    assert np.allclose(V, out[..., 0].mean(1)) and np.isclose(L, 0.5 * np.mean((V - R) ** 2))
    assert rel_err(dout, numerical_grad(lambda: value_loss(out, R)[0], out)) < TOL


def test_pair_value_loss_backward():
    rng = np.random.default_rng(6)
    out, R = rng.standard_normal((6, 4, 1)), rng.random((3, 2))
    L, dout, V = pair_value_loss(out, R, 0.7)
    e = V.reshape(2, 3).T - R                                  # errors of the states a, b
    want = 0.5 * np.mean(e ** 2) * 2 + 0.7 * 0.5 * np.mean((e[:, 0] - e[:, 1]) ** 2)
    assert np.isclose(L, want)
    assert rel_err(dout, numerical_grad(lambda: pair_value_loss(out, R, 0.7)[0], out)) < TOL


def test_fit_value_pairs_fits_the_difference():
    rng = np.random.default_rng(15)
    agent = Agent(hidden=16, seed=0, n_y=6, **DEEP_SET)
    obs = random_obs(rng, 64).reshape(32, 2, 6, 6)
    target = obs[..., 5].sum(-1) * 0.3 + obs[..., 0, 0]          # (32, 2)
    losses = agent.fit_value_pairs(obs, target, 1.0, epochs=30, batch_size=8, lr=3e-3, rng=rng)
    assert losses[-1] < losses[0] / 10


def test_agent_bc_gradient_through_features_and_setnet():
    rng = np.random.default_rng(7)
    agent = Agent(n_blocks=4, n_x=9, n_y=4, hidden=8, seed=1, **DEEP_SET)
    obs, acts = random_obs(rng, 5, n=4), np.stack([rng.integers(4, size=5), rng.integers(9, size=5),
                                                   rng.integers(4, size=5)], 1)
    f = agent.features(obs)
    loss = lambda: bc_loss(agent.actor.forward(f), acts, 9)[0]
    grads = agent.actor.backward(bc_loss(agent.actor.forward(f), acts, 9)[1])
    for k in ("phi.W0", "rho.W1", "rho.b0"):
        assert rel_err(grads[k], numerical_grad(loss, agent.actor.params[k])) < TOL, k


def test_aux_loss_backward_and_its_minimum():
    rng = np.random.default_rng(16)
    out, facts = 3 * rng.standard_normal((5, 4, 8)), rng.integers(0, 2, (5, 4, 8))
    L, dout = aux_loss(out, facts)
    assert rel_err(dout, numerical_grad(lambda: aux_loss(out, facts)[0], out)) < TOL
    assert np.isclose(L, np.mean(-facts * np.log(1 / (1 + np.exp(-out)))
                                 - (1 - facts) * np.log(1 - 1 / (1 + np.exp(-out)))))
    sure = np.where(facts > 0, 40.0, -40.0)        # logits that say every fact, far past sure
    assert aux_loss(sure, facts)[0] < 1e-15 and np.isfinite(aux_loss(1e4 * out, facts)[0])


def test_the_auxiliary_facts_train_the_head_and_not_the_policy(tmp_path):
    """With aux > 0 the actor's head has one output per fact after the policy's, which BC trains
    (gradient through the whole network, against finite differences), which the policy never
    reads, and which a checkpoint keeps."""
    rng = np.random.default_rng(17)
    agent = Agent(n_blocks=4, n_x=9, n_y=1, hidden=8, seed=1, dtype="float64", aux=0.7)
    assert agent.actor.forward(agent.features(random_obs(rng, 1, n=4))).shape[-1] == 11 + 8
    obs = random_obs(rng, 5, n=4, goals=2)
    acts = np.stack([rng.integers(4, size=5), rng.integers(9, size=5), np.zeros(5, int)], 1)
    f, facts = agent.features(obs), relation_targets(obs)
    loss_fn = agent._with_aux(lambda out, a: bc_loss(out, a, 9))
    loss = lambda: loss_fn(agent.actor.forward(f), (acts, facts))[0]
    L, dout = loss_fn(agent.actor.forward(f), (acts, facts))
    assert np.isclose(L, bc_loss(agent.actor.forward(f)[..., :11], acts, 9)[0]
                      + 0.7 * aux_loss(agent.actor.forward(f)[..., 11:], facts)[0])
    grads = agent.actor.backward(dout)
    for k in ("embed.W0", "block1.attn.Wq", "head.W1", "head.b1"):
        assert rel_err(grads[k], numerical_grad(loss, agent.actor.params[k])) < TOL, k
    # the fact columns change nothing the policy does
    before = agent.policy(f).log_prob(acts)
    agent.actor.params["head.b1"][11:] += 5.0
    assert np.array_equal(agent.policy(f).log_prob(acts), before)
    # BC learns the facts: the auxiliary loss falls well below its start
    obs = random_obs(rng, 256, n=4, goals=2)
    acts = agent.act(obs, rng=rng)
    start = aux_loss(agent.actor.forward(agent.features(obs))[..., 11:], relation_targets(obs))[0]
    agent.bc(obs, acts, 20, 32, 3e-3, rng)
    end = aux_loss(agent.actor.forward(agent.features(obs))[..., 11:], relation_targets(obs))[0]
    assert end < start / 3
    # and so does PPO, with no advantage to follow
    fresh = Agent(n_blocks=4, n_x=9, n_y=1, hidden=8, seed=2, dtype="float64", aux=0.7)
    fresh.ppo_update(obs, acts, fresh.policy(fresh.features(obs)).log_prob(acts), np.zeros(256),
                     np.zeros(256), epochs=20, minibatch=32, clip=0.2, ent_coef=0.0, vf_coef=0.5,
                     lr=3e-3, max_grad_norm=0.5, rng=rng)
    assert aux_loss(fresh.actor.forward(fresh.features(obs))[..., 11:],
                    relation_targets(obs))[0] < start / 3
    agent.save(tmp_path / "aux.npz")
    again = Agent.load(tmp_path / "aux.npz")
    assert again.aux == 0.7 and np.array_equal(again.actor.forward(f), agent.actor.forward(f))
    Agent(n_blocks=4, n_x=9, n_y=1, hidden=8).save(tmp_path / "none.npz")
    assert "aux" not in np.load(tmp_path / "none.npz")        # the default's files as before
    np.savez(tmp_path / "bad.npz", **{**np.load(tmp_path / "aux.npz"), "aux": np.array(-1.0)})
    with pytest.raises(ValueError, match="bad.npz: aux -1.0"):
        Agent.load(tmp_path / "bad.npz")
    with pytest.raises(ValueError, match="aux -1"):
        Agent(aux=-1)


def test_relation_targets_are_the_relations_in_chunks():
    rng = np.random.default_rng(18)
    obs = random_obs(rng, 7, goals=3)
    x, y, gx, gy, g = (obs[..., j] for j in (0, 1, 3, 4, 5))
    facts = relations(x, y, gx, gy, g, g * (np.hypot(gx - x, gy - y) < GEOMETRY["threshold"]))
    want = np.stack([facts[name] for name in AUX_FACTS], -1)
    assert np.array_equal(relation_targets(obs), want)
    assert np.array_equal(relation_targets(obs, chunk=3), want)
    assert want.any() and not want.all()


# ----------------------------------------------------------------------------- GAE

def gae_reference(r, v, term, trunc, nv, gamma, lam):
    """A_t = sum_l (gamma lam)^l delta_{t+l}, summed up to and including the episode's last step."""
    T, N = r.shape
    adv = np.zeros((T, N))
    for n in range(N):
        for t in range(T):
            total, discount = 0.0, 1.0
            for u in range(t, T):
                delta = r[u, n] + gamma * nv[u, n] * (1 - term[u, n]) - v[u, n]
                total += discount * delta
                if term[u, n] or trunc[u, n]:
                    break
                discount *= gamma * lam
            adv[t, n] = total
    return adv


def test_gae_matches_reference_with_terminations_and_truncations():
    rng = np.random.default_rng(8)
    T, N = 15, 3
    r, v, nv = rng.random((T, N)), rng.standard_normal((T, N)), rng.standard_normal((T, N))
    term, trunc = np.zeros((T, N)), np.zeros((T, N))
    term[[3, 9], [0, 1]] = 1
    trunc[[5, 11, 6], [0, 2, 1]] = 1
    adv, ret = gae(r, v, term, trunc, nv, 0.97, 0.9)
    assert np.allclose(adv, gae_reference(r, v, term, trunc, nv, 0.97, 0.9), atol=1e-12)
    assert np.allclose(ret, adv + v)
    # termination ignores next_values; truncation bootstraps from them
    assert np.isclose(adv[3, 0], r[3, 0] - v[3, 0])
    assert np.isclose(adv[5, 0], r[5, 0] + 0.97 * nv[5, 0] - v[5, 0])
    with pytest.raises(ValueError):
        gae(r, v, term, trunc, nv[:-1], 0.97, 0.9)


# ----------------------------------------------------------------------------- stability, sampling

def test_log_softmax_and_entropy_stable_for_extreme_logits():
    z = np.array([[1e4, -1e4, 0.0, 3.0], [-1e4, -1e4, -1e4, -1e4], [1e4, 1e4, -1e4, 0.0]])
    lp = log_softmax(z)
    H = entropy_of(lp)
    assert np.isfinite(lp).all() and np.isfinite(H).all() and (H >= 0).all() and (lp <= 0).all()
    assert np.allclose(H, [0.0, np.log(4), np.log(2)])
    dist = ActionDist(np.array([[[1e4, -1e4, 1e4, 0], [-1e4, 1e4, -1e4, 1e4]]]), 2)
    assert (np.isfinite(dist.entropy()).all()
            and np.isfinite(dist.backward([[0, 1, 0]], 1.0, 1.0)).all())
    m = np.random.default_rng(9).standard_normal((5, 8)) * 3   # moderate: naive formula is fine
    p = np.exp(m) / np.exp(m).sum(-1, keepdims=True)
    assert (np.allclose(log_softmax(m), np.log(p))
            and np.allclose(entropy_of(log_softmax(m)), -(p * np.log(p)).sum(-1)))


def test_sampling_frequencies_match_probabilities_and_mode_is_joint_argmax():
    rng, out, _, n_x = action_setup(seed=10, B=1, n=3, n_x=4, n_y=2, scale=1.0)
    joint = np.array(np.meshgrid(range(3), range(4), range(2), indexing="ij")).reshape(3, -1).T
    p = np.exp(ActionDist(np.repeat(out, len(joint), 0), n_x).log_prob(joint))
    M = 50000
    samples = ActionDist(np.repeat(out, M, 0), n_x).sample(np.random.default_rng(0))
    counts = np.zeros(len(joint))
    np.add.at(counts, (samples[:, 0] * 4 + samples[:, 1]) * 2 + samples[:, 2], 1)
    chi2 = np.sum((counts - M * p) ** 2 / (M * p))
    assert chi2 < 60                                          # df = 23: P(chi2 > 60) < 1e-4
    assert tuple(ActionDist(out, n_x).mode()[0]) == tuple(joint[p.argmax()])


def test_block_mode_takes_the_likeliest_block_whatever_its_x():
    """block_mode: argmax_b pi(b), then argmax_x pi(x | b), checked against the probabilities
    summed by hand; and the case where it and the joint mode part: block 0 is the likeliest
    block but its x is spread over four bins (a block to clear away), block 1's x is sure."""
    rng, out, _, n_x = action_setup(seed=12, B=64, n=3, n_x=4, n_y=2, scale=2.0)
    joint = np.array(np.meshgrid(range(3), range(4), range(2), indexing="ij")).reshape(3, -1).T
    dist = ActionDist(out, n_x)
    for k in range(len(out)):
        p = np.exp(ActionDist(np.repeat(out[k:k + 1], len(joint), 0), n_x).log_prob(joint))
        p = p.reshape(3, 4, 2)
        b = p.sum((1, 2)).argmax()                                 # the block's marginal
        x, y = np.unravel_index(p[b].argmax(), (4, 2))
        assert tuple(dist.block_mode()[k]) == (b, x, y)
    assert (dist.block_mode() != dist.mode()).any(1).sum() > 5       # the two rules part often
    out = np.zeros((1, 2, 1 + 4 + 1))
    out[0, :, 0] = [1.0, 0.0]                                      # pi(b): 0.73, 0.27
    out[0, 1, 1 + 2] = 5.0                                         # block 1: x = 2, p 0.98
    assert tuple(ActionDist(out, 4).block_mode()[0]) == (0, 0, 0)
    assert tuple(ActionDist(out, 4).mode()[0]) == (1, 2, 0)        # 0.27 * 0.98 > 0.73 / 4


# ----------------------------------------------------------------------------- features, API

def test_featurize_codes():
    obs = np.zeros((1, 3, 6))
    obs[0, :, :2] = [[0.0, 0.025], [0.2, 0.075], [-0.3, 0.025]]
    obs[0, 0, 3:] = [0.005, 0.025, 1.0]                         # satisfied (0.5 cm away)
    obs[0, 1, 3:] = [-0.2, 0.125, 1.0]                          # not satisfied
    f, col = featurize(obs, 3, "relations")[0], feature_columns(3, "relations")
    assert f.shape == (3, 16 + 3 * 21) and max(c.stop for c in col.values()) == f.shape[-1]
    assert list(f[:, col["at_goal"]][:, 0]) == [1, 0, 0]
    # heights are numbers, the same scale for a layer no demonstration has reached: no layer code
    assert not any("layer" in name for name in col)
    assert np.allclose(f[:, col["y"]][:, 0], [1 / 6, 1 / 2, 1 / 6])
    assert np.allclose(f[:, col["goal_y"]][:, 0], [1 / 6, 5 / 6, 0])                   # no goal: 0
    goal_part = [name for name in col
                 if name.startswith("goal") or name in ("to_goal_x", "to_goal_y")]
    assert not any(f[2, col[name]].any() for name in goal_part + ["has_goal", "at_goal"])
    # every 5 cm
    assert f[1, col["x_rbf"]].argmax() == 14 and f[1, col["goal_x_rbf"]].argmax() == 6


def test_plain_features_are_the_relations_features_without_the_relations(tmp_path):
    """features="plain" drops exactly the hand-computed columns; the checkpoint remembers which
    features its networks were trained on, and a one-block drop head (n_y = 1) round-trips."""
    obs = random_obs(np.random.default_rng(5), 3)
    plain, full = featurize(obs, 6, "plain"), featurize(obs, 6, "relations")
    assert plain.shape[-1] == 10 + 2 * 21
    assert np.array_equal(plain, full[..., : plain.shape[-1]])
    assert set(feature_columns(6, "relations")) - set(feature_columns(6, "plain")) == {*RELATIONS,
                                                                          "support_wanted_rbf"}
    leave = featurize(obs, 6, "relations+leave")                # the relations, then one code more
    assert np.array_equal(full, leave[..., : full.shape[-1]]) and leave.shape[-1] == 16 + 4 * 21
    assert set(feature_columns(6, "relations+leave")) - set(feature_columns(6, "relations")) == {
        "spot_to_leave_rbf"}
    stay = featurize(obs, 6, "relations+leave+stay")             # ... and one column more
    assert np.array_equal(leave, stay[..., : leave.shape[-1]]) and stay.shape[-1] == 17 + 4 * 21
    assert set(feature_columns(6, "relations+leave+stay")) - set(feature_columns(
        6, "relations+leave")) == {"support_in_place"}
    agent = Agent(hidden=8, dtype="float64")                     # the defaults: plain features
    assert agent.features(obs).shape == plain.shape and agent.act(obs).shape == (3, 3)
    assert (agent.act(obs)[:, 2] == 0).all()
    agent.save(tmp_path / "p.npz")
    again = Agent.load(tmp_path / "p.npz")
    assert (again.feature_set, again.network, again.n_y) == ("plain", "attention", 1)
    assert np.array_equal(again.value(obs), agent.value(obs))
    with pytest.raises(ValueError, match="features 'hand'"):
        featurize(obs, 6, "hand")
    with pytest.raises(ValueError, match="features 'hand'"):
        Agent(hidden=8, features="hand")


def test_a_block_in_the_way_codes_the_spot_it_must_leave():
    """relations+leave's spot_to_leave_rbf: the RBF code of where a block in the way stands, zero
    for the others; support_wanted_rbf: that of a goal that waits for a support."""
    obs = np.zeros((1, 3, 6))
    obs[0, :, :2] = [[-0.3, 0.025], [0.3, 0.025], [0.2, 0.025]]
    obs[0, 0, 3:] = [0.2, 0.025, 1.0]                           # block 2 stands on 0's goal spot
    obs[0, 1, 3:] = [-0.2, 0.075, 1.0]                          # 1's goal hangs in the air
    f, col = featurize(obs, 3, "relations+leave")[0], feature_columns(3, "relations+leave")
    leave, wanted = f[:, col["spot_to_leave_rbf"]], f[:, col["support_wanted_rbf"]]
    assert not leave[:2].any() and np.allclose(leave[2], f[2, col["x_rbf"]])
    assert leave[2].argmax() == 14                                  # x = 0.2, every 5 cm
    assert not wanted[[0, 2]].any() and wanted[1].argmax() == 6     # under 1's goal, x = -0.2
    obs[0, 2, 0] = 0.4                                              # 2 steps aside: none to leave
    assert not featurize(obs, 3, "relations+leave")[0, :, col["spot_to_leave_rbf"]].any()


def test_a_support_in_place_is_told_to_stay():
    """relations+leave+stay's support_in_place: a block right under a goal not met yet, on a
    lower layer; not one aside, not under a goal met already, not one in the way of a goal."""
    obs = np.zeros((1, 3, 6))
    obs[0, :, :2] = [[-0.3, 0.025], [0.01, 0.025], [0.3, 0.025]]
    obs[0, 0, 3:] = [0.0, 0.175, 1.0]                           # "3 up": 0's goal three storeys up
    f, col = featurize(obs, 6, "relations+leave+stay")[0], feature_columns(6,
                                                                           "relations+leave+stay")
    assert list(f[:, col["support_in_place"]]) == [0, 1, 0]    # 1 stands under it; 2 aside
    obs[0, 0, :2] = [0.0, 0.175]                                # the goal met: nothing to keep
    assert not featurize(obs, 6, "relations+leave+stay")[0, :, col["support_in_place"]].any()
    # a tower's ground goal (block 0) and the one above it (block 1): block 2 stands on the
    # ground goal's spot, under the other; it must leave, so it is no support
    x, y = [-0.3, 0.3, 0.0], [0.025, 0.025, 0.025]
    r = relation_table(x, y, [0.0, 0.0, 0.0], [0.025, 0.075, 0.0], [1.0, 1.0, 0.0])
    assert r["in_the_way"] == [0, 0, 1] and not any(r["support_in_place"])
    x[2] = 0.15                                 # aside: 0 is not blocked, and none is under 1
    r = relation_table(x, y, [0.0, 0.0, 0.0], [0.025, 0.075, 0.0], [1.0, 1.0, 0.0])
    assert not any(r["support_in_place"])


def relation_table(x, y, gx, gy, g):
    """relations() for one scene of 3 blocks, as {name: list of 3 floats}."""
    rel = relations(*(np.array([v], float) for v in (x, y, gx, gy, g)), np.zeros((1, 3)))
    return {name: list(v[0]) for name, v in rel.items()}


def test_relations():
    """Block 1's goal sits on block 0's goal; block 2 is in the way of block 0's goal."""
    x, y = [-0.3, 0.3, 0.01], [0.025, 0.025, 0.025]
    gx, gy, g = [0.0, 0.0, 0.0], [0.025, 0.075, 0.0], [1.0, 1.0, 0.0]
    r = relation_table(x, y, gx, gy, g)
    assert r["blocked"] == [1, 0, 0] and r["supported"] == [1, 1, 0]   # 2 is under 1's goal spot
    assert r["wait"] == [0, 1, 0] and r["first"] == [1, 0, 0] and not any(r["covered"])
    assert not any(r["needs_support"])
    assert r["in_the_way"] == [0, 0, 1]                         # 2 stands on 0's goal spot
    x[2] = 0.4                                      # block 2 moves away: 1's goal hangs in the air
    r = relation_table(x, y, gx, gy, g)
    assert r["blocked"] == [0, 0, 0] and r["supported"] == [1, 0, 0]
    assert r["needs_support"] == [0, 1, 0] and not any(r["in_the_way"])
    x[2] = 0.01
    y[1], x[1] = 0.075, 0.02                        # block 1 now rests on block 2
    r = relation_table(x, y, gx, gy, g)
    # 2 covered; 1's goal supported by 2
    assert r["covered"] == [0, 0, 1] and r["supported"][1] == 1
    assert set(r) == set(RELATIONS) | {"held", "needs_support", "support_in_place"}


def test_a_goal_on_two_legs_is_held_up():
    """The stem of "Y": its goal over blocks 0.75 block widths to either side is held up once
    both stand, though no block lies under its centre; one leg alone does not hold it."""
    w = 0.1
    x, y = [-0.75 * w, 0.75 * w, 0.3], [0.025, 0.025, 0.025]
    gx, gy, g = [-0.75 * w, 0.75 * w, 0.0], [0.025, 0.025, 0.075], [1.0, 1.0, 1.0]
    r = relation_table(x, y, gx, gy, g)
    assert r["supported"][2] == 0 and r["held"][2] == 1 and r["needs_support"][2] == 0
    x[1] = -0.3                                               # the right leg elsewhere
    r = relation_table(x, y, gx, gy, g)
    assert r["held"][2] == 0 and r["needs_support"][2] == 1


def test_act_value_sample_shapes_and_errors():
    rng = np.random.default_rng(11)
    agent = Agent(hidden=16, seed=0, n_y=6, **DEEP_SET)
    obs = random_obs(rng, 5)
    a1 = agent.act(obs[0], rng=rng)
    assert a1.shape == (3,) and a1.dtype == np.int64 and (0 <= a1).all() and (a1 < [6, 37, 6]).all()
    ab = agent.act(obs, deterministic=True)
    assert ab.shape == (5, 3) and np.array_equal(agent.act(obs[2], deterministic=True), ab[2])
    assert isinstance(agent.value(obs[0]), float) and agent.value(obs).shape == (5,)
    actions, logp, values = agent.sample(obs.astype(np.float32), rng)
    assert actions.shape == (5, 3) and logp.shape == (5,) and np.allclose(values, agent.value(obs))
    assert np.all(logp < 0)
    twin = Agent(hidden=16, seed=0, n_y=6, **DEEP_SET)           # no rng: the agent's own, seeded
    assert np.array_equal([agent.act(o) for o in obs], [twin.act(o) for o in obs])
    assert agent.act(np.zeros((6, 6), np.float32)).shape == (3,)
    with pytest.raises(ValueError):
        agent.act(np.zeros((9, 6)), deterministic=True)         # more blocks than a world holds
    with pytest.warns(OtherWorldWarning):                       # another world: it says so
        assert agent.act(np.zeros((4, 6)), deterministic=True)[2] < 4      # a layer it has
    with pytest.raises(ValueError):
        agent.bc(obs, np.array([[0, 37, 0]] * 5), 1, 4, 1e-3, rng)   # x-bin out of range
    # the greedy rule (Config.greedy): the joint mode by default, block_mode when asked
    f = agent.features(obs)
    assert np.array_equal(ab, agent.policy(f).mode())
    agent.greedy = "block"
    assert np.array_equal(agent.act(obs, deterministic=True), agent.policy(f).block_mode())
    with pytest.raises(ValueError, match="greedy 'first'"):
        Agent(hidden=16, greedy="first")


def test_adam_and_clip_grad_norm():
    p = {"w": np.ones(3)}
    opt = Adam(p, lr=0.1)
    opt.step({"w": np.array([5.0, -0.01, 1e3])})
    assert np.allclose(p["w"], [0.9, 1.1, 0.9])   # bias-corrected first step = lr sign(g)
    g, norm = clip_grad_norm({"a": np.array([3.0]), "b": np.array([4.0])}, 1.0)
    assert norm == 5.0 and np.isclose(np.sqrt(g["a"] ** 2 + g["b"] ** 2), 1.0)
    g2, _ = clip_grad_norm({"a": np.array([0.3])}, 1.0)
    assert g2["a"][0] == 0.3


# ----------------------------------------------------------------------------- persistence

def test_save_load_round_trip_and_byte_identical(tmp_path):
    rng = np.random.default_rng(12)
    obs = random_obs(rng, 4)
    a, b = (Agent(hidden=16, seed=3, n_y=6, **DEEP_SET) for _ in range(2))
    a.bc(obs, a.act(obs, deterministic=True), 2, 2, 1e-3, np.random.default_rng(0))
    b.bc(obs, b.act(obs, deterministic=True), 2, 2, 1e-3, np.random.default_rng(0))
    a.save(tmp_path / "a.npz")
    b.save(tmp_path / "b.npz")
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
    c = Agent.load(tmp_path / "a.npz")
    f = a.features(obs)
    assert np.array_equal(a.actor.forward(f), c.actor.forward(f))
    assert np.array_equal(a.value(obs), c.value(obs))
    assert (c.n_blocks, c.n_x, c.n_y, c.hidden) == (6, 37, 6, 16)
    Agent(hidden=16, seed=4, n_y=6, **DEEP_SET).save(tmp_path / "d.npz")
    assert (tmp_path / "a.npz").read_bytes() != (tmp_path / "d.npz").read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.npz", "b.npz", "d.npz"]   # no tmp left


def test_load_rejects_bad_files(tmp_path):
    good = tmp_path / "good.npz"
    Agent(hidden=8, n_y=6, **DEEP_SET).save(good)
    data = dict(np.load(good))
    cases = {"truncated.npz": good.read_bytes()[: len(good.read_bytes()) // 2],
             "garbage.npz": b"not a zip", "notes.txt": b"a text file\n"}
    for name, content in cases.items():
        (tmp_path / name).write_bytes(content)
    np.savez(tmp_path / "version.npz", **{**data, "format_version": np.array(99)})
    np.savez(tmp_path / "sizes.npz", **{**data, "sizes": np.array([6, 37, 6, 16])})
    np.savez(tmp_path / "shape.npz", **{**data, "actor.rho.W1": np.zeros((8, 5))})
    np.savez(tmp_path / "missing.npz", **{k: v for k, v in data.items() if k != "critic.phi.b0"})
    np.savez(tmp_path / "world.npz",
             **{**data, "geometry": data["geometry"] * [1, 2, 1, 1, 1, 1, 1]})
    np.savez(tmp_path / "state.npz", **{**data, "state_version": np.array(1)})
    np.savez(tmp_path / "features.npz", **{**data, "features": np.array("hand")})
    first = {k: v[:-1] for k, v in data.items() if k.endswith("phi.W0")}   # one feature fewer
    np.savez(tmp_path / "columns.npz", **{**data, **first})
    for name, msg in [("truncated.npz", "readable"), ("garbage.npz", "readable"),
                      ("notes.txt", "not a checkpoint"), ("version.npz", "99"),
                      ("sizes.npz", "sizes"), ("shape.npz", "actor.rho.W1"),
                      ("missing.npz", "critic.phi.b0"), ("world.npz", r"'block_h': \(0.1, 0.05\)"),
                      ("state.npz", r"round\{k\}.npz"), ("features.npz", "features 'hand'"),
                      ("columns.npz", "read 78 feature columns, the 'relations' features have 79")]:
        with pytest.raises(ValueError, match=msg) as e:
            Agent.load(tmp_path / name)
        assert name in str(e.value) and "allow_pickle" not in str(e.value)


def test_checkpoint_records_the_world_geometry(tmp_path):
    Agent(hidden=8, n_y=6, **DEEP_SET).save(tmp_path / "a.npz")
    saved = np.load(tmp_path / "a.npz")["geometry"]
    assert dict(zip(GEOMETRY, saved.tolist())) == GEOMETRY


# ----------------------------------------------------------------------------- learning

def copy_goal_task(rng, N, agent):
    """Move the single goal block to its goal's (x-bin, layer): the action is read off the goal."""
    obs = random_obs(rng, N)
    b = obs[..., 5].argmax(1)
    goal = obs[np.arange(N), b]
    x_bins = np.linspace(-0.45, 0.45, agent.n_x)
    acts = np.stack([b, np.abs(goal[:, 3:4] - x_bins).argmin(1),
                     np.round(goal[:, 4] / 0.05 - 0.5)], 1)
    return obs, acts.astype(np.int64)


def test_bc_learns_to_copy_the_goal():
    rng = np.random.default_rng(13)
    agent = Agent(hidden=64, seed=0, n_y=6, **DEEP_SET)
    obs, acts = copy_goal_task(rng, 1024, agent)
    losses = agent.bc(obs, acts, epochs=30, batch_size=64, lr=3e-3, rng=rng)   # 480 steps
    assert losses[0] > 5 and losses[-1] < losses[0] / 10, losses
    test_obs, test_acts = copy_goal_task(rng, 200, agent)
    assert np.mean(np.all(agent.act(test_obs, deterministic=True) == test_acts, 1)) > 0.7


def test_float32_agent_learns_like_float64_and_round_trips(tmp_path):
    """Training runs in float32 (twice as fast): the same weights at the start (rounded), the same
    learning, and a checkpoint that keeps its dtype; a file whose arrays disagree with its header
    is refused."""
    rng = np.random.default_rng(13)
    a64 = Agent(hidden=64, seed=0, n_y=6, **DEEP_SET)
    a32 = Agent(hidden=64, seed=0, n_y=6, **{**DEEP_SET, "dtype": "float32"})
    assert all(p.dtype == np.float32 for p in a32.state_dict().values())
    assert all(np.allclose(a32.state_dict()[k], v, atol=1e-6) for k, v in a64.state_dict().items())
    obs, acts = copy_goal_task(rng, 1024, a32)
    test_obs, test_acts = copy_goal_task(rng, 200, a32)
    for ag in (a64, a32):
        ag.bc(obs, acts, epochs=30, batch_size=64, lr=3e-3, rng=np.random.default_rng(0))
    hits = [np.mean(np.all(ag.act(test_obs, deterministic=True) == test_acts, 1))
            for ag in (a64, a32)]
    assert hits[1] > 0.7 and abs(hits[0] - hits[1]) < 0.1, hits
    a32.save(tmp_path / "a.npz")
    back = Agent.load(tmp_path / "a.npz")
    assert back.dtype == np.float32 and np.array_equal(back.act(test_obs, deterministic=True),
                                                       a32.act(test_obs, deterministic=True))
    data = dict(np.load(tmp_path / "a.npz"))
    np.savez(tmp_path / "b.npz", **{**data, "dtype": np.array("float64")})
    with pytest.raises(ValueError, match="expected finite float64"):
        Agent.load(tmp_path / "b.npz")


def test_ppo_update_raises_advantaged_action_and_fit_value():
    rng = np.random.default_rng(14)
    agent = Agent(hidden=16, seed=0, n_y=6, **DEEP_SET)
    obs = random_obs(rng, 64)
    actions, logp, values = agent.sample(obs, rng)
    adv = np.where(actions[:, 0] == 0, 1.0, -0.2)               # block 0 is good
    m = agent.ppo_update(obs, actions, logp, adv, values + adv, epochs=4, minibatch=16, clip=0.2,
                         ent_coef=0.01, vf_coef=0.5, lr=1e-3, max_grad_norm=0.5, rng=rng)
    change = ActionDist(agent.actor.forward(agent.features(obs)), 37).log_prob(actions) - logp
    assert ((change[adv > 0] > 0).all() and change[adv > 0].mean() > 0.03
            and change[adv < 0].mean() < 0)
    assert set(m) == {"policy_loss", "value_loss", "entropy", "approx_kl", "clip_frac",
                      "explained_variance"}
    assert (all(np.isfinite(v) for v in m.values()) and m["approx_kl"] >= 0
            and 0 <= m["clip_frac"] <= 1)
    target = obs[..., 5].sum(1) * 0.5 + obs[:, 0, 0]
    losses = agent.fit_value(obs, target, epochs=30, batch_size=16, lr=3e-3, rng=rng)
    assert losses[-1] < losses[0] / 10
