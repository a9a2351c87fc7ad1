"""Tests of the block world: Gymnasium API, scattering, physics of stacking, rest detection, exact
replay."""
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from matplotlib.figure import Figure

import env2d
from env2d import BlockWorld
from taskexp_lib import stress
from taskexp_lib.draw import draw_scene
from taskexp_lib.geometry import BLOCK_H, BLOCK_W, THRESHOLD, is_success, observation


@pytest.fixture
def env():
    return BlockWorld(6)


def flat_state(xs):
    """Blocks resting upright on the table at xs: state (n, 6)."""
    state = np.zeros((len(xs), 6))
    state[:, 0], state[:, 1] = xs, BLOCK_H / 2
    return state


SPREAD = [-0.4, -0.25, -0.1, 0.05, 0.2, 0.35]


def test_check_env_passes_with_warnings_as_errors():
    with warnings.catch_warnings():
        warnings.simplefilter("error")                # a warning (e.g. unbounded spaces) fails
        for kwargs in ({}, dict(drop=False), dict(n_blocks=3, render_mode="rgb_array"),
                       dict(n_blocks=8, max_steps=4)):
            check_env(gymnasium.make("taskexp/BlockWorld-v0", **kwargs).unwrapped)


def test_registered_with_gymnasium_and_keywords_pass_through():
    env = gymnasium.make("taskexp/BlockWorld-v0", n_blocks=7, max_steps=4)
    assert (env.unwrapped.n_blocks, env.unwrapped.max_steps) == (7, 4)
    # the world the method runs in drops a block at an x; drop=False gives the one that places
    assert env.unwrapped.drop and env.action_space.nvec.tolist() == [7, 37, 1]
    assert not gymnasium.make("taskexp/BlockWorld-v0", drop=False).unwrapped.drop
    obs, _ = env.reset(seed=0)
    assert obs.shape == (7, 6) and env.observation_space.contains(obs)


def test_step_before_reset_raises():
    with pytest.raises(gymnasium.error.ResetNeeded, match="reset"):
        BlockWorld(6).step([0, 0, 0])


def test_observations_stay_inside_the_observation_space(env):
    """Random actions, including falls off the table: every observation lies inside the bounds."""
    rng = np.random.default_rng(5)
    obs, _ = env.reset(seed=5)
    for i in range(60):
        obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs), obs
        if terminated or truncated:
            obs, _ = env.reset(seed=int(rng.integers(1000)))


def test_reset_is_deterministic_given_the_seed(env):
    obs_a, _ = env.reset(seed=7)
    goals_a = env.goals
    obs_b, _ = BlockWorld(6).reset(seed=7)
    assert np.array_equal(obs_a, obs_b)
    obs_c, _ = env.reset(seed=8)
    assert not np.array_equal(obs_a, obs_c)
    assert env.reset(seed=7)[0].tobytes() == obs_a.tobytes() and env.goals == goals_a


@pytest.mark.parametrize("n", [2, 6, 8])
def test_scatter_has_no_overlaps_and_keeps_goal_footprints_free(n):
    env = BlockWorld(n)
    tower = {0: (0.2, 0.025), 1: (0.2, 0.075), 2: (-0.3, 0.075)}
    for seed in range(100):
        options = {"goals": {b: g for b, g in tower.items() if b < n}} if seed % 2 else None
        obs, _ = env.reset(seed=seed, options=options)
        s = env.get_state()
        assert np.all(s[:, 1] == BLOCK_H / 2) and np.all(s[:, 2:] == 0)
        assert np.all(np.abs(s[:, 0]) <= 0.5 - BLOCK_W / 2 + 1e-12)     # on the table
        gaps = np.abs(s[:, None, 0] - s[None, :, 0]) + np.eye(n)
        assert gaps.min() >= BLOCK_W - 1e-12                              # no overlaps
        for b, (x, y) in env.goals.items():
            if n <= 6 or y < BLOCK_H:          # 8 blocks leave room for the ground goals' only
                assert np.abs(s[:, 0] - x).min() >= BLOCK_W - 1e-12       # footprint free
            assert np.hypot(s[b, 0] - x, s[b, 1] - y) > THRESHOLD         # not solved yet
        assert obs.dtype == np.float32 and obs[:, 5].sum() == len(env.goals)


