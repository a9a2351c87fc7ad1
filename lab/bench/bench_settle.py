"""How long the world takes to come to rest: substeps per action over many random and adversarial
actions, to show that env2d.MAX_SUBSTEPS is not cut short.

    python lab/bench/bench_settle.py [--episodes 6000] [--seed 7]

Episodes as in the property test tests/test_env2d.py::test_physics_never_breaks, with the same
stack_tower and adversarial_action (taskexp_lib/stress.py): 2 to 8 blocks, half of them starting
from a tower as tall as it gets, then 1 to 40 actions, each aimed uniformly, at the table's edge,
far in the air, into another block or onto it. Prints the mean, percentiles and the maximum of
the substeps to rest (60 a second) and how many actions hit the cap. About 25 s per 6000 episodes.
"""


import argparse

import numpy as np

import env2d
from env2d import BlockWorld
from taskexp_lib.stress import adversarial_action, stack_tower


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--episodes", type=int, default=6000)
    p.add_argument("--seed", type=int, default=7)
    a = p.parse_args()
    rng, substeps = np.random.default_rng(a.seed), []
    integers = lambda lo, hi: int(rng.integers(lo, hi + 1))           # noqa: E731
    choice = lambda seq: seq[int(rng.integers(len(seq)))]            # noqa: E731  (draws as rng.choice)
    for _ in range(a.episodes):
        n = int(rng.integers(2, 9))
        env = BlockWorld(n, max_steps=10**6)
        env.reset(seed=int(rng.integers(2**16)))
        if rng.random() < 0.5:
            stack_tower(env)
        for _ in range(int(rng.integers(1, 41))):
            info = env.step(adversarial_action(env.get_state(), integers, choice))[4]
            if not info["noop"]:
                substeps.append(info["settle_steps"])
    s = np.array(substeps)
    pct = np.percentile(s, [50, 90, 99, 99.9])
    print(f"{len(s)} actions; substeps to rest: mean {s.mean():.2f}, median {pct[0]:.0f}, "
          f"90% {pct[1]:.0f}, 99% {pct[2]:.0f}, 99.9% {pct[3]:.0f}, "
          f"max {s.max()} ({s.max() * env2d.DT:.1f} s); "
          f"{(s >= env2d.MAX_SUBSTEPS).sum()} at the cap of {env2d.MAX_SUBSTEPS}")


if __name__ == "__main__":
    main()
