"""Tests of the pipeline: task sampling, goal selection, relabelling, shapes, and the CLI end to
end."""
import json
import os

import numpy as np
import pytest

import taskexp
import taskexp_cli as cli
from agent import Agent
from env2d import BlockWorld
from taskexp_lib import labels, shapes
from taskexp_lib.checkpoint import load_npz
from taskexp_lib.features import AUX_FACTS
from taskexp_lib.geometry import BLOCK_H, is_success, layer, same_spot
from taskexp_lib.rollout import Trajectory


@pytest.fixture
def env():
    return BlockWorld(6)


def test_alter_makes_exactly_one_alteration_and_both_kinds(env):
    rng = np.random.default_rng(0)
    goals = {0: (0.1, 0.025), 3: (-0.2, 0.075)}
    kinds = set()
    for _ in range(300):
        new = taskexp.alter(goals, env, rng)
        added = set(new) - set(goals)
        changed = [b for b in goals if new[b] != goals[b]]
        assert set(goals) <= set(new)
        assert len(added) + len(changed) == 1, (goals, new)
        kinds.add("add" if added else "modify")
    assert kinds == {"add", "modify"}


@pytest.mark.parametrize("restrict", [True, False])
def test_alter_never_puts_two_goals_on_the_same_spot(env, restrict):
    """The world refuses goals that no two blocks can meet; alter never proposes them, even when
    a crowded task leaves few free spots."""
    rng = np.random.default_rng(3)
    goals = {b: (float(env.x_bins[4 * b]), float(env.y_bins[0])) for b in range(5)}
    for _ in range(2000):
        candidate = taskexp.alter(goals, env, rng, restrict)
        assert same_spot(candidate) is None, candidate
        env.reset(options={"goals": candidate})                   # and the world accepts it


def test_alter_without_restriction_draws_unrelated_tasks(env):
    rng = np.random.default_rng(1)
    counts = {len(taskexp.alter({0: (0.0, 0.025)}, env, rng, restrict=False)) for _ in range(300)}
    assert counts == set(range(1, env.n_blocks + 1))


class FixedValues:
    """A stand-in critic: V(s, g) read from a table keyed by (state id, candidate id)."""

    def __init__(self, v0, vT):
        self.v = {0: np.array(v0), 1: np.array(vT)}

    def value(self, obs):
        which = int(obs[0][0, 0])            # the state id is planted in block 0's x
        return self.v[which]


def test_free_table_puts_about_half_the_base_goals_on_a_block():
    """sec 4.1 as the authors built it: "onto the table" moves land on free table spots, so in
    the world that drops about half of the moved blocks' goals lie on another block (without
    free_table, most table moves land on a block)."""
    env = BlockWorld(6, drop=True)
    on_block = {}
    for free in (False, True):
        cfg = taskexp.Config(free_table=free)
        tasks, _, _ = taskexp.base_demos(cfg, env, np.random.default_rng(0), 300)
        moved = [next(iter(goals.values())) for _, goals in tasks]    # the moved block comes first
        on_block[free] = np.mean([layer(y) >= 1 for _, y in moved])
    assert 0.35 < on_block[True] < 0.65 and on_block[False] > 0.7, on_block


def test_select_goal_equation_1_and_ablations():
    s0, sT = np.zeros((6, 6)), np.ones((6, 6))
    cands = [{1: (0.0, 0.025)}] * 3
    agent = FixedValues(v0=[0.9, 0.1, 0.5], vT=[1.0, 0.6, 0.95])
    # ours: V(sT)-V(s0) = [0.1, 0.5, 0.45]; end2new: V(sT); init2new: -V(s0)
    assert taskexp.select_goal(agent, s0, sT, cands, "ours") == 1
    assert taskexp.select_goal(agent, s0, sT, cands, "end2new") == 0
    assert taskexp.select_goal(agent, s0, sT, cands, "init2new") == 1
    agent = FixedValues(v0=[0.9, 0.3, 0.2], vT=[1.0, 0.6, 0.95])
    assert taskexp.select_goal(agent, s0, sT, cands, "init2new") == 2


