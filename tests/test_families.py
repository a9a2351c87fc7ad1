"""Tests of the blocks no goal names: the evaluation families (blocked sites, goals in the air),
their scripted builder, and the hindsight on goals that teaches them (taskexp_lib/hindsight.py)."""
import importlib
import os
import sys

import numpy as np
import pytest

from env2d import BlockWorld
from taskexp_cli.try_structure import scripted_build
from taskexp_lib import hindsight, shapes
from taskexp_lib.config import Config
from taskexp_lib.geometry import BLOCK_H, BLOCK_W, is_success, layer, layer_y
from taskexp_lib.rollout import Trajectory, cut, replay


def unnamed_blocks_script():
    """lab/bench/unnamed_blocks.py as a module, imported as the lab's scripts import each other
    (their folder on the path)."""
    bench = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "lab",
                         "bench")
    if bench not in sys.path:
        sys.path.insert(0, bench)
    return importlib.import_module("unnamed_blocks")


@pytest.fixture
def world():
    return BlockWorld(6, max_steps=30, drop=True)


@pytest.fixture(scope="module")
def families():
    return shapes.family_tasks(Config(eval_episodes=12, seed=5), BlockWorld(6, drop=True))


def test_supports_fill_every_layer_under_a_goal_in_the_air():
    assert shapes.supports({0: (0.1, layer_y(0))}) == []
    assert np.allclose(shapes.supports({0: (0.1, layer_y(2))}), [(0.1, layer_y(1)),
                                                                 (0.1, layer_y(0))])
    tower_top = {0: (0.0, layer_y(3)), 1: (0.0, layer_y(2))}
    assert np.allclose(shapes.supports(tower_top), [(0.0, layer_y(1)), (0.0, layer_y(0))])
    legs = {0: (-0.75 * BLOCK_W, layer_y(0)), 1: (0.75 * BLOCK_W, layer_y(0)),
            2: (0.0, layer_y(1))}                                # "Y"'s bridge: no support
    assert shapes.supports(legs) == []


def test_family_scenes_need_blocks_no_goal_names_and_a_script_builds_them(families, world):
    assert set(families) == {"blocked", "air"}
    assert set(families["air"]) == set(shapes.FAMILIES["air"])
    for family, tasks in families.items():
        for name, scenes in tasks.items():
            for s0, goals in scenes:
                assert not is_success(s0, goals)
                if family == "blocked":       # a block without a goal stands on a ground goal
                    on_spot = [b for b in range(6) if b not in goals and any(
                        np.hypot(s0[b, 0] - x, s0[b, 1] - y) < 1e-9 for x, y in goals.values())]
                    assert len(on_spot) == 1, (name, goals, s0[:, :2])
                else:                         # nothing stands under any goal, all on the table
                    assert np.all(layer(s0[:, 1]) == 0)
                    assert all(abs(s0[b, 0] - x) >= BLOCK_W - 1e-9 for b in range(6)
                               for x, _ in goals.values())
                    assert shapes.supports(goals)
                assert scripted_build(world, s0, goals), (family, name, goals)


def test_a_family_that_needs_more_blocks_than_the_world_has_is_left_out():
    small = shapes.family_tasks(Config(eval_episodes=1, n_blocks=3), BlockWorld(3, drop=True))
    assert set(small["air"]) == {"1 up", "2 up"}    # "3 up", "two apart", "tower top" need 4
    assert small["blocked"] == {}                   # "I" needs 4 goal blocks and a blocker


def test_scripted_builder_fails_where_a_block_is_missing(world):
    """The builder is a check, not a rubber stamp: goals whose supports no free block can fill."""
    goals = {b: (x, layer_y(2)) for b, x in enumerate((-0.3, 0.0, 0.3))}   # 6 supports, 3 free
    s0 = shapes.start_state(world, goals, np.random.default_rng(0))
    assert not scripted_build(world, s0, goals)


def drops(world, moves):
    return [world.encode_action(b, x, world.y_bins[0]) for b, x in moves]


def played(world, s0, goals, moves):
    return replay([(s0, goals)], [np.array(drops(world, moves))], [world])[0]


def scene(world):
    s0 = np.zeros((6, 6))
    s0[:, 0], s0[:, 1] = (-0.45, -0.33, -0.21, 0.21, 0.33, 0.45), BLOCK_H / 2    # the middle free
    return s0


