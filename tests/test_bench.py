"""The reproduction report end to end at a tiny budget: lab/bench/reproduce.py runs its variants,
writes RESULTS.md with every table and the targets, and the figures it links to; the README's
headline is what the runs kept in lab/results/runs/ say (lab/bench/headline.py);
lab/bench/bench_speed.py times every phase of a run and counts the operations of its matrix
products; lab/bench/value_fit.py replays a run's value fits; lab/bench/run_seeds.py hands its runs
to an engine (lab/bench/engine.py, submitit); lab/bench/branch.py goes on from a run's round 0
under other settings of the later rounds."""
import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BENCH = os.path.join(ROOT, "lab", "bench")
sys.path.insert(0, BENCH)
import bench_speed  # noqa: E402
import branch  # noqa: E402
import engine  # noqa: E402
import headline  # noqa: E402
import value_fit  # noqa: E402
from run_seeds import FLAGS  # noqa: E402

import taskexp  # noqa: E402
import taskexp_cli as cli  # noqa: E402
from taskexp_lib import one_blas_thread, rollout  # noqa: E402
from taskexp_lib.config import Config, saved_config  # noqa: E402


def test_reproduce_writes_the_report(tmp_path):
    out, figs = tmp_path / "R.md", tmp_path / "figs"
    subprocess.run([sys.executable, os.path.join(BENCH, "reproduce.py"), "--seeds", "0",
                    "1", "--features", "plain", "--variants", "ours", "direct-ppo", "no-restrict",
                    "--rounds", "2", "--direct-rounds", "1", "--scale", "0.02", "--root",
                    str(tmp_path / "runs"), "--out", str(out), "--figures", str(figs),
                    "--", "--label-epochs", "6", "--expand-episodes", "3000"],   # quicker
                   check=True, cwd=tmp_path,
                   capture_output=True)
    text = out.read_text()
    for part in ("### Targets", "### Does equation (1) pick goals", "### Table 1", "### Table 2",
                 "### Direct PPO", "### Table 3", "## Where we differ from the paper"):
        assert part in text, part
    # one row per round of ours, with the paper's round-2 figures next to ours
    assert re.search(r"\| 2 \| .* \| 18 \| .* \| 5\.0 \|", text)
    assert "| zero-shot mean over shapes >= the paper's, round 2 | " in text
    # the actor's leading indicator per round, and the shapes' chance level beside direct PPO
    assert "### The order of the moves" in text and re.search(r"Chance level .* I \d", text)
    assert (tmp_path / "runs" / "ours-seed1" / "build_order.json").exists()
    # the round-0 critic's leading indicator, measured on both seeds' checkpoints and kept
    assert "| feasible among equation (1)'s picks, round-0 critic >= 75% |" in text
    assert (tmp_path / "runs" / "ours-seed1" / "feasible_goals.json").exists()
    assert "after round 1" in text and "w/o restriction" in text
    for name in ("fig1_plain.png", "fig2_plain.png"):
        assert (figs / name).stat().st_size > 1000 and name in text
    assert sorted(os.listdir(tmp_path / "runs")) == sorted(
        [f"{v}-seed{s}{ext}" for v in ("ours", "direct-ppo", "ours-norestrict") for s in (0, 1)
         for ext in ("", ".log")])
    # the headline from two of these runs, kept, then written between a README's markers
    kept = tmp_path / "kept"
    headline.keep([tmp_path / "runs" / f"ours-seed{s}" for s in (0, 1)], kept=kept)
    runs = headline.load("ours", kept=kept)
    assert [r["config"]["seed"] for r in runs] == [0, 1] and "feasible" in runs[0]
    assert not any(line.startswith("| w/o restriction") for line in headline.comparison(
        {"ours": runs}) + headline.headline({"ours": runs})), "Table 3 without kept ablations"
    # an ablation kept too: judged by its own rule, and a row of Table 3
    headline.keep([tmp_path / "runs" / f"ours-norestrict-seed{s}" for s in (0, 1)], kept=kept)
    by_variant = headline.load_all(kept=kept)
    assert by_variant["ours-norestrict"][1]["feasible"]["restrict"] is False
    assert runs[1]["feasible"]["restrict"] is True
    lines = headline.comparison(by_variant)
    assert sum(line.startswith("| w/o restriction |") for line in lines) == 1
    assert sum(line.startswith("| w/o restriction (`--no-restrict`) |")
               for line in headline.headline(by_variant)) == 1
    readme = tmp_path / "README.md"
    readme.write_text(f"intro\n{headline.BEGIN}\nold\n{headline.END}\nrest\n")
    headline.write_readme(readme, lines)
    assert headline.readme_block(readme) == lines
    assert readme.read_text().startswith("intro\n") and readme.read_text().endswith("rest\n")
    # the report written again from the kept copies: the same tables; a run not kept is named
    report = [sys.executable, os.path.join(BENCH, "reproduce.py"), "--seeds", "0", "1",
              "--features", "plain", "--rounds", "2", "--kept", str(kept), "--out",
              str(tmp_path / "K.md"), "--figures", str(figs), "--variants", "ours", "no-restrict"]
    subprocess.run(report, check=True, cwd=tmp_path, capture_output=True)

    def tables(md):                        # every table row but direct PPO's, not kept here
        parts = [part for part in md.split("\n### ") if not part.startswith("Direct PPO")]
        return [ln for part in parts for ln in part.split("\n")
                if ln.startswith("|") and "direct PPO" not in ln]
    assert tables((tmp_path / "K.md").read_text()) == tables(text)
    missing = subprocess.run(report + ["direct-ppo"], cwd=tmp_path, capture_output=True, text=True)
    assert missing.returncode != 0 and "keeps no plain direct-ppo run of seed 0" in missing.stderr