def test_relabel_uses_reached_positions(env):
    states = np.zeros((3, 6, 6))
    states[:, :, 1] = BLOCK_H / 2
    states[:, :, 0] = np.linspace(-0.4, 0.4, 6)
    states[2, 2, :2] = (0.3, 1.5 * BLOCK_H)          # block 2 moved, onto something
    traj = taskexp.Trajectory({2: (0.0, 0.3)}, states, np.zeros((2, 3), int), False)
    r = taskexp.relabel(traj, env)
    assert r.success and r.goals == {2: (0.3, 1.5 * BLOCK_H)}
    assert is_success(r.states[-1], r.goals) and not is_success(r.states[0], r.goals)
    traj = taskexp.Trajectory({0: (0.3, 0.3)}, states, np.zeros((2, 3), int), False)
    assert taskexp.relabel(traj, env) is None        # block 0 never moved: nothing achieved


@pytest.mark.parametrize("name", list(shapes.SHAPES))
def test_shapes_are_held_out_and_buildable(env, name):
    rng = np.random.default_rng(2)
    for _ in range(5):
        goals = shapes.place_cells(shapes.SHAPES[name], env, rng)
        high = [b for b, (_, y) in goals.items() if layer(y) >= 1]
        assert len(goals) >= 4 and len(high) >= 3
        obs, _ = env.reset(seed=int(rng.integers(1000)), options={"goals": goals})
        # build bottom-up by hand; the finished shape must stand and count as success
        for b, (x, y) in sorted(goals.items(), key=lambda kv: kv[1][1]):
            obs, reward, terminated, truncated, info = env.step(env.encode_action(b, x, y))
            assert not info["noop"], (name, goals, b)
        assert reward == 1.0 and terminated, (name, goals, env.get_state()[:, :2])


def run_cli(tmp_path, *extra):
    out = str(tmp_path / "run")
    # budgets x 0.02, fewer value-fit epochs and expansion attempts: the plumbing
    cli.main(["--rounds", "1", "--scale", "0.02", "--label-epochs", "6",
              "--expand-episodes", "3000", "--out", out, *extra])
    with open(os.path.join(out, "results.json")) as f:
        return out, json.load(f)


def test_cli_end_to_end_tiny_budget(tmp_path, capsys):
    out, res = run_cli(tmp_path)
    assert [r["round"] for r in res["rounds"]] == [0, 1]
    assert set(res["rounds"][1]["eval"]) == {"I", "Y", "3T"}
    families = res["rounds"][1]["families"]            # not in the paper: blocks no goal names
    assert set(families) == {"blocked", "air"} and set(families["blocked"]) == {"I", "Y"}
    blocks = res["rounds"][1]["blocks"]                # the same weights with 7 and 8 blocks
    assert set(blocks) == {"7", "8"} and set(blocks["8"]) == {"I", "Y", "3T"}
    for k in (0, 1):
        agent = Agent.load(os.path.join(out, f"round{k}.npz"))
        assert agent.act(np.zeros((6, 6), np.float32)).shape == (3,)
    expansion = res["rounds"][1]["expansion"]          # the leading indicator of equation (1)
    assert expansion["picks_reached"] == expansion["joined"] / expansion["successful"]
    printed = capsys.readouterr().out
    assert "Table 1" in printed and "Table 2" in printed and "picks reached" in printed
    assert "Zero-shot success, blocked" in printed and "| 1 up | 2 up |" in printed
    assert "worlds of other block counts (the weights learnt with 6)" in printed
    assert "  8 blocks, the weights learnt with 6: I " in printed            # each round's log
    drawn = str(tmp_path / "tried.png")                # after the run: a structure of one's own
    cli.main(["try", os.path.join(out, "round1.npz"), "0,0 0,1 1.5,0 1.5,1 0.75,2", "--blocks",
              "7", "--scenes", "2", "--out", drawn])
    assert "of 2 scenes" in capsys.readouterr().out and os.path.exists(drawn)
    assert os.path.exists(os.path.join(out, "fig1_max_goal_height.png"))