def test_a_part_keeps_the_support_its_goal_needs_and_drops_the_rest(world):
    s0 = scene(world)
    x = float(world.x_bins[16])                            # -0.05: a free spot
    goals = {0: (x, layer_y(0)), 1: (x, layer_y(1)), 5: (0.1, layer_y(0))}
    demo = played(world, s0, goals, [(5, 0.1), (0, x), (1, x)])
    assert demo.success and len(demo.actions) == 3
    whole = cut(demo, {1: goals[1]})                        # the top block alone: 0 carries none
    part, = hindsight.needed_moves([whole], [world])
    assert len(whole.actions) == 3                          # a query: what it was given stays
    assert [int(a[0]) for a in part.actions] == [0, 1]      # block 5's move is not needed
    assert is_success(part.states[-1], part.goals) and not is_success(part.states[0], part.goals)


def test_a_part_keeps_the_move_that_clears_its_site(world):
    s0 = scene(world)
    p = float(s0[2, 0])                                     # block 2 stands on the site
    goals = {2: (0.05, layer_y(0)), 4: (p, layer_y(0))}
    demo = played(world, s0, goals, [(2, 0.05), (4, p)])
    assert demo.success
    part, = hindsight.needed_moves([cut(demo, {4: goals[4]})], [world])
    assert [int(a[0]) for a in part.actions] == [2, 4]      # 2, which no goal names, moves away
    assert 2 not in part.goals


def test_cut_ends_where_a_part_first_holds_and_refuses_one_held_at_the_start(world):
    s0 = scene(world)
    x = float(world.x_bins[18])
    goals = {0: (x, layer_y(0)), 1: (x, layer_y(1))}
    demo = played(world, s0, goals, [(0, x), (1, x)])
    assert len(cut(demo, {0: goals[0]}).actions) == 1
    assert cut(demo, {3: tuple(s0[3, :2])}) is None


def test_goal_parts_are_proper_and_reproducible():
    goals = {0: (0.0, 0.025), 3: (0.1, 0.025), 4: (0.2, 0.025)}
    draws = [hindsight.goal_part(goals, np.random.default_rng(s)) for s in range(40)]
    assert all(0 < len(d) < len(goals) and set(d) <= set(goals) for d in draws)
    assert {len(d) for d in draws} == {1, 2}
    assert draws[0] == hindsight.goal_part(goals, np.random.default_rng(0))


def test_add_parts_keeps_the_parts_that_move_a_block_no_goal_names(world):
    s0 = scene(world)
    x = float(world.x_bins[16])
    tower = {0: (x, layer_y(0)), 1: (x, layer_y(1)), 2: (x, layer_y(2))}
    demos = [played(world, s0, tower, [(0, x), (1, x), (2, x)]) for _ in range(10)]
    apart = {0: (x, layer_y(0)), 5: (0.1, layer_y(0))}       # neither part needs the other's move
    demos.append(played(world, s0, apart, [(0, x), (5, 0.1)]))
    one = played(world, s0, {0: tower[0]}, [(0, x)])
    hindsight.add_parts(demos + [one], [world], np.random.default_rng(0), 4)
    assert one.parts == [] and demos[-1].parts == []        # no part moves a block it leaves out
    assert sum(len(d.parts) for d in demos) > 10
    for d in demos[:-1]:
        assert len({tuple(sorted(p.goals)) for p in d.parts}) == len(d.parts)    # each once
        for p in d.parts:
            assert isinstance(p, Trajectory) and p.success
            assert is_success(p.states[-1], p.goals)
            assert any(int(a[0]) not in p.goals for a in p.actions)
            assert set(p.goals) not in ({0}, {0, 1})       # the bottom needs no other block


def test_clearing_pairs_drop_the_second_block_where_the_first_stood():
    """--clear-pairs: the second move of such a pair drops another block on the first one's old
    spot, so the part that names the second block alone needs the first moved away."""
    import taskexp
    worlds = [BlockWorld(6, drop=True) for _ in range(2)]
    cfg = Config(clear_pairs=1.0)
    pairs = taskexp.base_pairs(cfg, worlds, np.random.default_rng(0), 24)
    for p in pairs:
        (b1, _, _), (b2, x2, _) = p.actions
        assert b1 != b2 and x2 == np.abs(worlds[0].x_bins - p.states[0][b1, 0]).argmin()
    hindsight.add_parts(pairs, worlds, np.random.default_rng(0), 4)
    # the parts that name the second block alone (a random second move needs the first 4 in 9)
    second = [q for p in pairs for q in p.parts if list(q.goals) == [int(p.actions[1][0])]]
    assert len(second) >= 20 and all(len(q.actions) == 2 for q in second)
    # on the table where the first stood, unless the first moved too little and now carries it
    assert sum(layer(q.goals[int(q.actions[1][0])][1]) == 0 for q in second) >= 18


