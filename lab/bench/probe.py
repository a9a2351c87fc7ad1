"""Can the networks' tokens tell "a goal right below mine is still pending" from "no goal names
the spot below mine"? A linear probe, in seconds.

    python lab/bench/probe.py runs/ours-seed0/round0.npz runs/ours-seed0/round3.npz

In the held-out shapes a goal in the air waits for the goal block below it; in the family "air"
(taskexp_lib/shapes.py) nothing names the spot below, and a block that no goal names must go
there. A policy that moves such a block in the first case, or waits in the second, fails one of
them (lab/notes.md, 2026-12-06). The two differ only in another block's goal, so a block's own
plain features are the same in both; only what attention brings into its token can tell them
apart (--features relations computes the difference by hand: there the control tells them apart).

The probe is made of minimal pairs. For every scene of the run's evaluation shapes at its start
and every goal block i whose goal has a pending goal j right below it (features.relations,
"wait"), the pair is (s0, goals) and (s0, goals without j's): block i's own features are the same
in both. A least-squares linear probe (ridge) on block i's token (AttentionNet.encode: what the
head reads) learns which of the two it is on the scenes of even index and is scored on the odd
ones. The same probe on block i's own features is the control: with plain features it must
score 50%. The blocks that no goal names in either ("free blocks") are probed too: without j's
goal one of them must go under i's, with it none need move; the policy can act on that only if
their tokens carry it.
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
from build_order import checkpoint_parser, expand, run_seed  # noqa: E402

import taskexp  # noqa: E402
from agent import Agent  # noqa: E402
from env2d import run_worlds  # noqa: E402
from taskexp_lib import one_blas_thread  # noqa: E402
from taskexp_lib.geometry import BLOCK_H, BLOCK_W, THRESHOLD, observation  # noqa: E402
from taskexp_lib.shapes import eval_tasks  # noqa: E402


def minimal_pairs(tasks):
    """[(scene index, block i, obs with j's goal, obs without it)] for the tasks [(s0, goals)]:
    every goal block i and pending goal j right below i's goal (what makes i "wait" in
    features.relations, one j at a time)."""
    pairs = []
    for scene, (s0, goals) in enumerate(tasks):
        whole = observation(s0, goals)
        pending = [j for j, (gx, gy) in goals.items()
                   if np.hypot(gx - s0[j, 0], gy - s0[j, 1]) >= THRESHOLD]
        for i in sorted(goals):
            gx, gy = goals[i]
            for j in pending:
                if j != i and abs(goals[j][0] - gx) < BLOCK_W \
                        and abs(goals[j][1] - (gy - BLOCK_H)) < BLOCK_H / 2:
                    without = {b: p for b, p in goals.items() if b != j}
                    pairs.append((scene, int(i), whole, observation(s0, without)))
    return pairs


def probe_accuracy(X, y, train, lam=1.0):
    """Ridge regression of y (+-1) on X (standardised on the training rows) -> the share of the
    other rows whose sign it gets right."""
    mu, sd = X[train].mean(0), X[train].std(0) + 1e-8
    Z = np.hstack([(X - mu) / sd, np.ones((len(X), 1))])
    A = Z[train]
    w = np.linalg.solve(A.T @ A + lam * np.eye(Z.shape[1]), A.T @ y[train])
    guess = np.where(Z[~train] @ w > 0, 1.0, -1.0)     # rows alike get one guess: half right
    return float(np.mean(guess == y[~train]))


def measure(checkpoint, seed=0, episodes=100):
    """-> {"pairs": count, "own features": acc, "actor tokens": acc, "critic tokens": acc}."""
    agent = Agent.load(checkpoint)
    cfg = taskexp.Config(seed=run_seed(checkpoint, seed), eval_episodes=episodes,
                         n_blocks=agent.n_blocks)
    envs, _ = run_worlds(cfg)
    pairs = [p for tasks in eval_tasks(cfg, envs[0]).values() for p in minimal_pairs(tasks)]
    if not pairs:
        raise SystemExit(f"{checkpoint}: no goal waits for another in these scenes")
    scenes = np.array([s for s, *_ in pairs] * 2)
    blocks = np.array([i for _, i, *_ in pairs] * 2)
    obs = np.stack([o for *_, o, _ in pairs] + [o for *_, o in pairs])
    y = np.r_[np.ones(len(pairs)), -np.ones(len(pairs))]      # +1: j's goal pending below
    rows = np.arange(len(obs))
    train = scenes % 2 == 0
    # the blocks no goal names in either (j is named in one): one of them must go under i's
    # goal when j's is left out, none when it is not
    free = [(r, k) for r in rows for k in range(obs.shape[1]) if obs[r % len(pairs), k, 5] == 0]
    free_rows, free_blocks = (np.array(c) for c in zip(*free)) if free else ([], [])
    f = agent.features(obs)
    out = {"pairs": len(pairs), "own features": probe_accuracy(f[rows, blocks], y, train)}
    for name, net in (("actor", agent.actor), ("critic", agent.critic)):
        if not hasattr(net, "encode"):
            continue                                      # a SetNet has no tokens to probe
        tokens = net.encode(f)
        out[f"{name} tokens"] = probe_accuracy(tokens[rows, blocks], y, train)
        if free:
            out[f"{name} free blocks"] = probe_accuracy(tokens[free_rows, free_blocks],
                                                        y[free_rows], train[free_rows])
    return out


def main():
    a = checkpoint_parser(__doc__.split("\n")[0], greedy=False).parse_args()  # no actions
    for path in expand(a.checkpoints):
        m = measure(path, a.seed, a.episodes)
        print(f"{path}: {m.pop('pairs')} minimal pairs; probe accuracy on held-out scenes: "
              + ", ".join(f"{k} {100 * v:.0f}%" for k, v in m.items()))


if __name__ == "__main__":
    with one_blas_thread():
        main()