def test_step_onto_another_block_stacks_it(env):
    env.reset(options={"state": flat_state(SPREAD), "goals": {0: (0.05, 1.5 * BLOCK_H)}})
    obs, reward, terminated, truncated, info = env.step(env.encode_action(0, 0.05, 1.5 * BLOCK_H))
    s = env.get_state()
    assert not info["noop"] and info["stable"] and 10 <= info["settle_steps"] < 60
    # resting contacts may penetrate by the slop (1 mm): a few mm and ~0.5 degree of play
    assert (abs(s[0, 0] - 0.05) < 3e-3 and abs(s[0, 1] - 1.5 * BLOCK_H) < 3e-3
            and abs(s[0, 2]) < 0.02)
    assert reward == 1.0 and terminated and info["success"] and not truncated
    assert np.abs(s[1:, :2] - flat_state(SPREAD)[1:, :2]).max() < 2e-3       # the others stayed


def test_teleport_into_an_occupied_spot_is_a_noop(env):
    env.reset(options={"state": flat_state(SPREAD), "goals": {0: (0.3, 0.025)}})
    before = env.get_state()
    for x in (0.05, 0.1, 0.0):                           # overlapping block 3 at x = 0.05
        obs, reward, terminated, truncated, info = env.step(env.encode_action(0, x, BLOCK_H / 2))
        assert info["noop"] and info["settle_steps"] == 0 and reward == 0.0
        assert np.array_equal(env.get_state(), before)
    # exactly side by side (touching block 5 at x = 0.35) is not an overlap
    _, _, _, _, info = env.step(env.encode_action(0, 0.45, BLOCK_H / 2))
    assert not info["noop"]


def test_goal_in_the_air_needs_a_support(env):
    goals = {1: (0.45, 1.5 * BLOCK_H)}                   # above the free spot at the right edge
    env.reset(options={"state": flat_state(SPREAD), "goals": goals})
    _, reward, terminated, _, info = env.step(env.encode_action(1, 0.45, 1.5 * BLOCK_H))
    assert reward == 0.0 and not terminated and env.get_state()[1, 1] < BLOCK_H     # it fell
    env.reset(options={"state": flat_state(SPREAD), "goals": goals})
    # build a support
    _, reward, terminated, _, _ = env.step(env.encode_action(0, 0.45, BLOCK_H / 2))
    assert reward == 0.0 and not terminated
    _, reward, terminated, truncated, info = env.step(env.encode_action(1, 0.45, 1.5 * BLOCK_H))
    assert reward == 1.0 and terminated and info["success"] and info["stable"] and not truncated


def test_tower_of_three_by_hand_is_stable_and_a_success(env):
    goals = {2: (0.0, BLOCK_H / 2), 4: (0.0, 1.5 * BLOCK_H), 5: (0.0, 2.5 * BLOCK_H)}
    env.reset(seed=3, options={"goals": goals})
    for b, (x, y) in goals.items():
        obs, reward, terminated, truncated, info = env.step(env.encode_action(b, x, y))
        assert not info["noop"] and info["stable"]
    assert reward == 1.0 and terminated and is_success(env.get_state(), goals)
    s = env.get_state()
    assert np.abs(s[[2, 4, 5], 0]).max() < 3e-3 and np.abs(s[[2, 4, 5], 2]).max() < 0.02


def test_no_rest_within_the_cap_is_unstable_and_no_success(env, monkeypatch):
    monkeypatch.setattr(env2d, "MAX_SUBSTEPS", 10)
    env.reset(options={"state": flat_state(SPREAD), "goals": {0: (0.45, BLOCK_H / 2)}})
    # still falling
    _, reward, terminated, _, info = env.step(env.encode_action(0, 0.45, 3.5 * BLOCK_H))
    assert not info["stable"] and info["settle_steps"] == 10 and reward == 0.0 and not terminated
    assert env.get_state()[0, 4] < -0.5                   # velocity kept


