"""Where the time of a run goes, and how it grows with the number of blocks.

    python lab/bench/bench_speed.py                 # everything (20-30 min on 2 cores; alone)
    python lab/bench/bench_speed.py --skip-full     # without the timed default run (~4 min)
    python lab/bench/bench_speed.py --full-only --out runs/timed    # the default run by phase
    python lab/bench/bench_speed.py --hidden 64     # all of it for networks of another width

Prints:
1. the default run (`python taskexp.py --rounds 3`, all cores, at --hidden's width): wall time
   in all and per round, CPU utilisation (user + system time of the main process and its physics
   workers / wall time), peak memory, its time by phase of the method (PHASES), each beside its
   floor: the time its matrix products (counted by Flops) take at one core's peak rate, plus its
   actions' physics (counted by Actions) at the run's mean CPU per action, shared over the cores
   with nothing else done (no phase is faster); then the whole run's floor;
2. the share of physics, network forward/backward and everything else, measured with timers
   around BlockWorld.simulate and the networks in a --scale 0.25 run with one worker and one
   thread (the physics in the main process, so that it can be timed);
3. one BC epoch and one PPO update of the default network against the cost of their matrix
   products alone, timed on the same shapes on this CPU in one thread, with one thread and with
   both cores (taskexp_lib/shards.py), after what a second core gives a matrix product and an
   element-wise loop of those shapes;
4. env actions/s (lab/bench/bench_env.py) and time per round with 4, 6 and 8 blocks.
Timings depend on the machine and on what else runs: run it with nothing else on the cores.
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import replace

import numpy as np

import env2d
import taskexp
import taskexp_cli as cli
from agent import Agent
from taskexp_lib import nn, one_blas_thread, rollout
from taskexp_lib.config import Config
from taskexp_lib.nets import NETWORKS
from taskexp_lib.shards import SHARDS

HERE = os.path.dirname(os.path.abspath(__file__))


def children_cpu():
    """User + system CPU time of this process's children that have ended (the physics workers of
    the runs it made)."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return children.ru_utime + children.ru_stime


def cpu_seconds():
    """User + system CPU time of this process and of its children that have ended."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    return me.ru_utime + me.ru_stime + children_cpu()


def timed_run(cfg, workers, out):
    """cli.run in `out` -> (seconds, {round: seconds}, CPU utilisation: the CPU time of the main
    process and its physics workers over the wall time, at most the number of cores)."""
    t0, cpu0 = time.perf_counter(), cpu_seconds()
    results = cli.run(cfg, out, log=lambda *a: None, workers=workers)
    wall = time.perf_counter() - t0
    clock = results["wallclock"]
    per_round = {k: clock[f"round{k}_s"] for k in range(cfg.rounds + 1)}
    return wall, per_round, (cpu_seconds() - cpu0) / wall


class Wrap:
    """Replaces cls.name by a call of self.around(the original, *args, **kwargs) until restore():
    what a subclass measures around every call of a method or a module's function."""

    def __init__(self, cls, name):
        self.cls, self.name, self.inner = cls, name, getattr(cls, name)
        setattr(cls, name, lambda *args, **kwargs: self.around(self.inner, *args, **kwargs))

    def restore(self):
        setattr(self.cls, self.name, self.inner)


class Timer(Wrap):
    """Wraps cls.name so that the seconds spent in it add up in self.total."""

    def __init__(self, cls, name):
        self.total = 0.0
        super().__init__(cls, name)

    def around(self, inner, *args, **kwargs):
        t0 = time.perf_counter()
        try:
            return inner(*args, **kwargs)
        finally:
            self.total += time.perf_counter() - t0


def timed_around(calls, cfg, workers, out):
    """timed_run with a Timer around each call of calls {line: [(cls, name), ...]} -> (its
    figures, {line: seconds spent in that line's calls}); the code is restored after."""
    timers = {line: [Timer(*where) for where in wheres] for line, wheres in calls.items()}
    try:
        figures = timed_run(cfg, workers, out)
    finally:
        for ts in timers.values():
            for t in ts:
                t.restore()
    return figures, {line: sum(t.total for t in ts) for line, ts in timers.items()}


# The method's phases, timed around the calls that make them; a phase's inner calls are counted
# on their own line: {line: (its calls, the lines it holds)}
PHASES = {"base demos (sec 4.1)": ([(taskexp, "base_demos")], ()),
          "behaviour cloning (BC)": ([(Agent, "bc")], ()),
          "PPO: rollouts": ([(taskexp, "ppo_phase")], ("PPO: updates",)),
          "PPO: updates": ([(Agent, "ppo_update")], ()),
          "labels: runs, ranking": ([(taskexp, "labelled")], ("labels: value fits",)),
          "labels: value fits": ([(Agent, "fit_value"), (Agent, "fit_value_pairs")], ()),
          "task expansion (sec 4.2)": ([(taskexp, "task_expansion")], ()),
          "zero-shot evaluation": ([(taskexp, "evaluate")], ())}


