"""Throughput of the block world: actions per second for n = 6 on one core, and how far that is from
the cost of pymunk's own stepping.

    python lab/bench/bench_env.py [--actions 2000] [--n-blocks 6] [--repeats 3]

Random actions (random block, x-bin and layer) from random scattered starts, resetting every 10
steps. Each action costs a teleport test, the physics reset to the state (exactness), the substeps
until rest and the rest checks. The floor is the stepping alone, timed on the same scenes for the
same number of substeps: pymunk's Space.step, and chipmunk's cpSpaceStep as env2d calls it. The
last two lines are the ratios of the env's cost to these floors (1.0: nothing but stepping).
Best of --repeats runs.
"""


import argparse
import time

import numpy as np

from env2d import DROP_GAP, DT, BlockWorld, _space_step


def run(env, actions, seed):
    """Step through `actions` (N, 3), resetting every 10. Returns (seconds, starts, substeps)."""
    starts, substeps = [], []
    t0 = time.perf_counter()
    for i, a in enumerate(actions):
        if i % 10 == 0:
            env.reset(seed=seed + i)
        start = env.get_state()
        _, _, _, _, info = env.step(a)
        if not info["noop"]:
            start[a[0]] = (env.x_bins[a[1]], env.y_bins[a[2]] + DROP_GAP, 0, 0, 0, 0)
            starts.append(start)
            substeps.append(info["settle_steps"])
    return time.perf_counter() - t0, starts, substeps


def physics_only(env, starts, substeps, raw):
    """Seconds spent stepping alone for the same scenes and substep counts: pymunk's Space.step,
    or (raw) chipmunk's cpSpaceStep as env2d calls it."""
    total = 0.0
    for start, k in zip(starts, substeps):
        env._load(start)       # private: the same space the env would simulate
        env._space.step(0.0)   # pymunk's one-off checks of new bodies (0 does nothing)
        step, args = (_space_step, (env._space._space, DT)) if raw else (env._space.step, (DT,))
        t0 = time.perf_counter()
        for _ in range(k):
            step(*args)
        total += time.perf_counter() - t0
    return total


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--actions", type=int, default=2000)
    p.add_argument("--n-blocks", type=int, default=6)
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args(argv)
    env = BlockWorld(args.n_blocks, max_steps=10)
    rng = np.random.default_rng(0)
    actions = np.stack([rng.integers(env.action_space.nvec) for _ in range(args.actions)])
    seconds, starts, substeps = min((run(env, actions, seed=1) for _ in range(args.repeats)),
                                    key=lambda r: r[0])
    step_s = min(physics_only(env, starts, substeps, False)
                 for _ in range(args.repeats)) / sum(substeps)
    raw_s = min(physics_only(env, starts, substeps, True)
                for _ in range(args.repeats)) / sum(substeps)
    per_action = seconds / len(actions)
    mean_sub = sum(substeps) / len(actions)              # no-ops count with 0 substeps
    print(f"n_blocks={args.n_blocks}  actions={len(actions)}  no-ops={len(actions) - len(starts)}")
    print(f"actions/s                        {1 / per_action:8.0f}")
    print(f"time per action                  {per_action * 1e6:8.1f} us")
    print(f"mean settle substeps per action  {mean_sub:8.2f}   "
          f"(per simulated action {np.mean(substeps):.2f})")
    print(f"pymunk Space.step per substep    {step_s * 1e6:8.2f} us")
    print(f"chipmunk cpSpaceStep per substep {raw_s * 1e6:8.2f} us   (what env2d calls)")
    ratio_step, ratio_raw = per_action / (step_s * mean_sub), per_action / (raw_s * mean_sub)
    print("ratio: time per action / (time per substep * mean substeps), stepping alone")
    print(f"  to pymunk's Space.step                 {ratio_step:6.2f}")
    print(f"  to chipmunk's cpSpaceStep              {ratio_raw:6.2f}")


if __name__ == "__main__":
    main()