def test_truncation_at_max_steps():
    env = BlockWorld(4, max_steps=3)
    env.reset(seed=0, options={"goals": {0: (0.0, 3.5 * BLOCK_H)}})  # unreachable in three steps
    flags = [env.step(env.encode_action(1, x, BLOCK_H / 2))[3] for x in (-0.45, 0.45, -0.45)]
    assert flags == [False, False, True]


def test_block_off_the_table_lands_on_the_floor(env):
    state = flat_state(SPREAD)
    state[5, :2] = (0.8, 0.2)                          # beyond the table's edge, in the air
    env.reset(options={"state": state, "goals": {0: (0.0, BLOCK_H / 2)}})
    _, _, _, _, info = env.step(env.encode_action(0, -0.45, BLOCK_H / 2))
    s = env.get_state()
    assert info["stable"] and np.isfinite(s).all()
    assert abs(s[5, 1] - (env2d.FLOOR_Y + BLOCK_H / 2)) < 3e-3


def random_episode(env, rng, steps):
    """States (steps + 1, n, 6) and actions (steps, 3) of random actions."""
    states, actions = [env.get_state()], []
    for _ in range(steps):
        actions.append(rng.integers(env.action_space.nvec))
        env.step(actions[-1])
        states.append(env.get_state())
    return np.array(states), np.array(actions)


def test_restart_from_a_saved_state_replays_bit_for_bit(env):
    rng = np.random.default_rng(0)
    for seed in range(5):
        env.reset(seed=seed)
        random_episode(env, rng, 4)
        saved, goals = env.get_state(), env.goals
        states, actions = random_episode(env, rng, 6)
        for replay_env in (env, BlockWorld(6)):        # the same env after history, and a new one
            replay_env.reset(options={"state": saved, "goals": goals})
            for t, a in enumerate(actions):
                replay_env.step(a)
                assert np.array_equal(replay_env.get_state(), states[t + 1]), (seed, t)


def test_declared_rest_is_real_rest(env):
    """After a declared rest, 2 more seconds of simulation move no block by REST_MOVE."""
    rng = np.random.default_rng(1)
    checked = 0
    for seed in range(12):
        env.reset(seed=seed)
        for _ in range(8):
            _, _, _, _, info = env.step(rng.integers(env.action_space.nvec))
            if info["noop"] or not info["stable"]:
                continue
            before = env._read()                       # continue the settled space itself
            for _ in range(120):
                env2d._space_step(env._space._space, env2d.DT)
            d = env._read()[:, :3] - before[:, :3]
            assert ((np.hypot(d[:, 0], d[:, 1]) + env2d.HALF_DIAG * np.abs(d[:, 2])).max()
                    < env2d.REST_MOVE)
            checked += 1
    assert checked > 50


def test_batch_read_matches_the_bodies(env):
    env.reset(seed=2)
    env.step(env.encode_action(0, 0.0, 2.5 * BLOCK_H))
    rows = [(*b.position, b.angle, *b.velocity, b.angular_velocity) for b in env._bodies]
    assert np.array_equal(env._read(), np.array(rows))


def test_drop_lets_physics_find_the_height():
    """drop=True: one action (block, x) builds a tower of any height, and a block let go at the
    edge of a stack rests on the stack's top, or beside it on the table."""
    env = BlockWorld(6, drop=True)
    assert env.action_space.nvec.tolist() == [6, 37, 1]
    goals = {b: (0.05, (k + 0.5) * BLOCK_H) for k, b in enumerate([3, 0, 1, 2])}   # x of block 3
    env.reset(options={"state": flat_state(SPREAD), "goals": goals})
    for b in (0, 1, 2):
        _, reward, terminated, _, info = env.step(env.encode_action(b, 0.05, 123.0))   # y ignored
        assert not info["noop"] and info["stable"]
    assert reward == 1.0 and terminated and is_success(env.get_state(), goals)
    assert env.decode_action([2, 18, 0]) == (2, 0.0, None)
    # drop_height: above what a falling block would hit, the table where there is nothing
    others = env.get_state()[[3, 0, 1, 4], :3]        # the tower (each block sinks 1 mm), block 4
    assert env2d.drop_height(0.05 + 0.0999, others) == pytest.approx(3.5 * BLOCK_H, abs=5e-3)
    assert env2d.drop_height(0.125, others) == pytest.approx(3.5 * BLOCK_H, abs=5e-3)   # both
    assert env2d.drop_height(0.06 + BLOCK_W, others[:3]) == BLOCK_H / 2       # side by side
    with pytest.raises(ValueError, match="drop"):
        BlockWorld(6, drop="yes")