REST = "the rest (checkpoints, bookkeeping)"


class InPhase(Wrap):
    """Wraps cls.name so that, while a call runs, `line` is the innermost phase under way (the
    top of `stack`): what Flops and Actions count inside is booked to it."""

    def __init__(self, cls, name, line, stack):
        self.line, self.stack = line, stack
        super().__init__(cls, name)

    def around(self, inner, *args, **kwargs):
        self.stack.append(self.line)
        try:
            return inner(*args, **kwargs)
        finally:
            self.stack.pop()


class Actions(Wrap):
    """Counts the actions whose physics rollout.simulate runs, by the phase under way."""

    def __init__(self, stack):
        self.stack, self.total = stack, {}
        super().__init__(rollout, "simulate")

    def around(self, inner, envs, ks, actions):
        line = self.stack[-1] if self.stack else REST
        self.total[line] = self.total.get(line, 0) + len(ks)
        return inner(envs, ks, actions)


def by_phase(cfg, workers, out, counted=None):
    """timed_run with a timer around each of PHASES -> (its figures, {line: seconds}, {line:
    actions simulated}), the seconds of a line without those of the lines it holds; "the rest" is
    the time outside. counted: a Flops, whose operations are then booked by phase too."""
    stack = []
    marks = [InPhase(*where, line, stack) for line, (calls, _) in PHASES.items()
             for where in calls]
    actions = Actions(stack)
    if counted is not None:
        counted.stack = stack
    try:
        figures, spent = timed_around({line: calls for line, (calls, _) in PHASES.items()}, cfg,
                                      workers, out)
    finally:
        for wrap in [actions, *reversed(marks)]:
            wrap.restore()
    for line, (_, inner) in PHASES.items():
        spent[line] -= sum(spent[i] for i in inner)
    spent[REST] = figures[0] - sum(spent.values())
    return figures, spent, actions.total


def shares(cfg, out):
    """A run with one worker and one thread, timed around the physics and the networks."""
    calls = {"physics": [(env2d.BlockWorld, "simulate")],
             "network": [(Net, name) for Net in NETWORKS.values() for name in ("forward",
                                                                                "backward")]}
    (total, _, _), spent = timed_around(calls, cfg, 1, out)
    spent["everything else"] = total - sum(spent.values())
    return total, spent


def products(net, B, n, passes=("forward", "backward")):
    """The matrix products of `passes` of `net` on B x n tokens, as operand shapes. Forward: x W
    for every weight W of an MLP or an attention projection, and per head Q K^T and A V.
    Backward: x^T d and d W^T for every W, and per head dY V^T, A^T dY, dS K and dS^T Q."""
    rows, out = B * n, []
    modules = getattr(net, "modules", {"phi": getattr(net, "phi", None),
                                       "rho": getattr(net, "rho", None)})
    for m in modules.values():
        if isinstance(m, nn.MLP):
            Ws, heads = [m.params[f"W{k}"] for k in range(m.n_layers)], {}
        elif isinstance(m, nn.SelfAttention):
            Ws = [m.params[f"W{c}"] for c in m.NAMES]
            h, d = m.heads, m.d
            scores = ((B, h, n, d), (B, h, d, n))                 # Q K^T (and dY V^T)
            mix = ((B, h, n, n), (B, h, n, d))                    # A V (and A^T dY, dS K, dS^T Q)
            heads = {"forward": [scores, mix], "backward": [scores] + [mix] * 3}
        else:
            continue
        for p in passes:
            out += heads.get(p, [])
        for W in Ws:
            i, o = W.shape
            ops = {"forward": [((rows, i), (i, o))],
                   "backward": [((i, rows), (rows, o)), ((rows, o), (o, i))]}
            out += [op for p in passes for op in ops[p]]
    return out


def flops(ops):
    """Floating-point operations of matrix products given as operand shapes: 2 m k p for each
    (m x k) (k x p), times the batch dimensions in front."""
    return sum(2 * int(np.prod(a[:-1])) * a[-1] * b[-1] for a, b in ops)


