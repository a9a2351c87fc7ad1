"""Tests of taskexp_lib/shards.py: a minibatch cut into parts gives the gradient of the whole
minibatch, the parts' replicas share the parameters, and two threads give the same bytes as one."""
import inspect
import re
import threading

import numpy as np
import pytest
from test_agent import random_obs

import taskexp
from agent import Agent, bc_loss, ppo_loss
from env2d import BlockWorld, physics_pool, run_worlds
from taskexp_lib.rollout import run_episodes
from taskexp_lib.shards import (
    SHARDS,
    DataParallel,
    Shards,
    read_only_map,
    replica,
    split,
    weighted_sum,
)


def test_split_and_weighted_sum():
    assert [p.tolist() for p in split(np.arange(5))] == [[0, 1, 2], [3, 4]]
    assert [p.tolist() for p in split(np.arange(1))] == [[0]]            # no empty part
    assert weighted_sum([1.0, 3.0], [0.25, 0.75]) == 2.5
    total = weighted_sum([{"a": np.ones(2)}, {"a": 3 * np.ones(2)}], [0.5, 0.5])
    assert total["a"].tolist() == [2.0, 2.0]


@pytest.mark.parametrize("network", ["attention", "setnet"])
def test_parts_weighted_by_their_share_give_the_whole_minibatch_gradient(network):
    """dL/dtheta = sum_k (B_k / B) dL_k/dtheta for a mean loss, checked on the BC loss with a
    part of 3 and one of 2 samples."""
    agent = Agent(hidden=16, seed=0, dtype="float64", network=network)
    rng = np.random.default_rng(0)
    obs, actions = random_obs(rng, 5), np.stack([rng.integers(6, size=5),
                                                  rng.integers(agent.n_x, size=5),
                                                  np.zeros(5, int)], -1)
    net, f = agent.actor, agent.features(obs)
    whole = net.backward(bc_loss(net.forward(f), actions, agent.n_x)[1])
    parts = split(np.arange(5))
    grads = []
    for idx in parts:
        twin = replica(net)
        grads.append(twin.backward(bc_loss(twin.forward(f[idx]), actions[idx], agent.n_x)[1]))
    summed = weighted_sum(grads, [len(p) / 5 for p in parts])
    for key in whole:                           # (bk's gradient is 0 up to rounding: atol)
        assert np.allclose(summed[key], whole[key], rtol=1e-10, atol=1e-15), key


def test_replicas_share_the_parameters_but_not_the_caches():
    agent = Agent(hidden=8, seed=0, dtype="float64")
    net, twin = agent.actor, replica(agent.actor)
    x = agent.features(random_obs(np.random.default_rng(1), 3))
    out = net.forward(x)
    twin.forward(x[:1])                          # its own caches: the original's stay
    assert net.attn[0].shape[0] == 3 and twin.attn[0].shape[0] == 1
    for key, p in net.params.items():
        p += 0.1                                 # an optimiser step in place ...
    assert not np.allclose(twin.forward(x), out)  # ... reaches the replica
    assert all(twin.params[k] is p for k, p in net.params.items())


def test_shards_run_every_part_in_order():
    for threads in (1, 2, 3):
        with Shards(threads) as shards:
            assert shards.map(lambda k, part: (k, part * 10), [1, 2, 3]) == [(0, 10), (1, 20),
                                                                              (2, 30)]


@pytest.mark.parametrize("threads", [1, 2])
def test_data_parallel_runs_a_plain_step_on_each_part(threads):
    """DataParallel calls fn(*replicas, part) once per part, on its own replicas of the networks
    (sharing the parameters), in one thread or in two, and weights the results by B_k / B."""
    agent = Agent(hidden=8, seed=0)
    calls = []

    def fn(actor, critic, idx):
        calls.append((actor, critic, idx.tolist(), threading.get_ident()))
        return float(idx.sum()), {"g": np.full(2, float(len(idx)))}

    with DataParallel([agent.actor, agent.critic], threads) as parallel:
        total, grads = parallel(fn, np.arange(5))
    assert total == 3 / 5 * (0 + 1 + 2) + 2 / 5 * (3 + 4)
    assert grads["g"].tolist() == [3 / 5 * 3 + 2 / 5 * 2] * 2
    calls.sort(key=lambda c: c[2])
    assert [c[2] for c in calls] == [[0, 1, 2], [3, 4]]
    assert len({c[3] for c in calls}) == threads          # both paths: one thread, or two
    for k, net in enumerate([agent.actor, agent.critic]):
        twins = [c[k] for c in calls]
        assert twins[0] is not twins[1] and net not in twins
        assert all(t.params[key] is p for t in twins for key, p in net.params.items())