def test_drop_on_a_tilted_block_uses_its_bounding_box():
    tilted = np.array([[0.0, np.hypot(BLOCK_W, BLOCK_H) / 2, np.arctan2(BLOCK_H, BLOCK_W)]])
    top = tilted[0, 1] + (BLOCK_W * np.sin(tilted[0, 2]) + BLOCK_H * np.cos(tilted[0, 2])) / 2
    assert env2d.drop_height(0.0, tilted) == pytest.approx(top + BLOCK_H / 2)
    fallen = np.array([[0.0, -0.47, 0.0]])                         # on the catch floor: no support
    assert env2d.drop_height(0.0, fallen) == BLOCK_H / 2


def test_encode_decode_round_trip(env):
    for a in np.stack(np.meshgrid(range(6), range(37), range(6)), -1).reshape(-1, 3):
        b, x, y = env.decode_action(a)
        assert np.array_equal(env.encode_action(b, x, y), a)
    assert np.array_equal(env.encode_action(2, 0.012, 0.08), [2, 18, 1])  # nearest bins
    assert env.encode_action(0, 0.0, 0.0).dtype == np.int64


@pytest.mark.parametrize("call, match", [
    (lambda e: e.step([6, 0, 0]), "action"),
    (lambda e: e.step([0, 37, 0]), "action"),
    (lambda e: e.step([0, 0, -1]), "action"),
    (lambda e: e.step([0.0, 1.0, 2.0]), "action"),
    (lambda e: e.step([0, 1]), "action"),
    (lambda e: e.reset(options={"goals": {6: (0.0, 0.025)}}), "block 6"),
    (lambda e: e.reset(options={"goals": {0: (0.7, 0.025)}}), "0.7"),
    (lambda e: e.reset(options={"goals": {0: (0.0, -0.01)}}), "-0.01"),
    (lambda e: e.reset(options={"goals": {0: (0.0, np.nan)}}), "nan"),
    (lambda e: e.reset(options={"goals": {}}), "goals"),
    (lambda e: e.reset(options={"goals": {0: 0.1}}), "0.1"),
    (lambda e: e.reset(options={"state": np.zeros((5, 6))}), r"\(5, 6\)"),
    (lambda e: e.reset(options={"state": np.full((6, 6), np.inf)}), "finite"),
    (lambda e: e.reset(options={"seed": 3}), "seed"),
    (lambda e: e.encode_action(9, 0.0, 0.0), "block 9"),
    (lambda e: e.encode_action(0, np.nan, 0.0), "nan"),
    (lambda e: BlockWorld(9), "n_blocks must be in 2..8, got 9"),
    (lambda e: BlockWorld(True), "got True"),
    (lambda e: BlockWorld(6, render_mode="human"), "human"),
    (lambda e: BlockWorld(6, max_steps=0), "max_steps=0"),
    (lambda e: BlockWorld(6, max_steps=-3), "max_steps=-3"),
    (lambda e: BlockWorld(6, max_steps=2.5), "max_steps=2.5"),
    (lambda e: BlockWorld(6, max_steps=True), "max_steps=True"),
    (lambda e: e.reset(options={"goals": {0: (0.0, 0.8)}}), "higher than 6 blocks"),
    (lambda e: e.reset(options={"goals": {0: (0.1, 0.025), 3: (0.105, 0.026)}}), "blocks 0 and 3"),
    (lambda e: e.reset(options={"state": np.full((6, 6), 9.0)}), "outside the world"),
])
def test_bad_inputs_raise_value_error(env, call, match):
    env.reset(seed=0)
    with pytest.raises(ValueError, match=match):
        call(env)


