"""The order in which blocks are moved: the moves sorted by report.move_kind, the share of
demonstrated steps that move a higher goal first (report.order_stats), plans replayed in the world
(rollout.replay), the other order of a joined demonstration (orders.other_orders), and the
leading indicator lab/bench/build_order.py."""
import os
import sys

import numpy as np
import pytest

import taskexp
from agent import Agent
from env2d import BlockWorld
from taskexp_lib import orders
from taskexp_lib.geometry import BLOCK_W, nearest_x_bin
from taskexp_lib.rollout import Trajectory, replay
from taskexp_lib.stats import MOVE_KINDS, move_kind, order_stats

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                "lab", "bench"))
import build_order  # noqa: E402

X = 0.2                                     # the tower's x, on the grid


@pytest.fixture
def world():
    """A world that drops, a scattered scene, and goals for a tower of three at X: blocks 0, 1, 2
    bottom up; blocks 3, 4, 5 have none."""
    env = BlockWorld(6, drop=True)
    goals = {b: (X, float(env.y_bins[b])) for b in range(3)}
    env.reset(seed=0, options={"goals": goals})
    return env, env.get_state(), goals


def drop(env, block, x):
    return env.encode_action(block, x, env.y_bins[0])


def test_move_kind_names_every_kind_of_move(world):
    env, s0, goals = world
    assert move_kind(s0, goals, drop(env, 0, X)) == "right"
    assert move_kind(s0, goals, drop(env, 0, X + BLOCK_W)) == "right block, other x"
    assert move_kind(s0, goals, drop(env, 2, X)) == "higher goal"
    assert move_kind(s0, goals, drop(env, 4, X)) == "free block"
    env.step(drop(env, 0, X))
    s1 = env.get_state()
    assert move_kind(s1, goals, drop(env, 0, -X)) == "placed block"
    assert move_kind(s1, goals, drop(env, 1, X)) == "right"        # the next layer is now lowest
    assert move_kind(s1, {0: goals[0]}, drop(env, 0, X)) is None    # nothing pending


def test_order_stats_counts_only_steps_with_several_pending_layers(world):
    env, s0, goals = world
    plan = [drop(env, b, X) for b in (0, 1, 2)]                  # bottom up: never higher first
    up = replay([(s0, goals)], [plan], [env])[0]
    assert up.success and len(up.actions) == 3
    stats = order_stats([up])
    assert stats == dict(multi_layer_steps=2, higher_first=0.0)  # the last step: one layer left
    wrong = Trajectory(goals, np.stack([s0, s0]), np.array([drop(env, 2, X)]), False)
    assert order_stats([up, wrong]) == dict(multi_layer_steps=3, higher_first=1 / 3)
    assert order_stats([]) == dict(multi_layer_steps=0, higher_first=None)


def test_replay_plays_a_plan_until_the_goals_hold(world):
    env, s0, goals = world
    envs = [BlockWorld(6, max_steps=1, drop=True) for _ in range(2)]   # a budget of one step
    tower = [drop(env, b, X) for b in (0, 1, 2)]
    upside_down = tower[::-1]
    extra = tower + [drop(env, 4, -X)]                           # a move after the goals held
    out = replay([(s0, goals)] * 3, [tower, upside_down, extra], envs)
    assert [t.success for t in out] == [True, False, True]
    assert len(out[2].actions) == 3 and len(out[2].states) == 4  # stopped when the goals held
    assert len(out[1].actions) == 3                              # the whole plan, past the budget
    assert np.array_equal(out[0].states[-1], out[2].states[-1])


def test_other_orders_keeps_only_the_orders_physics_allows(world):
    """Three demonstrations: block 0 to the table at X, then block 3 to another table spot (they
    commute); block 0 to X, then block 1 onto it (block 0 is its support); a tower of three, whose
    one order physics allows is its own; and one move alone, which has no other order."""
    env, _, goals = world
    far = X - 3 * BLOCK_W
    commuting = {0: goals[0], 3: (far, float(env.y_bins[0]))}
    dependent = {0: goals[0], 1: goals[1]}
    env.reset(seed=0, options={"goals": {**goals, **commuting}})    # every goal spot free
    s0 = env.get_state()
    plans = [[drop(env, 0, X), drop(env, 3, far)], [drop(env, 0, X), drop(env, 1, X)],
             [drop(env, b, X) for b in (0, 1, 2)], [drop(env, 0, X)]]
    tasks = [(s0, commuting), (s0, dependent), (s0, goals), (s0, {0: goals[0]})]
    demos = replay(tasks, plans, [env])
    assert all(d.success for d in demos)
    assert orders.other_orders(demos, [env], np.random.default_rng(0)) == 1
    other = demos[0].other_order
    assert other.success and [int(a[0]) for a in other.actions] == [3, 0]
    assert np.array_equal(other.states[0], s0) and other.goals == commuting
    assert all(d.other_order is None for d in demos[1:])
    assert len(orders.with_other_orders(demos)) == 5
    assert order_stats(orders.with_other_orders(demos[:1]))["multi_layer_steps"] == 0


def test_build_order_sorts_the_first_moves_of_a_checkpoint(tmp_path):
    path = str(tmp_path / "round0.npz")
    Agent(6, seed=0).save(path)                                      # untrained: any order
    m = build_order.measure(path, seed=0, episodes=8)
    assert list(m) == list(taskexp.Config.shapes)
    for shape, r in m.items():
        assert sum(r["first_move"].values()) == pytest.approx(1.0)
        assert sum(r["first_wrong"].values()) == pytest.approx(1.0)
        assert set(r["first_move"]) == set(MOVE_KINDS)
        assert 0 <= r["success"] <= r["first_wrong"]["all right"]    # success needs no wrong move
    # a tower built bottom up has no wrong move; one that starts at the top, at once
    env = BlockWorld(6, drop=True)
    goals = {b: (X, float(env.y_bins[b])) for b in range(3)}
    env.reset(seed=1, options={"goals": goals})
    s0 = env.get_state()
    up, down = replay([(s0, goals)] * 2, [[drop(env, b, X) for b in order]
                                          for order in ((0, 1, 2), (2, 1, 0))], [env])
    assert build_order.first_wrong(up) == ("all right", None)
    assert build_order.first_wrong(down) == ("higher goal", 1)
    assert nearest_x_bin(X) == int(drop(env, 0, X)[1])