def test_every_phase_of_a_run_shows_progress(tmp_path):
    """Each phase that takes more than a few seconds at full budget draws a progress bar: the CLI
    passes a bar factory down, and every phase must ask it for one."""
    from tqdm import tqdm
    asked = []

    def bar(total, desc):
        asked.append(desc)
        return tqdm(total=total, disable=True)
    cfg = cli.parse_args(["--rounds", "1", "--scale", "0.02", "--label-epochs", "6",
                          "--expand-episodes", "3000", "--out", "unused"]).cfg
    cli.run(cfg, str(tmp_path / "run"), log=lambda *a: None, bar=bar)
    phases = {"demos", "BC", "PPO base", "collect 1", "rank 1", "label 1", "value fit",
              "pair value fit", "collect", "eq. (1)", "verify", "other orders", "PPO distil",
              "eval", "blocked", "air", "7", "8"} | ({"parts"} if taskexp.Config.goal_parts
                                                       else set())
    assert phases <= set(asked), phases - set(asked)


def test_same_seed_same_results_different_seed_different(tmp_path):
    runs = [run_cli(tmp_path / name, "--seed", seed)
            for name, seed in (("a", "3"), ("b", "3"), ("c", "4"))]
    strip = [{k: v for k, v in r.items() if k != "wallclock"} for _, r in runs]
    files = [open(os.path.join(out, "round1.npz"), "rb").read() for out, _ in runs]
    assert strip[0] == strip[1] and files[0] == files[1]
    assert files[0] != files[2]


def test_top_candidates_follow_equation_1_and_outcomes_are_discounted():
    class GoalX:          # V(s, g) = block 1's goal x from s_T (block 0 at x = 1), 0 from s_0
        def value(self, obs):
            return obs[:, 1, 3] * obs[:, 0, 0]
    s0, sT = np.zeros((6, 6)), np.ones((6, 6))
    traj = Trajectory({}, np.stack([s0, sT]), np.zeros((1, 3), np.int64), True)
    cands = [{1: (x, 0.025)} for x in (0.1, 0.3, -0.2, 0.2)]
    assert labels.top_candidates(GoalX(), traj, cands, 3, taskexp.Pieces(), "ours") == [1, 3, 0]
    three = Trajectory({}, np.zeros((4, 6, 6)), np.zeros((3, 3), np.int64), True)
    assert np.allclose(labels.discounted_outcome(three, 0.9), [0.81, 0.9, 1.0])
    three.success = False
    assert not labels.discounted_outcome(three, 0.9).any()


def test_labelled_outcomes_for_v_are_recorded_and_reproducible(tmp_path):
    """On by default, once, after the base PPO (round 0), and not before the later expansions;
    --scale shrinks them; 0 is off."""
    flags = ("--label-iters", "2", "--label-epochs", "2")
    runs = [run_cli(tmp_path / name, *flags) for name in ("a", "b")]
    config, rounds = runs[0][1]["config"], runs[0][1]["rounds"]
    assert config["label_tasks"] == round(0.02 * taskexp.Config().label_tasks)
    assert rounds[0]["label_runs"] > 0 and len(rounds[0]["label_loss"]) == 1
    assert 0 <= rounds[0]["label_success"] <= 1
    assert not any(k.startswith("label_") for k in rounds[1])
    files = [open(os.path.join(out, "round1.npz"), "rb").read() for out, _ in runs]
    assert files[0] == files[1]
    _, off = run_cli(tmp_path / "off", "--label-tasks", "0")
    assert off["config"]["label_tasks"] == 0
    assert not any(k.startswith("label_") for r in off["rounds"] for k in r)


