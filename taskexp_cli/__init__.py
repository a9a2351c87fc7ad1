"""taskexp_cli/__init__.py -- the plumbing around taskexp.train: command-line flags generated from
Config, the run directory, checkpoints after every round, resuming a stopped run, progress bars.

    python taskexp.py --rounds 3            # the same as `taskexp --rounds 3` once installed
    python taskexp.py --help                         # every Config field is a flag
    python -m taskexp_cli try runs/ours-seed0/round3.npz "0,0 0,1 0,2" --blocks 7
                                                     # a structure you write (try_structure.py)

A run directory holds round{k}.npz (the agent after round k, for agent.Agent.load), state.npz
(everything --resume needs to go on exactly as if never stopped), results.json, and the figures.
"""
import argparse
import ast
import glob
import hashlib
import inspect
import json
import os
import sys
import time
from dataclasses import fields, replace
from functools import partial
from typing import NamedTuple

import numpy as np
from tqdm import tqdm

import taskexp
from agent import GREEDY
from taskexp import RunState
from taskexp_lib.checkpoint import load_state, save_json, save_state, saved_results
from taskexp_lib.config import TUPLES, Config, saved_config
from taskexp_lib.features import FEATURES
from taskexp_lib.geometry import MAX_BLOCKS, block_count
from taskexp_lib.nets import NETWORKS
from taskexp_lib.shapes import FAMILIES, SHAPES

from . import report

# --------------------------------------------------------------------------------------------
# Flags: one per Config field, its help text the field's docstring
# --------------------------------------------------------------------------------------------

CHOICES = {"select": ("ours", "end2new", "init2new"), "baseline": ("direct-ppo",),
           "shapes": tuple(SHAPES), "families": tuple(FAMILIES),
           "dtype": ("float32", "float64"),
           "network": tuple(NETWORKS), "features": FEATURES, "action": ("drop", "place"),
           "parts_in": ("all", "bc"), "greedy": GREEDY}
MIN_ZERO = {"seed", "rounds", "warmup", "max_stay", "eval_salt", "stretch", "ent_coef", "p_add",
            "goal_parts", "base_pairs", "clear_pairs", "aux_relations",
            "label_tasks", "label_top", "label_pair"}
AT_MOST_ONE = {"gamma", "gae_lambda", "clip", "p_add", "clear_pairs"}
SCALED = ("base_demos", "base_pairs", "ppo_steps", "expand_episodes", "eval_episodes",
          "ppo_episodes", "label_tasks")
RUN_FILES = ("results.json", "state.npz", "round*.npz")      # what a run leaves in its directory
RUN_FIELDS = ("seed", "rounds")                   # Config fields among the run flags of --help
ENGINEERING = ("dtype", "n_envs")                 # how it computes, not what it learns
EXAMPLES = """examples:
  taskexp --rounds 1 --scale 0.05           a smoke test: every budget x 0.05, under a minute
  taskexp --rounds 3                        the default run, in runs/ours-seed0
  taskexp --rounds 3 --seed 1               another seed, in runs/ours-seed1
  taskexp --select end2new --rounds 1       an ablation of Table 3, in runs/end2new-seed0
  taskexp --baseline direct-ppo --rounds 1  PPO directly on the held-out shapes
  taskexp --resume --out runs/ours-seed0    go on after a kill or Ctrl-C
  taskexp try runs/ours-seed0/round3.npz "0,0 0,1 1.5,0 1.5,1 0.75,2" --blocks 7
                                            a trained agent builds a structure you write
(python taskexp.py is the same command)"""


def field_docs(cls):
    """{field name: its docstring} of a dataclass whose fields are followed by string literals."""
    try:
        body = ast.parse(inspect.getsource(cls)).body[0].body
    except (OSError, TypeError):                               # no source (a frozen install)
        return {}
    return {a.target.id: " ".join(b.value.value.split()) for a, b in zip(body, body[1:])
            if isinstance(a, ast.AnnAssign) and isinstance(b, ast.Expr)
            and isinstance(b.value, ast.Constant) and isinstance(b.value.value, str)}


def flag(name):
    return "--blocks" if name == "n_blocks" else "--" + name.replace("_", "-")


def beyond_the_paper(name, doc):
    """A setting that is ours, not the paper's: its docstring says so, or it is engineering."""
    return "not in the paper" in doc or name.startswith("label_") or name in ENGINEERING