def test_the_indicator_counts_the_moves_of_blocks_no_goal_names(tmp_path):
    """lab/bench/unnamed_blocks.py on an untrained checkpoint: every task measured, shares in
    0..1, and the first-move share is what the episodes' first actions say."""
    unnamed_blocks = unnamed_blocks_script()

    from agent import Agent
    path = str(tmp_path / "round0.npz")
    Agent(6, n_x=37, n_y=1, hidden=16, seed=0).save(path)
    m = unnamed_blocks.measure(path, seed=0, episodes=3)
    assert {f: set(t) for f, t in m.items()} == {f: set(t) for f, t in shapes.FAMILIES.items()}
    for tasks in m.values():
        for r in tasks.values():
            assert all(0.0 <= r[k] <= 1.0 for k in ("success", "first_unnamed", "unnamed"))
            assert r["first_unnamed"] * 3 == round(r["first_unnamed"] * 3)     # of 3 scenes
    assert all(0.0 <= r[k] <= 1.0 for r in m["blocked"].values()
               for k in ("x_off_site", "best_x_off_site"))


def test_the_indicator_counts_a_support_moved_within_its_column():
    """unnamed_blocks.supports_undone: a block that no goal names taken from under a goal and set
    down under it again counts; one brought in from aside, or a goal block moved, does not."""
    unnamed_blocks = unnamed_blocks_script()
    h = BLOCK_H
    goals = {0: (0.0, 3.5 * h)}                                   # "3 up"
    s0 = np.zeros((3, 6))
    s0[:, 0], s0[:, 1] = [-0.3, 0.01, 0.3], h / 2                 # block 1 under the goal already

    def moved(b, x, y):                                           # one move: s0 -> (s0, s1)
        s1 = s0.copy()
        s1[b, :2] = x, y
        return Trajectory(goals, np.stack([s0, s1]), np.array([[b, 0, 0]]), False)
    undone = moved(1, 0.0, h / 2)                                 # back into its own column
    built = moved(2, 0.0, 1.5 * h)                                # a block from aside on top
    goal_block = moved(0, 0.0, 1.5 * h)
    assert unnamed_blocks.supports_undone([undone]) == 1.0
    assert unnamed_blocks.supports_undone([built, goal_block]) == 0.0
    assert unnamed_blocks.supports_undone([undone, built]) == 0.5


def test_the_indicator_finds_where_the_blocker_would_go(world):
    """unnamed_blocks.blocker_sent_off reads the blocker's own x-head: a policy that sends every
    block back where it stands scores 0, one that sends it to the farthest x-bin scores 1."""
    unnamed_blocks = unnamed_blocks_script()

    from agent import ActionDist
    tasks = shapes.family_tasks(Config(seed=0, eval_episodes=2), world)["blocked"]["I"]
    xs = np.asarray(world.x_bins)

    class Rigged:                               # every block's x-head certain of one bin
        features = staticmethod(lambda obs: obs)

        def __init__(self, pick):
            self.pick = pick                    # (x-bins, the block's x) -> the bin

        def policy(self, obs):
            out = np.zeros((1, world.n_blocks, 1 + len(xs) + 1))
            for i in range(world.n_blocks):
                out[0, i, 1 + self.pick(xs, obs[0, i, 0])] = 50.0
            return ActionDist(out, len(xs))

    stay, away = Rigged(lambda xs, x: np.abs(xs - x).argmin()), Rigged(lambda xs, x: np.abs(
        xs - x).argmax())
    mass, best = unnamed_blocks.blocker_sent_off(stay, tasks, xs)
    assert mass < 1e-9 and best == 0.0
    mass, best = unnamed_blocks.blocker_sent_off(away, tasks, xs)
    assert mass > 1 - 1e-9 and best == 1.0