def test_the_readme_headline_is_what_the_kept_runs_say():
    """Every figure of the README's headline comes from lab/results/runs/: edit one, and this
    fails."""
    by_variant = headline.load_all()
    assert [r["config"]["seed"] for r in by_variant["ours"]] == [0, 1, 2]
    # read as --resume reads a run's settings: a field added since a run was made has its default
    assert all(saved_config(r["config"]) == Config(seed=r["config"]["seed"])
               for r in by_variant["ours"]), "the kept runs are not of the default settings"
    # every row of today's code is its flag alone (main-9032628/ keeps the code before)
    for variant in (*headline.ABLATIONS, "no-labels"):
        runs = by_variant[headline.kept_name(variant)]
        seeds = [r["config"]["seed"] for r in runs]
        assert seeds == sorted(set(seeds)) and set(seeds) <= {0, 1, 2}, variant
        for r in runs:
            seed = str(r["config"]["seed"])
            rounds = str(r["config"]["rounds"])
            argv = ["--rounds", rounds, "--seed", seed, *FLAGS[variant], "--out", "unused"]
            made = cli.parse_args(argv).cfg
            assert saved_config(r["config"]) == made, f"{variant} seed {seed}: not its flag alone"
    assert headline.readme_block(os.path.join(ROOT, "README.md")) == headline.headline(by_variant)
    notes = os.path.join(ROOT, "lab", "notes.md")
    assert headline.readme_block(notes) == headline.comparison(by_variant)


def test_results_md_is_what_the_kept_runs_say(tmp_path):
    """RESULTS.md is written from lab/results/runs/ (reproduce.py --kept): written again, its tables
    and its discussion are the same; edit a figure of either, and this fails."""
    out = tmp_path / "R.md"
    subprocess.run([sys.executable, os.path.join(BENCH, "reproduce.py"), "--kept",
                    "--out", str(out), "--figures", str(tmp_path / "results")],
                   check=True, cwd=ROOT, capture_output=True)
    with open(os.path.join(ROOT, "lab", "RESULTS.md")) as f:
        committed = f.read().split("\n")
    again = out.read_text().split("\n")
    assert committed[0] == again[0] and committed[3:] == again[3:]


def test_the_readme_times_are_what_times_json_says():
    """The README's times for the smoke test, the default run and the tests come from
    lab/results/times.json (lab/bench/times.py), all three measured with one commit on one
    machine: edit one in the README, and this fails."""
    import times
    measured = times.load()
    assert {w: measured[w]["command"] for w in times.COMMANDS} == {
        w: " ".join(c) for w, c in times.COMMANDS.items()}
    assert len({(measured[w]["commit"], measured[w]["machine"]) for w in times.COMMANDS}) == 1
    lines = times.readme_lines(measured)
    assert headline.readme_block(os.path.join(ROOT, "README.md"), times.BEGIN, times.END) == lines
    assert f"about {times.minutes(measured['default']['seconds'])} on 2 cores" in lines[2]
    edited = dict(measured, smoke=dict(measured["smoke"], seconds=1))
    assert times.readme_lines(edited) != lines