class Parser(argparse.ArgumentParser):
    """A refusal is one line that names the flag, not the usage block before it."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def parser():
    """The command line: one flag per Config field, its help the field's docstring, in three
    groups (the run's flags first), with examples at the end."""
    p = Parser(prog="taskexp", description=taskexp.__doc__.split("\n")[0], epilog=EXAMPLES,
               formatter_class=argparse.RawDescriptionHelpFormatter)
    run = p.add_argument_group("the run")
    paper = p.add_argument_group("the paper's hyperparameters (sec 3-5)")
    ours = p.add_argument_group("beyond the paper (our additions, and how it computes)")
    run.add_argument("--out", default=None,
                     help="output directory (default runs/<variant>-seed<seed>; settings other "
                          "than the default's add -scale<s> and a code of them)")
    # --seed and --rounds follow (RUN_FIELDS, Config's first fields), then the run's other flags
    docs, d = field_docs(Config), Config()
    for f in fields(Config):
        default, doc = getattr(d, f.name), docs.get(f.name, "")
        text = doc.replace("%", "%%")                              # argparse formats help with %
        kw = dict(default=None, dest=f.name, help=f"{text} (default {default!r})")
        names = [flag(f.name)] + (["--n-blocks"] if f.name == "n_blocks" else [])
        if f.type is bool:
            kw["action"] = argparse.BooleanOptionalAction
        elif f.type is tuple:     # any number of its default's type; problem() refuses none
            kw["nargs"], kw["type"] = "*", type(default[0])         # where a run needs one
        else:
            kw["type"] = f.type
        if f.name in CHOICES:
            kw["choices"] = CHOICES[f.name]
        group = (run if f.name in RUN_FIELDS else ours if beyond_the_paper(f.name, doc)
                 else paper)
        group.add_argument(*names, **kw)
    run.add_argument("--scale", type=float, default=None,
                     help="multiply every data and step budget (0.05: a smoke test whose "
                          "numbers mean nothing; default 1)")
    run.add_argument("--workers", type=int, default=None,
                     help="processes that run the physics, and threads (at most 2) that share "
                          "each network minibatch (default: the cores this machine lets the run "
                          "use); the results are the same for any number")
    run.add_argument("--resume", action="store_true",
                     help="go on from the last complete round of the run in --out, with its "
                          "settings (--rounds may raise the number of rounds)")
    return p


def problem(cfg):
    """The first setting of cfg that no run can use, as a one-line reason, or None."""
    if not cfg.shapes:
        return "--shapes must name at least one held-out shape"
    need = max(len(SHAPES[s]) for s in cfg.shapes)
    counts = [("--blocks", cfg.n_blocks)] + [("--eval-blocks", n) for n in cfg.eval_blocks]
    try:
        for name, n in counts:
            block_count(n, least=need, name=name)
    except ValueError as e:
        return f"{e} (the held-out shapes need {need} blocks, the table holds {MAX_BLOCKS})"
    if not cfg.distill_epochs or min(cfg.distill_epochs) < 1:
        return (f"--distill-epochs must be epochs >= 1, round by round, got "
                f"{' '.join(map(str, cfg.distill_epochs)) or 'none'}")
    for f in fields(Config):
        v = getattr(cfg, f.name)
        if f.type in (int, float):
            low = 0 if f.name in MIN_ZERO else 1 if f.type is int else None
            if (v < low) if low is not None else not v > 0:
                return f"{flag(f.name)} must be {'> 0' if low is None else f'>= {low}'}, got {v}"
            if f.name in AT_MOST_ONE and v > 1:
                return f"{flag(f.name)} must be <= 1, got {v}"
    if cfg.max_stay >= cfg.n_blocks:
        return f"--max-stay must be below --blocks ({cfg.n_blocks}), got {cfg.max_stay}"
    return None


def scaled(cfg, scale):
    """cfg with every data and step budget (SCALED) times scale, at least 4; 0 stays 0."""
    cfg = replace(cfg)
    for name in SCALED if scale != 1.0 else ():
        budget = getattr(cfg, name)
        if budget:                                  # label_tasks 0 (no labels) stays 0
            setattr(cfg, name, max(4, int(round(budget * scale))))
    return cfg


def other_settings(cfg, scale=1.0):
    """{flag: value} of cfg's settings that differ from the default's at the same scale."""
    default = scaled(replace(Config(), seed=cfg.seed, rounds=cfg.rounds), scale)
    return {flag(f.name): getattr(cfg, f.name) for f in fields(Config)
            if getattr(cfg, f.name) != getattr(default, f.name)}


def run_name(cfg, scale=1.0):
    """The name of a run's default folder: the variant in words (ours, end2new, ours-nolabels,
    ...), -scale<s> for another --scale, and a code of any other setting that is not the
    default's, so that no run lands in the folder of a run with other settings."""
    tag = cfg.baseline or f"{cfg.select}{'' if cfg.restrict else '-norestrict'}"
    tag += "" if cfg.label_tasks else "-nolabels"
    tag += "" if cfg.features == Config.features else f"-{cfg.features}"
    tag += "" if cfg.n_blocks == Config.n_blocks else f"-{cfg.n_blocks}blocks"
    tag += "" if scale == 1.0 else f"-scale{scale:g}"
    said = {"--select", "--restrict", "--baseline", "--features", "--blocks"}
    said |= set() if cfg.label_tasks else {"--label-tasks"}
    other = {k: v for k, v in other_settings(cfg, scale).items() if k not in said}
    if other:
        text = json.dumps(other, sort_keys=True, default=list)
        tag += "-" + hashlib.sha256(text.encode()).hexdigest()[:6]
    return tag


class Invocation(NamedTuple):
    """What the command line asks for."""
    cfg: Config             # the run's settings (saved ones when resuming)
    out: str                # its directory
    resume: bool            # go on with the run in `out`
    scale: float            # the factor --scale applied to the budgets (1: none)
    workers: int            # physics processes and network threads; the results do not change


def usable_cores():
    try:
        return len(os.sched_getaffinity(0))            # the cores this process may run on
    except AttributeError:                             # macOS, Windows
        return os.cpu_count() or 1


def given_settings(a):
    """{Config field: value} of the flags given on a command line that parser() parsed into `a`."""
    given = {f.name: getattr(a, f.name) for f in fields(Config) if getattr(a, f.name) is not None}
    for name in TUPLES:
        if name in given:
            given[name] = tuple(given[name])
    return given


def parse_args(argv=None):
    """-> Invocation. Bad settings: a one-line reason, exit 2."""
    p = parser()
    a = p.parse_args(argv)
    if a.workers is not None and a.workers < 1:
        p.error(f"--workers must be >= 1, got {a.workers}")
    workers = usable_cores() if a.workers is None else a.workers
    given = given_settings(a)
    if a.out is not None and os.path.isfile(a.out):
        p.error(f"--out {a.out} is a file; name a directory for the run")
    if a.resume:
        others = sorted(set(given) - {"rounds"}) + (["scale"] if a.scale is not None else [])
        if others:
            p.error(f"--resume uses the settings saved in --out; drop {flag(others[0])}")
        if a.out is None:
            p.error("--resume needs --out, the directory of the run to go on with")
        results, why = saved_results(a.out)
        if results is None:
            p.error(f"--resume: {a.out} holds no readable run ({why}); "
                    f"start a new run with --out {a.out} and no --resume")
        cfg = saved_config(results["config"])
        cfg.rounds = given.get("rounds", cfg.rounds)
        done = results["rounds"][-1]["round"]
        if done >= cfg.rounds:
            p.error(f"--resume: {a.out} has finished all {cfg.rounds} rounds; "
                    "pass a larger --rounds to extend it")
        if problem(cfg):
            p.error(problem(cfg))
        return Invocation(cfg, a.out, True, 1.0, workers)
    cfg = Config(**given)
    if problem(cfg):
        p.error(problem(cfg))
    scale = 1.0 if a.scale is None else a.scale
    if not 0 < scale <= 100:
        p.error(f"--scale must be in (0, 100], got {scale}")
    cfg = scaled(cfg, scale)
    out = a.out or os.path.join("runs", f"{run_name(cfg, scale)}-seed{cfg.seed}")
    found = sorted(f for pattern in RUN_FILES for f in glob.glob(os.path.join(glob.escape(out),
                                                                              pattern)))
    if found:
        what = f"{out} already holds a run ({os.path.basename(found[0])})"
        results, why = saved_results(out)
        if results is None:
            p.error(f"{what} that cannot be resumed ({why}); delete its files or choose "
                    "another --out")
        p.error(f"{what}; continue it with --resume --out {out}, or choose another --out")
    return Invocation(cfg, out, False, scale, workers)


# --------------------------------------------------------------------------------------------
# A run in a directory: after every round, a checkpoint and state.npz (checkpoint.py), which
# holds all a run needs to go on as if never stopped
# --------------------------------------------------------------------------------------------

class ResumeError(ValueError):
    """state.npz is missing, unreadable, or from a run with other settings."""


def peak_memory_mb():
    """Peak resident memory of this process so far (MB), or None where `resource` is missing."""
    try:
        import resource
    except ImportError:                                      # Windows
        return None
    kb = 2**20 if sys.platform == "darwin" else 2**10        # ru_maxrss: bytes on macOS, else kB
    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / kb)


