"""Tests of a structure a person writes (try_structure.read_structure), of the agent in worlds of
other block counts with the weights it learnt in one, and of `python -m taskexp_cli try`."""
import os
import subprocess
import sys
import textwrap
import warnings

import numpy as np
import pytest
from PIL import Image

import taskexp_cli as cli
from agent import Agent, OtherWorldWarning
from env2d import BlockWorld, physics_pool, run_worlds
from taskexp_cli.report import blocks_table
from taskexp_cli.try_structure import read_structure
from taskexp_lib import shapes
from taskexp_lib.config import Config
from taskexp_lib.features import featurize
from taskexp_lib.geometry import BLOCK_H, BLOCK_W, layer_y, observation
from taskexp_lib.rollout import run_episodes

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ARCH = "0,0 0,1 1.5,0 1.5,1 0.75,2"           # two towers of two and a block across them
OTHER_WORLDS = pytest.mark.filterwarnings("ignore::agent.OtherWorldWarning")   # asked for


def test_a_written_structure_reads_as_cells_and_a_name_as_its_shape():
    assert read_structure(ARCH) == [(0, 0), (0, 1), (1.5, 0), (1.5, 1), (0.75, 2)]
    assert read_structure(" 0,0;0,1  ") == [(0, 0), (0, 1)]
    assert read_structure("3T", 6) == shapes.SHAPES["3T"]
    assert read_structure("0,2", 3) == [(0, 2)]                  # in the air, on two supports


@pytest.mark.parametrize("text, n_blocks, says", [
    ("", 8, "no cells"),
    ("0,0 x,1", 8, "cell 'x,1': write cells as dx,layer"),
    ("0,0,0", 8, "write cells as dx,layer"),
    ("0.3,0", 8, "multiple of 0.25"),
    ("nan,0", 8, "finite"),
    ("0,inf", 8, "finite"),
    ("0,1.5", 8, "whole number"),
    ("0,-1", 8, "whole number"),
    ("0,0 0.75,0", 8, "cells 0,0 and 0.75,0 overlap"),
    ("-4.5,0 4.75,0", 8, "9.25 block widths apart; the action grid spans 9"),
    ("0,0 0,1 0,2 0,3 0,4 0,5 0,6", 6, "needs 7 blocks (7 with goals, 0 under"),
    ("0,3", 3, "needs 4 blocks (1 with goals, 3 under goals in the air); the world has 3"),
])
def test_what_cannot_be_built_is_refused_in_one_line(text, n_blocks, says):
    with pytest.raises(ValueError) as e:
        read_structure(text, n_blocks)
    assert says in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_a_lopsided_structure_is_placed_on_the_grid_at_every_spot_it_fits():
    env, rng = BlockWorld(2), np.random.default_rng(0)
    xs = np.array([[x for x, _ in shapes.place_cells([(0, 0), (8, 0)], env, rng).values()]
                   for _ in range(200)])
    assert xs.min() >= env.x_bins[0] - 1e-9 and xs.max() <= env.x_bins[-1] + 1e-9
    assert np.isclose(xs.min(), env.x_bins[0]) and np.isclose(xs.max(), env.x_bins[-1])


def test_a_site_is_free_unless_a_block_stands_where_the_structure_needs_the_ground():
    env = BlockWorld(4)
    goals = {0: (0.0, layer_y(0)), 1: (0.0, layer_y(1)), 2: (0.3, layer_y(1))}  # 2 needs support
    state = np.zeros((4, 6))
    state[:, 0], state[:, 1] = [-0.4, -0.25, -0.1 - 1e-3, 0.4], BLOCK_H / 2
    assert shapes.site_free(state, goals)
    state[3, 0] = 0.3 + 0.9 * BLOCK_W                  # on the ground under block 2's goal
    assert not shapes.site_free(state, goals)
    state[3, 0], state[0, 0] = 0.4, 0.0                # block 0 at its own goal: it may stay
    assert shapes.site_free(state, goals)
    state[1, :2] = 0.05, BLOCK_H / 2                   # a goal block on another goal's spot
    assert not shapes.site_free(state, goals)
    s0 = shapes.start_state(env, goals, np.random.default_rng(1))    # room: scattered off it
    assert shapes.site_free(s0, goals)


def obs_in(n_blocks, seed=0):
    env = BlockWorld(n_blocks, drop=True)
    goals = shapes.place_cells([(0, 0), (0, 1)], env, np.random.default_rng(seed))
    return observation(shapes.start_state(env, goals, np.random.default_rng(seed)), goals)