def test_what_the_readme_quotes_from_results_md_is_in_it():
    """The README's paragraph on the full report quotes RESULTS.md: each figure must be there."""
    with open(os.path.join(ROOT, "README.md")) as f:
        readme = f.read()
    with open(os.path.join(ROOT, "lab", "RESULTS.md")) as f:
        results = f.read()
    paragraph = readme.split("**The full report**", 1)[1].split("\n\n", 1)[0]
    quoted = re.findall(r"\d+ \+- \d+%", paragraph)
    assert quoted and all(q in results for q in quoted), quoted


def test_bench_speed_accounts_for_every_phase(tmp_path):
    """lab/bench/bench_speed.py's time by phase: every phase of a tiny run is timed, none twice
    (what is left of the wall time for the rest is positive), and the run's code is restored after.
    At scale 0.02 the base policy solves a few tasks, so that there are outcomes to label."""
    cfg = cli.parse_args(["--rounds", "1", "--scale", "0.02", "--out", "unused"]).cfg
    before = taskexp.labelled
    with one_blas_thread():
        counted, simulate = bench_speed.Flops(), rollout.simulate
        try:
            (_, per_round, _), spent, actions = bench_speed.by_phase(cfg, 1, str(tmp_path / "run"),
                                                                     counted)
        finally:
            counted.restore()
    assert taskexp.labelled is before and rollout.simulate is simulate
    assert list(per_round) == [0, 1]
    assert all(s > 0 for s in spent.values()), spent      # the rest too: nothing counted twice
    # every phase that steps the world or runs a network has its actions and operations booked
    for line in ("base demos (sec 4.1)", "PPO: rollouts", "task expansion (sec 4.2)",
                 "zero-shot evaluation", "labels: runs, ranking"):
        assert actions[line] > 0, (line, actions)
    assert set(actions) <= set(spent) and set(counted.by_phase) <= set(spent)
    assert counted.by_phase["behaviour cloning (BC)"] > 0 and "base demos (sec 4.1)" not in \
        counted.by_phase                                   # no network in the random demos
    assert sum(counted.by_phase.values()) == sum(counted.total.values())


def test_bench_speed_counts_the_networks_operations():
    """bench_speed.Flops counts the matrix products of every forward and backward, checked
    against the attention network's operations written out by hand (2 per multiply-add), per
    token: the embedding F H + H H; per layer the projections Q, K, V, O (4 H H), the FFN (2 H H)
    and, per head, Q K^T and A V (n d each, n H over the heads); the head H H + H out. The
    backward does each product twice (x^T d and d W^T; four per-head products for two)."""
    agent = taskexp.make_agent(Config())
    B, n, H = 5, agent.n_blocks, agent.hidden
    f = agent.features(np.zeros((B, n, 6)))
    F, layers = f.shape[-1], agent.critic.layers
    per_token = lambda out: 2 * (F * H + H * H + layers * (6 * H * H + 2 * n * H) + H * H + H * out)
    counted = bench_speed.Flops()
    try:
        agent.critic.backward(np.ones_like(agent.critic.forward(f)))
        agent.actor.forward(f[:2])
    finally:
        counted.restore()
    actor_out = 1 + agent.n_x + agent.n_y
    assert counted.total == {"forward": B * n * per_token(1) + 2 * n * per_token(actor_out),
                             "backward": 2 * B * n * per_token(1)}
    counted.total["forward"] = 0
    agent.actor.forward(f)                                     # restored: nothing counts
    assert counted.total["forward"] == 0


def test_value_fit_replays_the_runs_fits():
    """lab/bench/value_fit.py: with nothing held out and the run's own settings, a replayed value
    fit ends at the run's critic to the byte, so the held-out curves it prints are of the run's own
    fits; held out, only rows new to the fit leave its training set."""
    cfg = cli.parse_args(["--rounds", "1", "--scale", "0.03", "--out", "unused"]).cfg
    with one_blas_thread():
        fresh, fits = value_fit.round0_fits(cfg, 1)
        assert len(fits) == cfg.label_iters
        fit, n_old = fits[1], len(fits[0]["obs"])
        agent, curve = value_fit.replay(fresh, fit, n_old, fit["epochs"], fit["batch"], fit["lr"],
                                        holdout=0)
        assert len(curve) == fit["epochs"] and np.isnan(curve[0][1])
        for k, p in agent.critic.params.items():
            assert p.tobytes() == fit["after"][k].tobytes(), k
        train, test = value_fit.held_out(n_old, len(fit["obs"]), 0.5, np.random.default_rng(0),
                                         block=4)
        assert len(test) and test.min() >= n_old and set(range(n_old)) <= set(train)
        assert sorted([*train, *test]) == list(range(len(fit["obs"])))
        agent, curve = value_fit.replay(fresh, fit, n_old, 2, fit["batch"], fit["lr"],
                                        holdout=0.5)
        assert np.isfinite(curve).all()
        assert any((p != fit["after"][k]).any() for k, p in agent.critic.params.items())