# tqdm on a terminal; nothing when the output goes to a file, so logs stay readable
terminal_bar = partial(tqdm, leave=False, disable=None, dynamic_ncols=True)


def run(cfg, out_dir, log=print, resume=False, bar=terminal_bar, workers=1):
    """taskexp.train with a checkpoint after every round; returns the results dict.

    After round k: round{k}.npz, state.npz and results.json. resume=True goes on from the last
    complete round and gives the same results as a run never stopped.
    """
    os.makedirs(out_dir, exist_ok=True)
    rng = np.random.default_rng(cfg.seed)
    state_path = os.path.join(out_dir, "state.npz")
    agent, state = None, None
    if resume:
        try:
            agent, saved = load_state(state_path, cfg, rng, taskexp.make_agent(cfg))
            state = RunState(**saved)
        except (OSError, ValueError) as e:
            raise ResumeError(f"cannot resume: {e}") from None
        # state.npz is written before results.json: a kill between the two leaves results.json
        # a round behind, or damaged
        save_json(os.path.join(out_dir, "results.json"), state.results)
        log(f"resuming {out_dir} after round {state.last_round}")
    clock = state.results["wallclock"] if state else {}
    t_start = time.time() - clock.get("total_s", 0.0)
    t_round = [time.time()]

    def after_round(k, agent, run, rng):
        clock = run.results["wallclock"]
        clock[f"round{k}_s"] = round(time.time() - t_round[0], 1)
        clock["total_s"] = round(time.time() - t_start, 1)
        clock["peak_memory_mb"] = peak_memory_mb()
        agent.save(os.path.join(out_dir, f"round{k}.npz"))
        save_state(state_path, agent, run, rng)                  # the commit point of round k
        save_json(os.path.join(out_dir, "results.json"), run.results)
        tested = run.results["rounds"][-1]
        rates = lambda r: ", ".join(f"{s} {v:.0%}" for s, v in r.items())    # {name: success}
        log(f"round {k}: zero-shot {rates(tested['eval'])}  ({clock['total_s']:.0f}s so far, "
            f"peak memory {clock['peak_memory_mb']} MB)")
        for family, r in tested.get("families", {}).items():
            log(f"  {family}: {rates(r)}")
        for n, r in tested.get("blocks", {}).items():
            log(f"  {n} blocks, the weights learnt with {cfg.n_blocks}: {rates(r)}")
        t_round[0] = time.time()

    return taskexp.train(cfg, agent, state, rng, on_round=after_round, bar=bar, log=log,
                         workers=workers).results