class Flops:
    """Wraps the forward and backward of every network class (NETWORKS) so that the operations of
    their matrix products (products, flops) add up in self.total {"forward": .., "backward": ..}
    over all the calls, whatever the network or the batch."""

    def __init__(self):
        self.total, self.per_sample = {"forward": 0, "backward": 0}, {}
        self.stack, self.by_phase = [], {}       # by_phase: the operations of each phase's calls
        self.wraps = [Counted(self, Net, name) for Net in NETWORKS.values() for name in self.total]

    def add(self, name, ops):
        self.total[name] += ops
        line = self.stack[-1] if self.stack else REST
        self.by_phase[line] = self.by_phase.get(line, 0) + ops

    def sample(self, net, n, name):
        """The operations of one sample of n tokens through `name` of `net`, found once per
        network shape (replicas and the same network at other batch sizes share it)."""
        key = (type(net), tuple(p.shape for p in net.params.values()), n, name)
        if key not in self.per_sample:
            self.per_sample[key] = flops(products(net, 1, n, (name,)))
        return self.per_sample[key]

    def restore(self):
        for w in self.wraps:
            w.restore()


class Counted(Wrap):
    """One network class's forward or backward, for Flops: each call adds the operations of the
    batch it is given (B samples of n tokens) to counter.total[name]."""

    def __init__(self, counter, Net, name):
        self.counter = counter
        super().__init__(Net, name)

    def around(self, inner, net, x, *args, **kwargs):
        B, n = np.shape(x)[:2]
        self.counter.add(self.name, B * self.counter.sample(net, n, self.name))
        return inner(net, x, *args, **kwargs)