def test_engine_runs_the_seeds_as_direct_runs_do_and_reuses_them(tmp_path):
    """lab/bench/run_seeds.py hands its runs to submitit's local executor: two tiny runs (two
    seeds) give the bytes of the same runs made directly, and a second call starts none."""
    root = tmp_path / "runs"
    seeds = [sys.executable, os.path.join(BENCH, "run_seeds.py"), "--seeds", "0", "1",
             "--rounds", "1", "--scale", "0.02", "--root", str(root), "--", "--label-epochs", "6",
             "--expand-episodes", "3000"]
    first = subprocess.run(seeds, check=True, capture_output=True, text=True, cwd=tmp_path)
    assert "0 of 2 runs finished already; 2 to go" in first.stdout, first.stdout
    for seed in (0, 1):
        direct = tmp_path / f"direct{seed}"
        cli.main(["--rounds", "1", "--scale", "0.02", "--seed", str(seed), "--label-epochs", "6",
                  "--expand-episodes", "3000", "--out", str(direct)])
        made = root / f"ours-seed{seed}"
        for name in ("round0.npz", "round1.npz"):
            assert (made / name).read_bytes() == (direct / name).read_bytes(), (seed, name)
        results = [json.loads((d / "results.json").read_text()) for d in (made, direct)]
        assert [{**r, "wallclock": None} for r in results][0] == {**results[1], "wallclock": None}
    again = subprocess.run(seeds, check=True, capture_output=True, text=True, cwd=tmp_path)
    assert "2 of 2 runs finished already; 0 to go" in again.stdout, again.stdout
    assert "| ours | " in again.stdout                             # the tables, as before


def test_engine_reports_a_failed_run_with_its_log_and_finishes_the_others(tmp_path):
    fail = [sys.executable, "-c", "import sys; print('went wrong here'); sys.exit(3)"]
    ok = [sys.executable, "-c", "print('fine')"]
    said = []
    failed = engine.run_all({"bad": (fail, str(tmp_path / "bad.log")),
                             "good": (ok, str(tmp_path / "good.log"))},
                            str(tmp_path / "jobs"), jobs=2, say=said.append)
    assert failed == {"bad": "went wrong here\n"}
    assert "finished good" in said and any(s.startswith("FAILED bad") for s in said), said
    assert (tmp_path / "good.log").read_text() == "fine\n"


def test_a_branch_of_round_0_gives_the_bytes_of_a_run_made_with_its_settings(tmp_path):
    """Round 0 reads none of branch.LATER: a round-0 run, branched with other settings of the
    later rounds and resumed, gives the round-1 checkpoint of a run made with them throughout.
    A setting that round 0 reads is refused."""
    tiny = ["--scale", "0.02", "--label-epochs", "6", "--expand-episodes", "3000"]
    later = {"other_orders": False, "buffer_size": 1000, "distill_epochs": (1,)}
    flags = ["--no-other-orders", "--buffer-size", "1000", "--distill-epochs", "1"]
    cli.main(["--rounds", "0", *tiny, "--out", str(tmp_path / "base")])
    branch.branch(str(tmp_path / "base"), str(tmp_path / "branch"), later)
    cli.main(["--resume", "--rounds", "1", "--out", str(tmp_path / "branch")])
    cli.main(["--rounds", "1", *tiny, *flags, "--out", str(tmp_path / "direct")])
    for name in ("round0.npz", "round1.npz"):
        branched, direct = (tmp_path / d / name for d in ("branch", "direct"))
        assert branched.read_bytes() == direct.read_bytes(), name
    made = json.loads((tmp_path / "branch" / "results.json").read_text())
    assert made["branched_from"] == dict(run=str(tmp_path / "base"), ablation=False,
                                         changes=json.loads(json.dumps(later)))   # tuples: lists
    # BC over the base demos takes bc_epochs, over the generated data distill_epochs
    assert [len(made["rounds"][k]["bc_loss"]) for k in (0, 1)] == [Config.bc_epochs, 1]
    with pytest.raises(SystemExit, match="--p-add: round 0 reads it"):
        branch.branch(str(tmp_path / "base"), str(tmp_path / "other"), {"p_add": 0.7}, True)
    with pytest.raises(SystemExit, match="--select: round 0 reads it"):
        branch.branch(str(tmp_path / "base"), str(tmp_path / "other"), {"select": "end2new"})
    branch.branch(str(tmp_path / "base"), str(tmp_path / "end2new"), {"select": "end2new"}, True)
    with pytest.raises(SystemExit, match="branch a run made with --rounds 0"):
        branch.branch(str(tmp_path / "direct"), str(tmp_path / "other"), later)