@pytest.mark.parametrize("flags, network, features, n_y", [
    ([], "attention", "plain", 1),                        # the defaults: drop, learn relations
    (["--network", "setnet", "--features", "relations", "--action", "place", "--warmup", "8"],
     "setnet", "relations", 6),                            # the earlier defaults, as options
    (["--features", "relations+leave"], "attention", "relations+leave", 1),    # issue 53's L
    (["--features", "relations+leave+stay"], "attention", "relations+leave+stay", 1)])   # S
def test_cli_network_features_and_action_reach_the_agent(tmp_path, flags, network, features, n_y):
    out, res = run_cli(tmp_path, *flags)
    agent = Agent.load(os.path.join(out, "round1.npz"))
    assert (agent.network, agent.feature_set, agent.n_y) == (network, features, n_y)
    assert res["config"]["action"] == ("drop" if n_y == 1 else "place")
    width = {"plain": 52, "relations": 79, "relations+leave": 100,
             "relations+leave+stay": 101}[features]
    assert agent.features(np.zeros((1, 6, 6))).shape[-1] == width


def test_cli_aux_relations_reaches_the_agent_and_resumes(tmp_path):
    """--aux-relations: the run's actor has a fact column per AUX_FACTS after the policy's, its
    checkpoints keep the weight, and the run resumes with it."""
    out, res = run_cli(tmp_path, "--aux-relations", "0.5")
    agent = Agent.load(os.path.join(out, "round1.npz"))
    assert agent.aux == 0.5 and res["config"]["aux_relations"] == 0.5
    f = agent.features(np.zeros((1, 6, 6)))
    assert agent.actor.forward(f).shape[-1] == agent.n_policy + len(AUX_FACTS)
    cli.main(["--resume", "--out", out, "--rounds", "2"])
    assert Agent.load(os.path.join(out, "round2.npz")).aux == 0.5


def test_the_greedy_rule_reaches_the_evaluation(capsys):
    """--greedy block: the run's agent takes block_mode when evaluate asks for the greedy action;
    the default stays the joint mode; a rule that does not exist is refused."""
    cfg, *_ = cli.parse_args(["--greedy", "block", "--hidden", "16", "--eval-episodes", "4"])
    assert cfg.greedy == "block" and taskexp.Config().greedy == "joint"
    agent, env = taskexp.make_agent(cfg), BlockWorld(cfg.n_blocks)
    assert agent.greedy == "block"
    tasks = shapes.eval_tasks(cfg, env)["I"]
    dists = []                                       # the policy at every step, in order
    agent.policy = lambda f, policy=agent.policy: dists.append(policy(f)) or dists[-1]
    trajs = taskexp.run_episodes(agent, tasks, [env], deterministic=True)   # one at a time
    taken = np.concatenate([t.actions for t in trajs])
    assert np.array_equal(taken, np.concatenate([d.block_mode() for d in dists]))
    assert not np.array_equal(taken, np.concatenate([d.mode() for d in dists]))
    with pytest.raises(SystemExit):
        cli.parse_args(["--greedy", "first"])
    assert "--greedy: invalid choice" in capsys.readouterr().err


@pytest.mark.parametrize("flags", [["--select", "init2new", "--no-restrict"],
                                   ["--baseline", "direct-ppo"]])
def test_cli_ablations_run(tmp_path, flags):
    _, res = run_cli(tmp_path, *flags)
    assert [r["round"] for r in res["rounds"]] == [0, 1]
    cfg = res["config"]
    assert ((cfg["select"], cfg["restrict"]) == ("init2new", False)
            or cfg["baseline"] == "direct-ppo")


