"""taskexp_lib/shards.py -- one minibatch on both cores, with the same bytes for any number of
threads (data-parallel gradients).

A minibatch is always cut into SHARDS parts. Each part runs its forward and backward on a
replica of the network (the same parameter arrays, its own caches), and the parts' gradients
are added in a fixed order, each weighted by its share of the minibatch:

    L = mean over the B samples  =>  dL/dtheta = sum_k (B_k / B) dL_k/dtheta

where L_k is the same loss over part k alone. With one thread the parts run one after the
other, with two side by side: the same arithmetic either way, so a run's results do not depend
on how many threads it has. numpy releases the GIL inside BLAS and its element-wise loops, so
Python threads are enough, and they share the networks without copying them.

Agent's updates (agent.py) are written as one plain minibatch step, loss_and_grads(*nets, idx);
DataParallel wraps that function from outside, so none of the above shows in them.
"""
import copy
from concurrent.futures import ThreadPoolExecutor

import numpy as np

SHARDS = 2


def replica(net):
    """A copy of an AttentionNet or SetNet that shares its parameter arrays (an optimiser step
    updates both) but keeps its own forward caches, so that two replicas can run at once."""
    twin = copy.copy(net)
    if hasattr(net, "modules"):                                    # AttentionNet
        twin.modules = {name: copy.copy(m) for name, m in net.modules.items()}
    else:                                                          # SetNet
        twin.phi, twin.rho = copy.copy(net.phi), copy.copy(net.rho)
    return twin


def split(idx):
    """A minibatch's indices -> its SHARDS parts, in order (no empty part)."""
    return [part for part in np.array_split(idx, SHARDS) if len(part)]


def weighted_sum(values, weights):
    """sum_k weights[k] values[k], added in order; values: arrays, floats, or dicts of arrays."""
    if isinstance(values[0], dict):
        return {key: weighted_sum([v[key] for v in values], weights) for key in values[0]}
    total = values[0] * weights[0]
    for v, w in zip(values[1:], weights[1:]):
        total = total + v * w
    return total


class Shards:
    """Runs step(k, part) for the parts of a minibatch, part 0 in the calling thread and the
    others in threads - 1 helper threads. A context manager: the helpers stop on exit."""

    def __init__(self, threads):
        self.pool = ThreadPoolExecutor(threads - 1) if threads > 1 else None

    def map(self, step, parts):
        """-> [step(k, parts[k]) for every k], in order."""
        if self.pool is None:
            return [step(k, part) for k, part in enumerate(parts)]
        futures = [self.pool.submit(step, k, part) for k, part in enumerate(parts) if k > 0]
        first = step(0, parts[0])
        return [first] + [f.result() for f in futures]

    def mean(self, step, idx):
        """The minibatch idx in its parts: step(k, part) gives a tuple of means over part k
        (losses, gradients); -> the same tuple over the whole minibatch, sum_k (B_k / B) (...)_k."""
        parts = split(idx)
        weights = [len(p) / len(idx) for p in parts]                   # B_k / B
        return tuple(weighted_sum(v, weights) for v in zip(*self.map(step, parts)))

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.pool is not None:
            self.pool.shutdown()


class DataParallel:
    """Data-parallel gradients from outside a plain minibatch step. For fn(*nets, idx) -> a tuple
    of means over the samples idx (losses, gradients as dicts, logged figures),

        parallel(fn, idx) = sum_k (B_k / B) fn(*replicas_k, part_k)

    over the SHARDS parts of idx, each part on its own replicas of the networks (so the forward
    caches of two parts never meet), part 0 in the calling thread and the others in threads - 1
    helper threads. This is fn(*nets, idx) up to rounding, and the same bytes for any number of
    threads. fn must use the networks it is given, never the originals. A context manager: the
    helpers stop on exit. Agent.data_parallel makes one with the agent's threads."""

    def __init__(self, nets, threads):
        self.replicas = [[replica(net) for net in nets] for _ in range(SHARDS)]
        self.shards = Shards(threads)

    def __call__(self, fn, idx):
        return self.shards.mean(lambda k, part: fn(*self.replicas[k], part), idx)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.shards.__exit__(*exc)


def read_only_map(agent, fn, items, threads):
    """[fn(twin, item) for item in items], with the items cut into `threads` runs that go side
    by side, each on its own replica `twin` of the agent (the networks' replicas). For work that
    only reads the agent and draws nothing at random, such as the values of equation (1): the
    results are those of one thread."""
    runs = [run for run in np.array_split(np.arange(len(items)), threads) if len(run)]
    if len(runs) < 2:
        return [fn(agent, item) for item in items]

    def run(k, idx):
        twin = copy.copy(agent)
        twin.actor, twin.critic = replica(agent.actor), replica(agent.critic)
        return [fn(twin, items[i]) for i in idx]

    with Shards(threads) as shards:
        return [out for part in shards.map(run, runs) for out in part]