def test_the_agent_acts_and_values_in_any_world_with_the_weights_it_learnt():
    agent = Agent(6, seed=3, dtype="float64")
    with warnings.catch_warnings():
        warnings.simplefilter("error")                 # its own world: nothing to say
        agent.act(obs_in(6), deterministic=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OtherWorldWarning)
        for n in (2, 7, 8):
            a = agent.act(obs_in(n), deterministic=True)
            assert 0 <= a[0] < n and np.isfinite(agent.value(obs_in(n, seed=1)))
    for bad, says in ((np.zeros((1, 1, 6)), "must be in 2..8, got 1"),
                      (np.zeros((1, 9, 6)), "must be in 2..8, got 9"),
                      (np.zeros((1, 6, 5)), r"shape \(B, n, 6\)")):
        with pytest.raises(ValueError, match=says):
            agent.act(bad)


def test_a_program_is_told_once_per_block_count_whoever_asks():
    """The warnings module says it, not state on the agent: acting and valuing in a world of 7
    from several places warns once, as a program shows warnings by default."""
    code = textwrap.dedent("""
        import numpy as np
        from agent import Agent
        agent, obs = Agent(6, seed=0), lambda n: np.zeros((1, n, 6))
        agent.act(obs(7))
        agent.value(obs(7))
        agent.sample(obs(7))
        agent.act(obs(8))
        agent.act(obs(6))
    """)
    res = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-2000:]
    told = [line for line in res.stderr.splitlines() if "OtherWorldWarning" in line]
    assert len(told) == 2 and "one of 7 with" in told[0] and "one of 8 with" in told[1], res.stderr


@OTHER_WORLDS
def test_a_blocks_features_do_not_depend_on_how_many_blocks_the_world_has():
    """The features of a block are its own (plain): the same in a world of 6 and of 8, scaled by
    the layers of the world the agent learnt in, whatever the world it acts in."""
    agent = Agent(6, dtype="float64")
    obs8 = obs_in(8)
    assert np.array_equal(agent.features(obs8[None])[0, :6], agent.features(obs8[None, :6])[0])
    assert np.array_equal(agent.features(obs8[None]), featurize(obs8[None], 6, "plain"))


@OTHER_WORLDS
def test_an_agent_that_places_picks_only_the_layers_a_world_has():
    agent = Agent(6, n_y=6, seed=1)
    for n in (3, 8):
        obs = np.repeat(obs_in(n)[None], 500, axis=0)
        layers = agent.act(obs, rng=np.random.default_rng(0))[:, 2]
        assert layers.max() < min(n, 6) and len(set(layers)) == min(n, 6)


@OTHER_WORLDS
def test_physics_workers_run_worlds_of_any_block_count_with_the_same_results():
    agent, cfg = Agent(6, seed=2), Config(n_envs=4, n_blocks=7)
    tasks = shapes.eval_tasks(Config(eval_episodes=3, shapes=("I",)),
                              BlockWorld(7, drop=True))["I"]
    alone = run_episodes(agent, tasks, run_worlds(cfg)[0], deterministic=True)
    with physics_pool(2, drop=True) as pool:
        shared = run_episodes(agent, tasks, run_worlds(cfg, pool)[0], deterministic=True)
        six = shapes.eval_tasks(Config(eval_episodes=2), BlockWorld(6, drop=True))["Y"]
        run_episodes(agent, six, run_worlds(Config(n_envs=4), pool)[0], deterministic=True)
    assert all(np.array_equal(a.states, b.states) for a, b in zip(alone, shared))


def test_the_blocks_table_reports_other_worlds_beside_the_runs_own():
    results = {"config": {"n_blocks": 6}, "rounds": [
        {"round": 0, "eval": {"I": 0.5, "Y": 0.25}, "blocks": {"7": {"I": 0.25, "Y": 0.0}}}]}
    table = blocks_table(results).splitlines()
    assert "the weights learnt with 6" in table[0]
    assert table[3:] == ["| 0 | 6 | 50% | 25% |", "| 0 | 7 | 25% | 0% |"]
    del results["rounds"][0]["blocks"]                 # a run made before: no table
    assert blocks_table(results) == ""


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    path = str(tmp_path_factory.mktemp("agent") / "round0.npz")
    Agent(6, seed=0).save(path)
    return path


def test_try_builds_a_written_structure_in_another_world_and_draws_the_attempt(
        checkpoint, tmp_path, capsys):
    out = str(tmp_path / "arch.png")
    cli.main(["try", checkpoint, ARCH, "--blocks", "7", "--scenes", "3", "--out", out, "--gif"])
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].endswith("learnt in a world of 6 blocks, tried in one of 7 (the same "
                               "weights)")
    assert printed[1].startswith("built in ") and printed[1].endswith("of 3 scenes (0%) of 7 "
                                                                      "blocks"), printed
    assert "the site was free at the start in" in printed[2]
    assert "a scripted builder that first clears the site builds it in 3 of 3" in printed[3]
    assert Image.open(out).format == "PNG"
    gif = Image.open(str(tmp_path / "arch.gif"))
    assert gif.format == "GIF" and gif.n_frames == 11           # the start and 10 actions


