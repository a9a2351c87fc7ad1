"""Is V(s, g)'s regression on the labelled outcomes done when the run stops it? Held-out loss.

    python lab/bench/value_fit.py                            # seed 0, the run's own fits (~10 min)
    python lab/bench/value_fit.py --epochs 20 --batch 256 1024 --lr 1e-3 3e-3 --plot fits.png

Most of a default run's time is its value fits (lab/notes.md, Time), so this asks whether they could
stop earlier or take fuller steps. It runs round 0 of the default run (base skills, sec 4.1,
then the labelled outcomes of taskexp_lib/labels.py) with an agent that keeps what each of its
value fits started from: the labels, the critic, its Adam state and the Generator. Then it
replays every fit from there, with a fifth of the labels new to that fit held out (in blocks of
consecutive rows, so mostly whole runs: the rows of one run are alike), and prints the loss on
the held-out labels after every epoch, for each --batch and --lr. Held out at 0 (--holdout 0)
and at the run's own settings, a replay is the run's fit to the byte (tests/test_bench.py).
A fit whose held-out loss still falls at the run's last epoch could not stop sooner at the same
loss. A lower loss is not a better critic for equation (1), though: judge a change of the fits
by the picks it leaves (lab/bench/feasible_goals.py on the round-0 checkpoint).
"""
import argparse
import copy
import itertools
import os
import sys
from dataclasses import replace

import numpy as np

sys.path.insert(0, os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
import taskexp  # noqa: E402
import taskexp_cli as cli  # noqa: E402
from taskexp_lib.config import Config  # noqa: E402
from taskexp_lib.shards import SHARDS  # noqa: E402


def record_value_fits(agent):
    """Make agent.fit_value keep, at each call, what the fit starts from and what it ends with;
    -> the list it appends dicts to (obs, returns, epochs, batch, lr, rng state, critic params
    and Adam state before, params after)."""
    fits, fit_value = [], agent.fit_value

    def recording(obs, returns, epochs, batch_size, lr, rng, *args, **kwargs):
        opt = agent.critic_opt
        fit = dict(obs=np.asarray(obs), returns=np.asarray(returns), epochs=epochs,
                   batch=batch_size, lr=lr, rng=copy.deepcopy(rng.bit_generator.state),
                   params=copy.deepcopy(agent.critic.params),
                   adam=copy.deepcopy((opt.m, opt.v, opt.t)))
        out = fit_value(obs, returns, epochs, batch_size, lr, rng, *args, **kwargs)
        fits.append({**fit, "after": copy.deepcopy(agent.critic.params)})
        return out

    agent.fit_value = recording
    return fits


def round0_fits(cfg, workers):
    """Round 0 of a run with settings cfg -> (make a fresh agent, the value fits it recorded)."""
    agent = taskexp.make_agent(cfg)
    fits = record_value_fits(agent)
    taskexp.train(replace(cfg, rounds=0), agent=agent, workers=workers, log=lambda *a: None)
    return lambda: taskexp.make_agent(cfg), fits


def held_out(n_old, n, frac, rng, block=64):
    """Rows [n_old, n) are new to a fit: hold out `frac` of their blocks -> (train, held-out)."""
    starts = np.arange(n_old, n, block)
    mask = np.zeros(n, bool)
    for s in starts[rng.permutation(len(starts))[: int(round(frac * len(starts)))]]:
        mask[s:s + block] = True
    return np.flatnonzero(~mask), np.flatnonzero(mask)


def replay(fresh, fit, n_old, epochs, batch, lr, holdout=0.2, seed=0, threads=1):
    """Fit `fit` again from its start, `holdout` of its new rows held out, one epoch at a time
    -> (agent, [(train loss, held-out loss) per epoch]); held-out loss nan when none is."""
    agent = fresh()
    agent.threads = threads
    for k, p in fit["params"].items():
        agent.critic.params[k][...] = p
    opt = agent.critic_opt
    opt.m, opt.v, opt.t = copy.deepcopy(fit["adam"])
    rng = np.random.default_rng()
    rng.bit_generator.state = fit["rng"]
    obs, R = fit["obs"], fit["returns"]
    train, test = held_out(n_old, len(obs), holdout, np.random.default_rng(seed))
    curve = []
    for _ in range(epochs):
        loss = agent.fit_value(obs[train], R[train], 1, batch, lr, rng)[0]
        held = np.mean(0.5 * (agent.value(obs[test]) - R[test]) ** 2) if len(test) else np.nan
        curve.append((loss, float(held)))
    return agent, curve


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seed", type=int, default=0, help="the run's seed")
    p.add_argument("--epochs", type=int, default=None,
                   help="epochs of each replayed fit (default: the run's own)")
    p.add_argument("--batch", type=int, nargs="+", default=[Config.bc_batch])
    p.add_argument("--lr", type=float, nargs="+", default=[Config.label_lr])
    p.add_argument("--holdout", type=float, default=0.2,
                   help="the share of each fit's new labels held out")
    p.add_argument("--plot", help="also draw the held-out curves to this image")
    a = p.parse_args()
    if (a.epochs is not None and a.epochs < 1) or min(a.batch) < 1 or min(a.lr) <= 0:
        p.error("--epochs, --batch and --lr must be positive")
    if not 0 <= a.holdout < 1:
        p.error("--holdout must be at least 0 and below 1")
    workers = cli.usable_cores()
    cfg = replace(Config(), seed=a.seed)
    print(f"round 0 of the default run, seed {a.seed}, {workers} cores ...", flush=True)
    fresh, fits = round0_fits(cfg, workers)
    curves = {}
    for i, fit in enumerate(fits):
        n_old = len(fits[i - 1]["obs"]) if i else 0     # each fit: all labels so far, old first
        epochs = a.epochs or fit["epochs"]
        print(f"\nfit {i + 1} of {len(fits)}: {len(fit['obs'])} labels ({len(fit['obs']) - n_old}"
              f" new, {a.holdout:.0%} of those held out); the run fits {fit['epochs']} epochs "
              f"at batch {fit['batch']}, lr {fit['lr']:g}")
        for batch, lr in itertools.product(a.batch, a.lr):
            _, curve = replay(fresh, fit, n_old, epochs, batch, lr, a.holdout,
                              threads=min(workers, SHARDS))
            curves[i, batch, lr] = held = [h for _, h in curve]
            best = int(np.argmin(held))
            print(f"  batch {batch}, lr {lr:g}: held-out loss by epoch "
                  + " ".join(f"{h:.4f}" for h in held)
                  + f"; lowest at epoch {best + 1}; train {curve[0][0]:.4f} -> {curve[-1][0]:.4f}",
                  flush=True)
    if a.plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, axes = plt.subplots(1, len(fits), figsize=(4 * len(fits), 3.2), squeeze=False)
        for (i, batch, lr), held in curves.items():
            axes[0, i].plot(range(1, len(held) + 1), held, label=f"batch {batch}, lr {lr:g}")
        for i, ax in enumerate(axes[0]):
            ax.axvline(fits[i]["epochs"], color="grey", ls=":", label="the run stops")
            ax.set(title=f"fit {i + 1}", xlabel="epoch", ylabel="held-out loss")
        axes[0, 0].legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(a.plot, dpi=100)
        print(f"\nwrote {a.plot}")


if __name__ == "__main__":
    main()