def test_levers_averages_each_figure_over_the_runs(tmp_path):
    """lab/bench/levers.py: the mean over the shapes, each family's mean over its tasks and the
    other worlds, per run, and per task over the runs; only the rounds every run has."""
    import levers
    record = lambda k, a: dict(round=k, eval={"I": a, "Y": 0.0}, families={"air": {"1 up": a}},
                               blocks={"7": {"I": 1.0}})
    for name, a in (("one", 0.2), ("two", 0.6)):
        rounds = [record(k, a) for k in range(2 if name == "one" else 3)]
        (tmp_path / f"{name}.json").write_text(json.dumps({"rounds": rounds}))
    rows = levers.summary(levers.load(str(tmp_path / "*.json")))
    assert [k for k, *_ in rows] == [0, 1]
    _, means, tasks = rows[1]
    assert np.allclose(means["I/Y/3T"], [0.1, 0.3]) and np.allclose(means["air"], [0.2, 0.6])
    assert tasks["I/Y/3T"] == {"I": 0.4, "Y": 0.0} and means["7 blocks"] == [1.0, 1.0]


def test_the_probe_pairs_differ_in_one_goal_and_its_control_scores_half():
    """lab/bench/probe.py: each minimal pair keeps block i's own features and drops the goal of
    the block right below its goal; a probe on those features cannot beat chance."""
    import probe

    from agent import Agent
    from env2d import BlockWorld
    from taskexp_lib import shapes
    tasks = shapes.eval_tasks(Config(eval_episodes=6), BlockWorld(6, drop=True))["I"]
    pairs = probe.minimal_pairs(tasks)
    assert len(pairs) == 6 * 3               # a tower of four: the top three wait for the one below
    agent = Agent(6, n_x=37, n_y=1, hidden=16, seed=0)
    for _, i, with_j, without in pairs:
        assert (with_j[:, 5] - without[:, 5]).sum() == 1 and with_j[i, 5] == without[i, 5] == 1
        f = agent.features(np.stack([with_j, without]))
        assert np.array_equal(f[0, i], f[1, i])
    X, y = np.random.default_rng(0).normal(size=(40, 3)), np.r_[np.ones(20), -np.ones(20)]
    train = np.arange(40) % 2 == 0
    assert probe.probe_accuracy(np.ones((40, 3)), y, train) == 0.5     # rows alike: one guess
    X[:, 0] += 3 * y                                                  # a column that tells them
    assert probe.probe_accuracy(X, y, train) == 1.0


def test_greedy_tries_a_checkpoint_with_both_rules_on_the_runs_tests(tmp_path):
    """lab/bench/greedy.py: every test a run makes after a round (the shapes, the families, the
    other worlds), once per rule of Config.greedy, on the same scenes."""
    import greedy

    from agent import GREEDY, Agent
    Agent(6, n_x=37, n_y=1, hidden=16, seed=0).save(tmp_path / "round0.npz")
    found = greedy.measure(str(tmp_path / "round0.npz"), episodes=2)
    assert list(found) == list(GREEDY)
    for r in found.values():
        assert list(r) == ["eval", "families", "blocks"] and list(r["blocks"]) == ["7", "8"]
        assert list(r["families"]) == list(Config.families)
        assert [name for name, _ in greedy.summary(r)] == ["I/Y/3T", "blocked", "air",
                                                           "7 blocks", "8 blocks"]
    cfg = greedy.run_config(str(tmp_path / "round0.npz"), seed=3)
    assert cfg.seed == 3 and cfg.greedy == "joint"            # no results.json: the defaults