def test_try_says_when_even_the_scripted_builder_cannot_build_it():
    """A staircase whose top two blocks overhang the bottom one by more than half falls: the
    summary does not claim that the structure stands."""
    from taskexp_cli.try_structure import summary, try_structure
    agent = Agent(6, hidden=16, seed=0)
    tried = try_structure(agent, "0,0 0.75,1 1.5,2", scenes=2)
    assert not any(tried.scripted)
    assert summary(tried).splitlines()[2].endswith("builds it in 0 of 2 (where it does not, the "
                                                   "structure falls or the table leaves no room)")
    with pytest.raises(ValueError, match="scenes: at least 1"):
        try_structure(agent, "0,0", scenes=0)


@pytest.mark.parametrize("args, says", [
    (["0,0 0.5,0"], "cells 0,0 and 0.5,0 overlap"),
    (["3T", "--blocks", "5"], "needs 6 blocks"),
    (["I", "--blocks", "9"], "--blocks must be in 2..8, got 9"),
    (["I", "--blocks", "1"], "--blocks must be in 2..8, got 1"),
    (["I", "--scenes", "0"], "--scenes must be >= 1"),
    (["I", "--scene", "5", "--scenes", "5"], "--scene must be in 0..4"),
    (["I", "--out", "/nonexistent/tried.png"], "no folder /nonexistent to draw in"),
    (["I", "--out", "tried.txt"], "name a picture, e.g. tried.png"),
])
def test_try_refuses_in_one_line_before_it_says_anything_else(checkpoint, args, says, capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["try", checkpoint, *args])
    out, err = capsys.readouterr()
    assert e.value.code == 2 and says in err and err.count("\n") == 1, err
    assert out == ""


def test_try_refuses_what_is_no_checkpoint_in_one_line(tmp_path, capsys):
    for path in (str(tmp_path / "missing.npz"), os.devnull):
        with pytest.raises(SystemExit):
            cli.main(["try", path, "I"])
        err = capsys.readouterr().err
        assert "error:" in err and err.count("\n") == 1, err


def test_eval_blocks_flag_takes_counts_none_or_refuses():
    assert cli.parse_args(["--eval-blocks", "7"]).cfg.eval_blocks == (7,)
    assert cli.parse_args(["--eval-blocks"]).cfg.eval_blocks == ()
    assert cli.parse_args(["--families"]).cfg.families == ()      # any tuple: none is a setting
    assert Config().eval_blocks == (7, 8)
    with pytest.raises(SystemExit):
        cli.parse_args(["--eval-blocks", "5"])          # "3T" needs 6
    assert cli.problem(Config(eval_blocks=(7, 9))) == (
        "--eval-blocks must be in 6..8, got 9 (the held-out shapes need 6 blocks, the table holds "
        "8)")


@OTHER_WORLDS
def test_the_bench_splits_success_by_whether_the_site_was_free():
    """lab/bench/more_blocks.py: success as the run's evaluation counts it, split by
    shapes.site_free (8 blocks: the wide shapes' sites are seldom free)."""
    import sys
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                    "lab", "bench"))
    import more_blocks

    from taskexp import evaluate
    agent, cfg = Agent(6, hidden=16, seed=0), Config(eval_episodes=4, n_envs=4)
    worlds = run_worlds(Config(n_blocks=8, n_envs=4))[0]
    tasks = shapes.eval_tasks(cfg, worlds[0])
    split, rates = more_blocks.split_by_site(agent, tasks, worlds), evaluate(agent, tasks, worlds)
    for shape, (won, free, on_free, on_busy) in split.items():
        share = np.mean([shapes.site_free(s0, goals) for s0, goals in tasks[shape]])
        assert won == f"{100 * rates[shape]:.0f}%" and free == f"{100 * share:.0f}%"
        assert (on_free == "-") == (share == 0) and (on_busy == "-") == (share == 1)


def test_record_gives_a_run_made_before_the_figures_its_own_run_would_have(tmp_path):
    """lab/bench/more_blocks.py --record, on a run whose results.json lacks the other worlds (as
    runs made before eval_blocks do): it writes what taskexp.train wrote, to the byte."""
    import json
    import sys
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                    "lab", "bench"))
    import more_blocks
    out = str(tmp_path / "run")
    cli.main(["--rounds", "0", "--scale", "0.02", "--label-epochs", "3", "--out", out])
    path = os.path.join(out, "results.json")
    with open(path) as f:
        made = f.read()
    before = json.loads(made)
    del before["config"]["eval_blocks"]
    for rnd in before["rounds"]:
        del rnd["blocks"]
    with open(path, "w") as f:
        json.dump(before, f, indent=1)
    more_blocks.record(out, workers=1)
    with open(path) as f:
        assert f.read() == made