def test_render_and_draw_scene():
    env = BlockWorld(6, render_mode="rgb_array")
    env.reset(seed=0)
    image = env.render()
    assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3 and image.std() > 0
    assert BlockWorld(6).render() is None
    ax = draw_scene(Figure().add_subplot(), env.get_state(), env.goals, title="t")
    assert ax.get_ylim() == (-0.05, 6 * BLOCK_H + 0.1) and ax.get_title() == "t"
    ticks = [axis.get_major_formatter() for axis in (ax.xaxis, ax.yaxis)]
    assert [f(0.2, 0) for f in ticks] == ["0.2 m"] * 2 and ticks[0](-1e-17, 0) == "0.0 m"


def test_observation_and_is_success_helpers():
    state = flat_state(SPREAD)
    obs = observation(state, {2: (0.1, 0.075)})
    assert obs.shape == (6, 6) and obs.dtype == np.float32
    assert np.allclose(obs[2, 3:], (0.1, 0.075, 1.0)) and not obs[[0, 1, 3, 4, 5], 3:].any()
    assert (is_success(state, {1: (-0.25 + 0.019, 0.025)})
            and not is_success(state, {1: (-0.22, 0.025)}))


# ----------------------------------------------------------------------------- property-based

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

TABLE_EPS = 3 * env2d.SLOP      # resting blocks may sink by the allowed penetration, no more


def lowest_point(state):
    """y of each block's lowest corner (n,): a rotated box reaches |cos a| h/2 + |sin a| w/2 below
    its centre."""
    a = state[:, 2]
    return state[:, 1] - 0.5 * (np.abs(np.cos(a)) * BLOCK_H + np.abs(np.sin(a)) * BLOCK_W)


@st.composite
def adversarial_action(draw, state):
    """stress.adversarial_action, drawn through hypothesis so a failing example shrinks."""
    return stress.adversarial_action(state, lambda lo, hi: draw(st.integers(lo, hi)),
                                     lambda seq: draw(st.sampled_from(seq)))


# Its long lines stay (noqa): derandomize=True seeds hypothesis from the test's source, comments
# aside, so reflowing it would change the examples it draws.
@settings(max_examples=250, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(data=st.data(), n=st.integers(2, 8), seed=st.integers(0, 2**16), tower=st.booleans())
def test_physics_never_breaks(data, n, seed, tower):
    """Up to 40 actions per example, ~5000 in all: teleports into blocks, far in the air, at the table's
    edge and onto tall stacks. After every action: finite state, every block on the table (not in
    it) or on the catch floor, rest within the substep cap; at the end, exact replay from a saved state."""  # noqa: E501
    env = BlockWorld(n, max_steps=10**6)
    env.reset(seed=seed)
    if tower:                                              # start from a tower as tall as it gets
        stress.stack_tower(env)
    saved, actions, states = env.get_state(), [], []
    for _ in range(data.draw(st.integers(1, 40), label="steps")):
        action = data.draw(adversarial_action(env.get_state()), label="action")
        _, _, _, _, info = env.step(action)
        s = env.get_state()
        actions.append(action)
        states.append(s)
        assert np.isfinite(s).all(), (action, s)
        assert s.shape == (n, 6)
        on_floor = s[:, 1] < -BLOCK_H                      # fell off: must lie on the catch floor
        assert (lowest_point(s)[~on_floor] > -TABLE_EPS).all(), ("block in the table", action, s)
        assert (lowest_point(s)[on_floor] > env2d.FLOOR_Y - TABLE_EPS).all(), ("block through the floor", s)  # noqa: E501
        assert (np.abs(s[:, 0]) < 5).all(), ("block left the world", s)
        assert info["noop"] or (info["stable"] and info["settle_steps"] <= env2d.MAX_SUBSTEPS), (action, info)  # noqa: E501
    replay = BlockWorld(n, max_steps=10**6)
    replay.reset(options={"state": saved, "goals": env.goals})
    for action, s in zip(actions, states):
        replay.step(action)
        assert np.array_equal(replay.get_state(), s), action
