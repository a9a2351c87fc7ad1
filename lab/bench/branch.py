"""lab/bench/branch.py -- a run's rounds of task expansion under other settings, from its round 0.

Round 0, the base skills (sec 4.1), is about half of a default run, and it reads none of the
settings of task expansion and self-distillation (LATER). A lever among those is measured faster
from one round-0 run per seed, branched once per setting:

    python taskexp.py --rounds 0 --seed 0 --out runs/base-seed0              # once per seed
    python lab/bench/branch.py runs/base-seed0 runs/expand-seed0 --expand-episodes 9000
    python taskexp.py --resume --out runs/expand-seed0 --rounds 2

The branch's results are the bytes a run made with those settings from the start would give
(tests/test_bench.py); its results.json names the run it came from (branched_from).
"""
import argparse
import os
import shutil
import sys
from dataclasses import asdict, replace

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
import taskexp  # noqa: E402
import taskexp_cli as cli  # noqa: E402
from taskexp_lib.checkpoint import load_state, save_json, save_state, saved_results  # noqa: E402
from taskexp_lib.config import saved_config  # noqa: E402

# the settings that only rounds >= 1 read (round 0's labels and stretch tasks read p_add,
# candidates, restrict and select, so those are not among them), and what is evaluated beside
# the shapes (the families, the worlds of other block counts)
LATER = ("rounds", "expand_episodes", "other_orders", "goal_parts", "parts_in", "distill_epochs",
         "buffer_size", "baseline", "families", "eval_blocks")
# Table 3's rules, which an ablation (--ablation) applies from round 1 on: all rows then share
# one base policy and round-0 critic, so that the table compares goal selection alone. Such a
# branch is not the run made with the rule from the start, whose round-0 labels would already
# rank candidates by it.
ABLATIONS = ("select", "restrict")


def branch(source, out, changes, ablation=False):
    """Write into `out` the run in `source` after its round 0, with the settings `changes`
    ({Config field: value}: fields of LATER, and of ABLATIONS if `ablation`). SystemExit with a
    one-line reason otherwise."""
    allowed = LATER + (ABLATIONS if ablation else ())
    wrong = sorted(set(changes) - set(allowed))
    if wrong:
        raise SystemExit(f"{cli.flag(wrong[0])}: round 0 reads it, so a branch of round 0 cannot "
                         f"change it; a branch changes {', '.join(map(cli.flag, allowed))}"
                         + ("" if ablation else " (and, with --ablation, Table 3's rules)"))
    results, why = saved_results(source)
    if results is None:
        raise SystemExit(f"{source}: no run to branch ({why})")
    if results["rounds"][-1]["round"] != 0:
        raise SystemExit(f"{source}: saved after round {results['rounds'][-1]['round']}; branch "
                         "a run made with --rounds 0")
    if os.path.exists(out):
        raise SystemExit(f"{out} exists; name a new directory")
    cfg = saved_config(results["config"])
    rng = np.random.default_rng(cfg.seed)
    agent, saved = load_state(os.path.join(source, "state.npz"), cfg, rng,
                              taskexp.make_agent(cfg))
    run = taskexp.RunState(**saved)
    run.results["config"] = asdict(replace(cfg, **changes))
    run.results["branched_from"] = dict(run=os.path.abspath(source), changes=changes,
                                        ablation=ablation)
    os.makedirs(out)
    shutil.copy(os.path.join(source, "round0.npz"), out)
    save_state(os.path.join(out, "state.npz"), agent, run, rng)
    save_json(os.path.join(out, "results.json"), run.results)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                epilog="the flags are taskexp.py's: " +
                                " ".join(map(cli.flag, LATER)))
    p.add_argument("source", help="a run made with --rounds 0")
    p.add_argument("out", help="the new run's directory")
    p.add_argument("--ablation", action="store_true",
                   help="allow Table 3's rules (--select, --no-restrict), applied from round 1 on")
    a, flags = p.parse_known_args()
    changes = cli.given_settings(cli.parser().parse_args(flags))
    branch(a.source, a.out, changes, a.ablation)
    print(f"wrote {a.out}; go on with:\n    python taskexp.py --resume --out {a.out} "
          f"--rounds {max(changes.get('rounds', 1), 1)}")


if __name__ == "__main__":
    main()