def saved_round(out):
    """The last complete round of the run in `out`, or -1 if there is none."""
    results, _ = saved_results(out)
    return -1 if results is None else results["rounds"][-1]["round"]


def how_to_go_on(out):
    """What a stopped run left in `out`, and how to go on from it."""
    k = saved_round(out)
    if k < 0:
        return f"no round was complete, so there is nothing to resume in {out}."
    return (f"rounds 0..{k} are saved in {out}; go on with:\n"
            f"    python taskexp.py --resume --out {out}")


def as_flags(setting):
    """(flag, value) -> the words that set it on the command line: "--seed 3", "--shapes I Y",
    and a switch as "--name" or "--no-name" ("--no-restrict")."""
    name, value = setting
    if isinstance(value, bool):
        return name if value else name.replace("--", "--no-", 1)
    return f"{name} {' '.join(map(str, value)) if isinstance(value, tuple) else value}"


def settings_note(cfg, out, resume, scale):
    """What a run's settings mean for its numbers, or None for the default's."""
    other = other_settings(cfg, scale)
    if scale != 1.0:
        return (f"note: --scale {scale:g} shrinks every budget: this run tests the code, and its "
                "success rates say nothing about the method")
    budgets = [flag(name) for name in SCALED if flag(name) in other]
    if resume and budgets:                  # e.g. a smoke test's run, given more rounds
        return (f"note: {out} was made with budgets other than the default's ("
                + ", ".join(f"{b} {other[b]}" for b in budgets) + "): its success rates are not "
                "those of the default run")
    if other:
        return "settings other than the default's: " + " ".join(map(as_flags, other.items()))
    return None


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["try"]:                     # python -m taskexp_cli try CHECKPOINT STRUCTURE
        from .try_structure import main as try_main
        return try_main(argv[1:])
    cfg, out, resume, scale, workers = parse_args(argv)
    note = settings_note(cfg, out, resume, scale)
    if note:
        print(note)
    try:
        results = run(cfg, out, resume=resume, workers=workers)
        print()
        print(report.tables(results))
        for more in (report.family_tables(results), report.blocks_table(results)):
            if more:
                print("\n" + more)
        for path in report.figures(results, out):
            print("wrote", path)
    except KeyboardInterrupt:
        print(f"\ninterrupted; {how_to_go_on(out)}", file=sys.stderr)
        sys.exit(130)
    except ResumeError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    except FloatingPointError as e:
        print(f"\nerror: training diverged: {e}\n{how_to_go_on(out)}", file=sys.stderr)
        sys.exit(1)
    print(f"wrote {out}/results.json, state.npz (for --resume) and round0..{cfg.rounds}.npz "
          f"in {results['wallclock']['total_s']:.0f}s")
    if note:
        print(note)


if __name__ == "__main__":
    main()
