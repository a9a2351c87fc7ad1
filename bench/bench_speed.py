"""Where the time of a run goes, and how it grows with the number of blocks.

    python bench/bench_speed.py                 # everything (~10 min on 2 cores; run it alone)
    python bench/bench_speed.py --skip-full     # without the timed default run (~4 min)

Prints:
1. the default run (`python taskexp.py --rounds 3`, all cores): wall time in all and per round;
2. the share of physics, network forward/backward and everything else, measured with timers
   around BlockWorld.simulate and the MLPs in a --scale 0.25 run with one worker (the physics in
   the main process, so that it can be timed);
3. one BC epoch and one PPO update against the cost of their matrix products alone, timed on
   the same shapes on this CPU;
4. env actions/s (bench/bench_env.py) and time per round with 4, 6 and 8 blocks.
Timings depend on the machine and on what else runs: run it with nothing else on the cores.
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace

import numpy as np

import agent
import env2d
import taskexp
from taskexp_lib import cli, nn, one_blas_thread
from taskexp_lib.config import Config

HERE = os.path.dirname(os.path.abspath(__file__))


def timed_run(cfg, workers, out):
    """cli.run in `out` -> (seconds, {round: seconds})."""
    t0 = time.perf_counter()
    results = cli.run(cfg, out, log=lambda *a: None, workers=workers)
    clock = results["wallclock"]
    return time.perf_counter() - t0, {k: clock[f"round{k}_s"] for k in range(cfg.rounds + 1)}


class Timer:
    """Wraps cls.name so that the seconds spent in it add up in self.total."""

    def __init__(self, cls, name):
        self.total, self.cls, self.name, self.inner = 0.0, cls, name, getattr(cls, name)
        timer = self

        def wrapped(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return timer.inner(*args, **kwargs)
            finally:
                timer.total += time.perf_counter() - t0
        setattr(cls, name, wrapped)

    def restore(self):
        setattr(self.cls, self.name, self.inner)


def shares(cfg, out):
    timers = {"physics": [Timer(env2d.BlockWorld, "simulate")],
              "network": [Timer(nn.MLP, "forward"), Timer(nn.MLP, "backward")]}
    try:
        total, _ = timed_run(cfg, 1, out)
    finally:
        for ts in timers.values():
            for t in ts:
                t.restore()
    spent = {k: sum(t.total for t in ts) for k, ts in timers.items()}
    spent["everything else"] = total - sum(spent.values())
    return total, spent


def matmul_seconds(net, B, n, repeats):
    """The matrix products of one forward and backward of a SetNet on B x n tokens, alone."""
    rows, seconds = B * n, 0.0
    for mlp in (net.phi, net.rho):
        for k in range(mlp.n_layers):
            W = mlp.params[f"W{k}"]
            x = np.ones((rows, W.shape[0]), W.dtype)
            d = np.ones((rows, W.shape[1]), W.dtype)
            t0 = time.perf_counter()
            for _ in range(repeats):
                x @ W, x.T @ d, d @ W.T                  # forward, dW, dx
            seconds += (time.perf_counter() - t0) / repeats
    return seconds


def network_ratios(cfg):
    rng = np.random.default_rng(0)
    env = env2d.BlockWorld(cfg.n_blocks)
    tasks, obs, actions = taskexp.base_demos(cfg, env, rng, 4096)
    # the deep set over the relations, in the world that places: the network this bench measures
    ag = agent.Agent(cfg.n_blocks, n_y=cfg.n_blocks, hidden=cfg.hidden, dtype=cfg.dtype,
                     network="setnet", features="relations")
    t0 = time.perf_counter()
    ag.bc(obs, actions, 1, cfg.bc_batch, cfg.bc_lr, rng)
    bc = time.perf_counter() - t0
    n_batches = -(-len(obs) // cfg.bc_batch)
    bc_mm = n_batches * matmul_seconds(ag.actor, cfg.bc_batch, cfg.n_blocks, 20)
    _, logp, values = ag.sample(obs, rng)
    adv = rng.standard_normal(len(obs))
    t0 = time.perf_counter()
    ag.ppo_update(obs, actions, logp, adv, values + adv, epochs=cfg.ppo_epochs,
                  minibatch=cfg.ppo_minibatch, clip=cfg.clip, ent_coef=cfg.ent_coef,
                  vf_coef=cfg.vf_coef, lr=cfg.ppo_lr, max_grad_norm=cfg.max_grad_norm, rng=rng)
    ppo = time.perf_counter() - t0
    per_minibatch = sum(matmul_seconds(net, cfg.ppo_minibatch, cfg.n_blocks, 20)
                        for net in (ag.actor, ag.critic))
    ppo_mm = cfg.ppo_epochs * -(-len(obs) // cfg.ppo_minibatch) * per_minibatch
    return (bc, bc_mm), (ppo, ppo_mm), len(obs)


def env_throughput(n_blocks):
    out = subprocess.run([sys.executable, os.path.join(HERE, "bench_env.py"), "--n-blocks",
                          str(n_blocks), "--actions", "1000"], capture_output=True, text=True,
                         check=True).stdout
    return out.strip().splitlines()


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--skip-full", action="store_true", help="skip the timed default run")
    a = p.parse_args()
    cfg, workers = Config(), cli.usable_cores()
    print(f"config: the defaults of taskexp_lib.config.Config (networks in {cfg.dtype}); "
          f"{workers} cores")
    with tempfile.TemporaryDirectory() as tmp:
        if not a.skip_full:
            total, per_round = timed_run(cfg, workers, os.path.join(tmp, "full"))
            rounds = ", ".join(f"{k}: {s:.0f} s" for k, s in per_round.items())
            print(f"\n1. default run, --workers {workers}: {total:.0f} s ({rounds})")
        small = cli.parse_args(["--rounds", "1", "--scale", "0.25", "--out", "unused"]).cfg
        total, spent = shares(small, os.path.join(tmp, "shares"))
        print(f"\n2. where the time goes (--rounds 1 --scale 0.25, one process): {total:.1f} s")
        for name, s in spent.items():
            print(f"   {name:16s} {s:6.1f} s  {100 * s / total:4.0f}%")
        (bc, bc_mm), (ppo, ppo_mm), n = network_ratios(cfg)
        print(f"\n3. networks ({cfg.dtype}, {n} samples): one BC epoch {bc:.2f} s = "
              f"{bc / bc_mm:.1f}x its matrix products alone ({bc_mm:.2f} s); one PPO update "
              f"({cfg.ppo_epochs} epochs) {ppo:.2f} s = {ppo / ppo_mm:.1f}x ({ppo_mm:.2f} s)")
        print("\n4. blocks: time per round (--rounds 1 --scale 0.1, one process) and env speed")
        for n_blocks in (4, 6, 8):
            shapes = ("I",) if n_blocks < 6 else Config.shapes
            cfg_n = replace(small, n_blocks=n_blocks, shapes=shapes, base_demos=2000,
                            ppo_steps=2000, expand_episodes=300, eval_episodes=10)
            total, per_round = timed_run(cfg_n, 1, os.path.join(tmp, f"n{n_blocks}"))
            line = next(s for s in env_throughput(n_blocks) if "actions/s" in s)
            print(f"   n = {n_blocks}: round 0 {per_round[0]:.1f} s, round 1 {per_round[1]:.1f} s;"
                  f" {line.strip()}")


if __name__ == "__main__":
    with one_blas_thread():                 # as in a run
        main()
