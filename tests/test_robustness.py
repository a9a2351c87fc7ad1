"""Robustness (issue 3): bad settings refused in one line, resume after a kill gives the same run,
Ctrl-C says how to resume, NaN stops training with where it happened, memory stays flat."""
import dataclasses
import functools
import gc
import json
import os
import signal
import subprocess
import sys
import time
import tracemalloc

import numpy as np
import pytest

import agent as agent_module
import taskexp
import taskexp_cli as cli
from agent import Agent
from taskexp_lib import checkpoint

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# budgets x 0.02, fewer value-fit epochs (a third of a tiny run's time) and half the expansion
# attempts: what these tests check (refusals, resume, workers, memory) does not depend on them
TINY = ["--scale", "0.02", "--label-epochs", "6", "--expand-episodes", "3000"]
PPO = dict(epochs=1, minibatch=16, clip=0.2, ent_coef=0.0, vf_coef=0.5, lr=1e-3, max_grad_norm=0.5)


def results_without_clock(out):
    with open(os.path.join(out, "results.json")) as f:
        res = json.load(f)
    res.pop("wallclock")
    return res


def child(*argv):
    """Run taskexp.py in a child process (so it can be killed) with its output piped."""
    return subprocess.Popen([sys.executable, "-u", os.path.join(ROOT, "taskexp.py"), *argv],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


# ----------------------------------------------------------------------------- the CLI

@pytest.mark.parametrize("argv, reason", [
    (["--rounds", "-1"], "--rounds must be >= 0"),
    (["--select", "best"], "invalid choice"),
    (["--scale", "-1"], "--scale must be in"),
    (["--blocks", "5"], "--blocks must be in 6..8"),
    (["--blocks", "9"], "--blocks must be in 6..8"),
    (["--seed", "-1"], "--seed must be >= 0"),
    (["--rounds", "x"], "invalid int"),
    (["--resume"], "--resume needs --out"),
    (["--resume", "--out", "runs/x", "--seed", "2"], "drop --seed"),
    (["--resume", "--out", "/nonexistent/run"], "holds no readable run"),
    (["--gamma", "1.5"], "--gamma must be <= 1"),
    (["--ppo-lr", "0"], "--ppo-lr must be > 0"),
    (["--aux-relations", "-1"], "--aux-relations must be >= 0"),
    (["--max-stay", "6"], "--max-stay must be below --blocks"),
    (["--shapes", "O"], "invalid choice"),
    (["--distill-epochs", "8", "0"], "--distill-epochs must be epochs >= 1"),
    (["--distill-epochs"], "--distill-epochs must be epochs >= 1, round by round, got none"),
    (["--shapes"], "--shapes must name at least one held-out shape"),
    (["--resume", "--out", "runs/x", "--ppo-steps", "9"], "drop --ppo-steps"),
])
def test_cli_refuses_bad_arguments_in_one_line(argv, reason, capsys):
    with pytest.raises(SystemExit) as e:
        cli.parse_args(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1, err                  # no usage block before it
    assert reason in err[0] and err[0].endswith("(see --help)")


@pytest.mark.parametrize("leftover", ["results.json", "state.npz", "round0.npz"])
def test_cli_refuses_a_directory_with_another_runs_files(tmp_path, leftover, capsys):
    (tmp_path / leftover).write_text("")
    with pytest.raises(SystemExit):
        cli.parse_args(["--out", str(tmp_path)])
    assert f"already holds a run ({leftover})" in capsys.readouterr().err


def test_out_that_is_a_file_is_refused_in_one_line(tmp_path, capsys):
    (tmp_path / "f").write_text("")
    with pytest.raises(SystemExit):
        cli.parse_args(["--out", str(tmp_path / "f")])
    err = capsys.readouterr().err.strip().splitlines()
    assert "is a file" in err[-1] and "Traceback" not in "".join(err)


def test_damaged_results_json_sends_the_user_nowhere_in_circles(tmp_path, capsys):
    """A run whose results.json is damaged: with state.npz intact, --resume goes on from it; with
    both damaged, a new run there is refused with what to do (delete), not with --resume."""
    out = str(tmp_path / "run")
    cli.main(["--rounds", "1", *TINY, "--out", out])
    with open(os.path.join(out, "results.json"), "w") as f:
        f.write("{broken")
    cfg, _, resume, *_ = cli.parse_args(["--resume", "--rounds", "2", "--out", out])
    assert resume and cfg.rounds == 2
    with open(os.path.join(out, "state.npz"), "w") as f:
        f.write("broken")
    for argv, phrase in ((["--out", out], "delete its files"),
                         (["--resume", "--rounds", "2", "--out", out], "holds no readable run")):
        with pytest.raises(SystemExit):
            cli.parse_args(argv)
        assert phrase in capsys.readouterr().err


def test_every_config_field_is_a_flag():
    """The flags are generated from taskexp.Config: each field can be set, with its docstring."""
    help_text = cli.parser().format_help()
    for f in dataclasses.fields(taskexp.Config):
        assert cli.flag(f.name) in help_text, f.name
        assert cli.field_docs(taskexp.Config).get(f.name), f"{f.name} has no docstring"
    cfg, *_ = cli.parse_args(["--ppo-steps", "123", "--no-restrict", "--shapes", "I", "Y",
                              "--p-add", "0.25", "--out", "unused"])
    assert (cfg.ppo_steps, cfg.restrict, cfg.shapes, cfg.p_add) == (123, False, ("I", "Y"), 0.25)


def test_help_shows_the_run_flags_first_then_the_paper_then_ours_then_examples():
    help_text = cli.parser().format_help()
    at = {name: help_text.index(name) for name in (
        "the run:", "the paper's hyperparameters", "beyond the paper", "examples:")}
    assert list(at) == sorted(at, key=at.get)
    options = help_text[at["the run:"]:]
    run = [options.index(f"\n  {name} ") for name in (
        "--out", "--seed", "--rounds", "--scale", "--workers", "--resume")]
    assert run == sorted(run) and run[-1] < options.index("the paper's hyperparameters")
    paper = options[options.index("the paper's"):options.index("beyond the paper")]
    assert "--candidates" in paper and "--label-tasks" not in paper and "--stretch" not in paper
    assert "taskexp --rounds 1 --scale 0.05" in help_text[at["examples:"]:]


def test_no_run_lands_in_the_folder_of_a_run_with_other_settings(tmp_path, monkeypatch):
    """The smoke test (--scale) and any setting not the default's name their own folder: the
    default run never finds (and --resume never goes on with) a run of other budgets there."""
    monkeypatch.chdir(tmp_path)
    out = lambda *argv: cli.parse_args(list(argv)).out
    default = os.path.join("runs", "ours-seed0")
    assert out() == out("--rounds", "1") == default
    smoke = out("--rounds", "1", "--scale", "0.05")
    assert smoke == os.path.join("runs", "ours-scale0.05-seed0")
    others = [out("--ppo-steps", "123"), out("--ppo-steps", "124"), out("--label-tasks", "500"),
              out("--scale", "0.05", "--candidates", "8"), smoke]
    assert default not in others and len(set(others)) == len(others), others
    assert out("--ppo-steps", "123") == out("--ppo-steps", "123")            # the same settings
    assert out("--ppo-steps", str(taskexp.Config.ppo_steps)) == default      # are the default's


def test_blocks_flag_names_the_run_and_reaches_the_world(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)                     # runs/ here holds no run of these names
    cfg, out, *_ = cli.parse_args(["--blocks", "7"])
    assert cfg.n_blocks == 7 and out == os.path.join("runs", "ours-7blocks-seed0")
    cfg, out, *_ = cli.parse_args(["--label-tasks", "0"])         # not the default run's folder
    assert cfg.label_tasks == 0 and out == os.path.join("runs", "ours-nolabels-seed0")
    cfg, out, *_ = cli.parse_args(["--features", "relations"])
    assert cfg.features == "relations" and out == os.path.join("runs", "ours-relations-seed0")


# ----------------------------------------------------------------------------- nothing lost

def test_killed_run_resumes_to_the_same_results(tmp_path, capsys):
    """SIGKILL in round 2 (after round 1 is saved), then --resume: results.json and every checkpoint
    equal those of a run never stopped."""
    whole, killed = str(tmp_path / "whole"), str(tmp_path / "killed")
    distill = ["--distill-epochs", "3", "1"]            # round 1: 3 BC epochs, then 1 each round
    cli.main(["--rounds", "3", *TINY, *distill, "--out", whole])
    p = child("--rounds", "3", *TINY, *distill, "--out", killed)
    for line in p.stdout:
        if line.startswith("round 1:"):
            break
    p.kill()
    p.communicate()
    assert not os.path.exists(os.path.join(killed, "round3.npz"))
    capsys.readouterr()
    cli.main(["--resume", "--out", killed])
    log = capsys.readouterr().out
    # a run at another scale never goes on silently: the note says whose budgets these are
    assert log.startswith(f"note: {killed} was made with budgets other than the default's (")
    # went on from the saved round rather than starting again (which would also give equal files)
    assert (f"resuming {killed} after round " in log and "[round 0]" not in log
            and "round 1:" not in log)
    assert results_without_clock(killed) == results_without_clock(whole)
    # BC epochs: bc_epochs over the base demos, then distill_epochs round by round, the last
    # value for every round after (also across the resume)
    epochs = [len(r["bc_loss"]) for r in results_without_clock(killed)["rounds"]]
    assert epochs == [taskexp.Config.bc_epochs, 3, 1, 1], epochs
    for k in range(4):
        with open(os.path.join(killed, f"round{k}.npz"), "rb") as a, \
                open(os.path.join(whole, f"round{k}.npz"), "rb") as b:
            assert a.read() == b.read(), k


def test_resume_can_add_rounds_and_refuses_other_settings(tmp_path, capsys):
    """A 1-round run extended to 2 equals a 2-round run; a state from other settings is refused."""
    one, two = str(tmp_path / "one"), str(tmp_path / "two")
    cli.main(["--rounds", "1", *TINY, "--out", one])
    cli.main(["--resume", "--rounds", "2", "--out", one])
    cli.main(["--rounds", "2", *TINY, "--out", two])
    assert results_without_clock(one) == results_without_clock(two)
    cfg, *_ = cli.parse_args(["--rounds", "3", *TINY, "--seed", "1",
                                   "--out", str(tmp_path / "new")])
    with pytest.raises(ValueError,
                       match=r"state.npz: saved by a run with other settings.*'seed': \(0, 1\)"):
        cli.run(cfg, one, log=lambda *a: None, resume=True)
    with open(os.path.join(one, "state.npz"), "r+b") as f:    # a truncated state file
        f.truncate(1000)
    with pytest.raises(ValueError, match="state.npz: not a readable"):
        cli.run(cli.parse_args(["--resume", "--rounds", "3", "--out", one])[0], one, resume=True)
    capsys.readouterr()
    with pytest.raises(SystemExit) as e:                      # the CLI says it in one line
        cli.main(["--resume", "--rounds", "3", "--out", one])
    err = capsys.readouterr().err.strip().splitlines()
    assert (e.value.code == 2 and len(err) == 1 and "cannot resume" in err[0]
            and "state.npz: not a readable" in err[0])


def test_a_run_of_earlier_code_resumes_to_the_same_results(tmp_path, capsys):
    """Settings saved before other_orders and distill_epochs existed, and with fields removed
    since at the values today's code runs (config.REMOVED), still resume (config.upgraded), to
    the results of a run never stopped; a run that used a removed setting is refused in one line
    that names it."""
    old, new = str(tmp_path / "old"), str(tmp_path / "new")
    # what the code did: no other orders, and one number of BC epochs for every round
    before = ["--no-other-orders", "--bc-epochs", "3", "--distill-epochs", "3"]
    cli.main(["--rounds", "1", *TINY, *before, "--out", old])

    def as_before(settings, **removed):            # the settings as the code before saved them
        settings = {**settings, "hard_picks": False, "label_later_tasks": 0,
                    "label_later_epochs": 30, **removed}
        assert settings.pop("other_orders") is False
        assert settings.pop("distill_epochs") == [settings["bc_epochs"]] == [3]
        return settings

    def save_as_before(**removed):
        with open(os.path.join(old, "results.json")) as f:
            results = json.load(f)
        checkpoint.save_json(os.path.join(old, "results.json"),
                             dict(results, config=as_before(results["config"], **removed)))
        with np.load(os.path.join(old, "state.npz")) as z:
            state = dict(z)
        saved = json.loads(str(state["results"]))
        state["results"] = np.array(json.dumps(dict(saved, config=as_before(saved["config"],
                                                                           **removed))))
        checkpoint.save_npz(os.path.join(old, "state.npz"), state)

    save_as_before()
    cli.main(["--resume", "--rounds", "2", "--out", old])
    cli.main(["--rounds", "2", *TINY, *before, "--out", new])
    assert results_without_clock(old) == results_without_clock(new)
    save_as_before(label_later_tasks=40)           # labels before every later round: gone
    capsys.readouterr()
    with pytest.raises(SystemExit):
        cli.parse_args(["--resume", "--rounds", "3", "--out", old])
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "label_later_tasks=40" in err[0], err


def test_any_number_of_workers_gives_the_same_bytes(tmp_path):
    """The physics runs in worker processes, every random draw in the main process: one worker or
    three, the results and the checkpoints are the same."""
    outs = [str(tmp_path / f"workers{w}") for w in (1, 3)]
    for w, out in zip((1, 3), outs):
        cli.main(["--rounds", "1", *TINY, "--workers", str(w), "--out", out])
    assert results_without_clock(outs[0]) == results_without_clock(outs[1])
    for k in range(2):
        with open(os.path.join(outs[0], f"round{k}.npz"), "rb") as a, \
                open(os.path.join(outs[1], f"round{k}.npz"), "rb") as b:
            assert a.read() == b.read(), k


def alive(pid):
    """True while process pid runs (a zombie, dead but not yet reaped, counts as gone)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not os.path.exists("/proc/self/task"), reason="needs Linux's /proc")
def test_a_killed_run_leaves_no_workers_behind(tmp_path):
    p = child("--rounds", "3", *TINY, "--workers", "2", "--out", str(tmp_path / "run"))
    for line in p.stdout:
        if line.startswith("round 0:"):
            break
    with open(f"/proc/{p.pid}/task/{p.pid}/children") as f:
        workers = [int(pid) for pid in f.read().split()]
    assert len(workers) >= 2, workers                       # the pool (and its helpers)
    p.kill()
    p.communicate()
    deadline = time.time() + 20
    while any(alive(pid) for pid in workers) and time.time() < deadline:
        time.sleep(0.2)
    assert not any(alive(pid) for pid in workers)


def test_ctrl_c_stops_cleanly_and_says_how_to_resume(tmp_path):
    out = str(tmp_path / "run")
    p = child("--rounds", "3", *TINY, "--out", out)
    for line in p.stdout:
        if line.startswith("round 0:"):
            break
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130 and "Traceback" not in err
    assert (f"rounds 0..0 are saved in {out}; go on with:\n"
            f"    python taskexp.py --resume --out {out}") in err


def test_tasks_survive_the_state_file_with_their_goal_order():
    s0 = np.random.default_rng(0).normal(size=(6, 6))
    tasks = [(s0, {3: (0.1, 0.025), 0: (-0.2, 0.075)}), (s0 + 1, {5: (0.3, 0.025)})]
    back = checkpoint.arrays_to_tasks(*checkpoint.tasks_to_arrays(tasks, 6))
    assert [list(g.items()) for _, g in back] == [list(g.items()) for _, g in tasks]
    assert all(np.array_equal(a, b) for (a, _), (b, _) in zip(back, tasks))


# ----------------------------------------------------------------------------- numerics

DEEP_SET = dict(network="setnet", features="relations")      # whose parameters the test names


@pytest.mark.filterwarnings("ignore::RuntimeWarning")     # the overflow is the point of the test
def test_nan_in_training_stops_with_phase_and_step():
    rng = np.random.default_rng(0)
    obs, acts = rng.normal(size=(40, 6, 6)), np.zeros((40, 3), np.int64)
    agent = Agent(hidden=8, n_y=6, **DEEP_SET)
    agent.actor.params["rho.b1"][3] = np.nan
    with pytest.raises(FloatingPointError, match="BC epoch 1 minibatch 1: non-finite loss"):
        agent.bc(obs, acts, 2, 16, 1e-3, rng)
    agent = Agent(hidden=8, n_y=6, **DEEP_SET)
    with pytest.raises(FloatingPointError, match="PPO update: inputs: non-finite advantages"):
        agent.ppo_update(obs, acts, np.zeros(40), np.r_[np.inf, np.zeros(39)], np.zeros(40),
                         rng=rng, **PPO)
    with pytest.raises(FloatingPointError, match="value fit epoch 1 minibatch 1: non-finite loss"):
        agent.fit_value(obs, np.full(40, 1e300), 1, 16, 1e-3, rng)
    with pytest.raises(FloatingPointError, match="BC epoch 1: non-finite parameters phi.W0"):
        Agent(hidden=8, n_y=6, **DEEP_SET).bc(obs, acts, 1, 64, np.inf, rng)     # an infinite rate


def test_nan_in_a_run_names_round_and_update_and_main_says_so(tmp_path, monkeypatch, capsys):
    real = agent_module.ppo_loss

    def broken(*args, **kwargs):
        loss, dout = real(*args, **kwargs)
        return np.nan, dout
    # the CLI's training, with a loss that goes bad handed in as the method's ppo_loss
    train = functools.partial(taskexp.train, pieces=taskexp.Pieces(ppo_loss=broken))
    monkeypatch.setattr(taskexp, "train", train)
    with pytest.raises(SystemExit) as e:
        cli.main(["--rounds", "1", *TINY, "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert e.value.code == 1
    assert ("error: training diverged: round 0: PPO base update 1: PPO update epoch 1 minibatch 1: "
            "non-finite policy_loss") in err
    assert "no round was complete" in err


# ----------------------------------------------------------------------------- memory

def test_memory_stays_flat_and_the_buffer_bounded(tmp_path):
    """Python-tracked memory (numpy arrays included) after each of 6 rounds grows by < 0.2 MB per
    round from round 2 on: a leak of every round's episodes (run_episodes' results kept in a
    list) measures +0.56 MB per round here, this code +0.02. And the demo buffer and task list
    hold at most buffer_size entries."""
    cfg, *_ = cli.parse_args(["--rounds", "5", *TINY, "--out", str(tmp_path)])
    cfg.buffer_size = 300                                  # < the 400 base demos: the bound binds
    after = []

    def measure(k, agent, run, rng):
        gc.collect()
        after.append(tracemalloc.get_traced_memory()[0] / 2**20)
    tracemalloc.start()
    try:
        run = taskexp.train(cfg, on_round=measure, log=lambda *a: None)
    finally:
        tracemalloc.stop()
    slope = np.polyfit(np.arange(len(after) - 2), after[2:], 1)[0]
    assert len(after) == 6 and slope < 0.2, (slope, after)
    assert len(run.buffer_act) == len(run.buffer_obs) == 300
    assert len(run.all_tasks) <= 300


def test_the_settings_note_is_a_command_that_makes_the_same_settings():
    """A run says which of its settings are not the default's as flags (cli.settings_note), the
    switches among them as --name or --no-name: given back to the CLI, they make its Config."""
    argv = ["--no-restrict", "--aux-relations", "0.5", "--shapes", "I", "Y"]
    cfg = cli.parse_args(argv)[0]
    note = cli.settings_note(cfg, "out", resume=False, scale=1.0)
    assert "--no-restrict" in note and "False" not in note
    assert cli.parse_args(note.split(": ", 1)[1].split())[0] == cfg