def train_bits(threads):
    """BC, value fits and a PPO update with `threads` threads -> every parameter's bytes."""
    agent = Agent(hidden=16, seed=0)
    agent.threads = threads
    rng = np.random.default_rng(0)
    N = 300                                      # 256 + 44: a last minibatch of unequal parts
    obs = random_obs(rng, N)
    actions = np.stack([rng.integers(6, size=N), rng.integers(agent.n_x, size=N),
                        np.zeros(N, int)], -1)
    agent.bc(obs, actions, 2, 256, 1e-3, rng)
    agent.fit_value(obs, rng.random(N), 1, 256, 1e-3, rng)
    agent.fit_value_pairs(np.stack([obs, obs[::-1]], 1), rng.random((N, 2)), 1.0, 1, 128, 1e-3,
                          rng)
    _, logp, values = agent.sample(obs, rng)
    adv = rng.standard_normal(N)
    agent.ppo_update(obs, actions, logp, adv, values + adv, epochs=2, minibatch=256, clip=0.2,
                     ent_coef=0.01, vf_coef=0.5, lr=3e-4, max_grad_norm=0.5, rng=rng,
                     ppo_loss=ppo_loss)
    return {k: p.tobytes() for k, p in agent.state_dict().items()}


def test_two_threads_give_the_same_bytes_as_one():
    assert SHARDS == 2
    assert train_bits(1) == train_bits(2)


def test_update_methods_name_no_threads():
    """Agent's updates read as one plain minibatch step: the cores are DataParallel's business
    (Agent.data_parallel), so no update method's source names them."""
    for name in ("bc", "fit_value", "fit_value_pairs", "_fit", "ppo_update"):
        source = inspect.getsource(getattr(Agent, name))
        assert not re.search("thread|replica|shard", source, re.I), name


def test_base_demos_are_the_same_with_the_physics_in_workers():
    cfg = taskexp.Config(n_envs=4)
    results = []
    for workers in (1, 2):
        with physics_pool(workers, drop=True) as pool:
            envs, _ = run_worlds(cfg, pool)
            results.append(taskexp.base_demos(cfg, envs, np.random.default_rng(0), 50))
    (tasks1, obs1, act1), (tasks2, obs2, act2) = results
    assert obs1.tobytes() == obs2.tobytes() and act1.tobytes() == act2.tobytes()
    assert [g for _, g in tasks1] == [g for _, g in tasks2]
    # one world on its own steps its scene move by move, as a single BlockWorld does
    one = taskexp.base_demos(cfg, BlockWorld(cfg.n_blocks, drop=True), np.random.default_rng(0),
                             20)
    again = taskexp.base_demos(cfg, [BlockWorld(cfg.n_blocks, drop=True)],
                               np.random.default_rng(0), 20)
    assert one[1].tobytes() == again[1].tobytes()


def test_read_only_map_gives_the_results_of_one_thread():
    """Equation (1) on both cores: each half of the trajectories on a replica of the agent."""
    agent = Agent(hidden=16, seed=0)
    obs = random_obs(np.random.default_rng(2), 7)
    value = lambda ag, o: ag.value(o[None])[0]
    alone = [value(agent, o) for o in obs]
    for threads in (1, 2, 3):
        assert read_only_map(agent, value, list(obs), threads) == alone


def test_episodes_without_values_draw_the_same_actions():
    """Runs that need no V(s, g) (collect, verify, labels) skip the critic, nothing else."""
    agent = Agent(hidden=16, seed=0)
    env = BlockWorld(6, max_steps=4, drop=True)
    tasks = []
    for k in range(6):
        env.reset(seed=k)
        tasks.append((env.get_state(), env.goals))
    envs = [BlockWorld(6, max_steps=4, drop=True) for _ in range(3)]
    with_v = run_episodes(agent, tasks, envs, np.random.default_rng(0))
    without = run_episodes(agent, tasks, envs, np.random.default_rng(0), values=False)
    for a, b in zip(with_v, without):
        assert a.actions.tolist() == b.actions.tolist() and a.success == b.success
        assert np.all(b.values == 0) and np.any(a.values != 0)