def best_seconds(job, repeats):
    """The fastest of `repeats` timings of job(): a floor should not carry the machine's noise."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        job()
        best = min(best, time.perf_counter() - t0)
    return best


def product_rate(hidden, n_blocks, dtype, repeats=300):
    """Operations per second of one core on a matrix product of one part's shape (bc_batch /
    SHARDS samples x n_blocks tokens, by hidden x hidden), the best of `repeats` timings."""
    x = np.ones((Config.bc_batch // SHARDS * n_blocks, hidden), dtype)
    W = np.ones((hidden, hidden), dtype)
    return flops([(x.shape, W.shape)]) / best_seconds(lambda: x @ W, repeats)


def matmul_seconds(net, B, n, repeats):
    """The matrix products of one forward and backward of `net` on B x n tokens, alone, in one
    thread: the best of `repeats` timings."""
    ops = [(np.ones(a, net.dtype), np.ones(b, net.dtype)) for a, b in products(net, B, n)]

    def all_products():
        for x, y in ops:
            x @ y
    return best_seconds(all_products, repeats)


def two_cores(hidden, repeats=2000):
    """How much more a matrix product and an element-wise loop of one part's shape (128 samples x
    6 blocks, the networks' width) get done on two threads than on one: {name: speed-up}. The
    ceiling of the data-parallel gradients on this machine."""
    x, W = np.ones((768, hidden), np.float32), np.ones((hidden, hidden), np.float32)
    jobs = {"matrix product": lambda: x @ W, "element-wise tanh": lambda: np.tanh(x)}
    out = {}
    for name, job in jobs.items():
        def work():
            for _ in range(repeats):
                job()
        seconds = []
        for threads in (1, 2):
            pool = [threading.Thread(target=work) for _ in range(threads)]
            t0 = time.perf_counter()
            for t in pool:
                t.start()
            for t in pool:
                t.join()
            seconds.append((time.perf_counter() - t0) / threads)      # per unit of work
        out[name] = seconds[0] / seconds[1]
    return out


def network_ratios(cfg, threads):
    """One BC epoch and one PPO update of the default agent on 4096 base demos, with `threads`
    threads -> ((BC seconds, their matrix products alone), (PPO ...), samples)."""
    rng = np.random.default_rng(0)
    env = env2d.BlockWorld(cfg.n_blocks, drop=True)
    tasks, obs, actions = taskexp.base_demos(cfg, env, rng, 4096)
    ag = taskexp.make_agent(cfg)
    ag.threads = threads
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
    p.add_argument("--full-only", action="store_true", help="the timed default run alone (1.)")
    p.add_argument("--out", default=None,
                   help="keep the timed default run here (to compare it with another run)")
    p.add_argument("--hidden", type=int, default=Config.hidden,
                   help=f"the networks' width (default {Config.hidden}, Config's)")
    a = p.parse_args()
    cfg, workers = replace(Config(), hidden=a.hidden), cli.usable_cores()
    print(f"config: the defaults of taskexp_lib.config.Config ({cfg.network} over {cfg.features} "
          f"features, {cfg.hidden} wide, networks in {cfg.dtype}); {workers} cores")
    with tempfile.TemporaryDirectory() as tmp:
        if not a.skip_full:
            out = a.out or os.path.join(tmp, "full")
            counted, physics = Flops(), children_cpu()
            try:
                (total, per_round, cpu), spent, actions = by_phase(cfg, workers, out, counted)
            finally:
                counted.restore()
            physics = children_cpu() - physics
            rounds = ", ".join(f"{k}: {s:.0f} s" for k, s in per_round.items())
            with open(os.path.join(out, "results.json")) as f:
                memory = json.load(f)["wallclock"]["peak_memory_mb"]
            run = "default run" + ("" if a.hidden == Config.hidden else f" --hidden {a.hidden}")
            ops, rate = counted.total, product_rate(cfg.hidden, cfg.n_blocks, cfg.dtype)
            per_action = physics / max(sum(actions.values()), 1)    # the workers' CPU per action
            print(f"\n1. {run}, --workers {workers}: {total:.0f} s ({rounds}); CPU "
                  f"utilisation {cpu:.2f} of {workers} cores; peak memory of the main process "
                  f"{memory} MB. By phase, beside its floor: its matrix products at one core's "
                  f"peak rate and its actions' physics at {per_action * 1e3:.2f} ms of CPU each "
                  f"(the run's mean), over {workers} cores with nothing else done:")
            print(f"   {'phase':36s} {'time':>6s} {'share':>5s} {'floor':>6s} {'x floor':>7s} "
                  f"{'actions':>8s}")
            for name, s in spent.items():
                floor = (counted.by_phase.get(name, 0) / rate
                         + actions.get(name, 0) * per_action) / workers
                ratio = f"{s / floor:6.1f}x" if floor > 0.05 else "      -"
                print(f"   {name:36s} {s:5.0f}s {100 * s / total:4.0f}% {floor:5.0f}s {ratio} "
                      f"{actions.get(name, 0):8d}")
            products_s = sum(ops.values()) / rate
            least = (products_s + physics) / workers
            print(f"   its floor: the networks' matrix products, {sum(ops.values()):.2e} "
                  f"operations (forward {ops['forward']:.2e}, backward "
                  f"{ops['backward']:.2e}), take {products_s:.0f} s of one core at its peak "
                  f"({rate / 1e9:.0f} GFLOP/s on a product of one part's shape); the physics "
                  f"workers used {physics:.0f} s of CPU. With nothing else to do and both kept "
                  f"busy, {workers} cores need {least:.0f} s: the run took {total / least:.2f}x "
                  "that")
        if a.full_only:
            return
        small = cli.parse_args(["--rounds", "1", "--scale", "0.25", "--hidden", str(cfg.hidden),
                                "--out", "unused"]).cfg
        total, spent = shares(small, os.path.join(tmp, "shares"))
        print(f"\n2. where the time goes (--rounds 1 --scale 0.25, one process, one thread): "
              f"{total:.1f} s")
        for name, s in spent.items():
            print(f"   {name:16s} {s:6.1f} s  {100 * s / total:4.0f}%")
        print(f"\n3. networks ({cfg.dtype}): one BC epoch and one PPO update ({cfg.ppo_epochs} "
              "epochs) against their matrix products timed alone (one thread)")
        gains = ", ".join(f"{name} {gain:.2f}x"
                          for name, gain in two_cores(cfg.hidden).items())
        print(f"   both cores against one, alone: {gains}")
        for threads in sorted({1, min(workers, SHARDS)}):
            (bc, bc_mm), (ppo, ppo_mm), n = network_ratios(cfg, threads)
            print(f"   {threads} thread{'s' * (threads > 1)}, {n} samples: BC epoch {bc:.2f} s = "
                  f"{bc / bc_mm:.2f}x its products ({bc_mm:.2f} s); PPO update {ppo:.2f} s = "
                  f"{ppo / ppo_mm:.2f}x ({ppo_mm:.2f} s)")
        print(f"\n4. blocks: time per round (--rounds 1 --scale 0.1, --workers {workers}) and env "
              "speed (one core)")
        for n_blocks in (4, 6, 8):
            shapes = ("I",) if n_blocks < 6 else Config.shapes
            cfg_n = replace(small, n_blocks=n_blocks, shapes=shapes, base_demos=2000,
                            ppo_steps=2000, expand_episodes=300, eval_episodes=10)
            total, per_round, _ = timed_run(cfg_n, workers, os.path.join(tmp, f"n{n_blocks}"))
            line = next(s for s in env_throughput(n_blocks) if s.startswith("actions/s"))
            print(f"   n = {n_blocks}: round 0 {per_round[0]:.1f} s, round 1 {per_round[1]:.1f} s;"
                  f" {' '.join(line.split())}")


if __name__ == "__main__":
    with one_blas_thread():                 # as in a run
        main()