def test_ppo_batch_returns_are_lambda_returns():
    """GAE over a flattened batch: per episode, R_t = A_t + V_t with the terminal value 0."""
    cfg = taskexp.Config(gamma=0.9, gae_lambda=0.95)
    obs_state = np.zeros((4, 6, 6))
    t1 = taskexp.Trajectory({0: (0.0, 0.025)}, obs_state, np.zeros((3, 3), int), True,
                            logp=np.zeros(3), values=np.array([0.7, 0.8, 0.9]))
    t2 = taskexp.Trajectory({0: (0.0, 0.025)}, obs_state[:3], np.zeros((2, 3), int), False,
                            logp=np.zeros(2), values=np.array([0.5, 0.4]))
    _, _, _, adv, ret = taskexp.ppo_batch([t1, t2], cfg)
    expected = []
    for t in (t1, t2):
        v, T, a, out = t.values, len(t.values), 0.0, []
        for k in reversed(range(T)):
            r = float(t.success and k == T - 1)
            v_next = v[k + 1] if k + 1 < T else 0.0
            a = r + cfg.gamma * v_next - v[k] + cfg.gamma * cfg.gae_lambda * a * (k + 1 < T)
            out.append(a + v[k])
        expected += out[::-1]
    assert (np.allclose(ret, expected)
            and np.allclose(adv, np.array(expected) - np.r_[t1.values, t2.values]))
    assert np.isclose(ret[2], 1.0) and np.isclose(ret[4], 0.0)      # success step; failed end


def test_histogram_figure_shows_each_round_share_spread_and_title():
    """Figure 1 of two seeds: each round's bars are its share of tasks per layer (mean over the
    seeds, std as error bars), on a log axis, titled, the legend beside the axes."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from taskexp_cli.report import histogram_figure
    per_round = [(0, [[8, 2, 0], [6, 4, 0]]), (1, [[5, 4, 1], [5, 4, 1]])]
    fig = histogram_figure(per_round, "Figure 1: test", "layer", 0, log=True)
    ax = fig.axes[0]
    heights = [p.get_height() for p in ax.patches]
    assert np.allclose(heights, [0.7, 0.3, 0.0, 0.5, 0.4, 0.1])
    assert ax.get_yscale() == "log" and "Figure 1: test" in ax.get_title()
    assert "2 seeds" in ax.get_title()
    bars = [c for c in ax.containers if hasattr(c, "patches")]
    assert all(c.errorbar is not None for c in bars) and len(bars) == 2    # the seeds' std
    renderer = FigureCanvasAgg(fig).get_renderer()
    legend = ax.get_legend().get_window_extent(renderer)
    assert legend.x0 >= ax.get_window_extent(renderer).x1                     # covers no bar


def test_cli_hindsight_on_goals_teaches_moves_of_blocks_no_goal_names(tmp_path):
    """--base-pairs and --goal-parts (taskexp_lib/hindsight.py) add steps that move a block no
    goal names, which the default's data never show, and reproduce byte for byte."""
    flags = ("--base-pairs", "4000", "--goal-parts", "4")   # x 0.02: 80 pairs
    (out, res), (again, _) = (run_cli(tmp_path / name, *flags) for name in ("a", "b"))
    assert res["rounds"][1]["expansion"]["parts"] > 0 and res["rounds"][1]["unnamed_moves"] > 0
    assert open(os.path.join(out, "round1.npz"), "rb").read() == \
        open(os.path.join(again, "round1.npz"), "rb").read()
    _, default = run_cli(tmp_path / "default")
    assert default["rounds"][1]["expansion"]["parts"] == 0
    assert default["rounds"][1]["unnamed_moves"] < res["rounds"][1]["unnamed_moves"]
    # --parts-in bc: BC learns the parts, PPO and the next round's expansion only whole demos
    bc, res_bc = run_cli(tmp_path / "bc", *flags, "--parts-in", "bc")
    info, info_bc = res["rounds"][1]["expansion"], res_bc["rounds"][1]["expansion"]
    assert info_bc == info                           # the same expansion: round 0 is the same
    demos = info["joined"] + info["relabelled"]
    prev = lambda run: len(load_npz(os.path.join(run, "state.npz"))["prev_tasks.goals"])
    assert prev(out) == demos + info["parts"] and prev(bc) == demos
    assert res_bc["rounds"][1]["unnamed_moves"] == res["rounds"][1]["unnamed_moves"]
