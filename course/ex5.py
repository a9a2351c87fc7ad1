"""course/ex5.py -- exercise 5: one-alteration task sampling (taskexp.alter, sec
4.2).

The student writes alter(goals, env, rng) -> a new goal dict: exactly one goal added for a free
block, or one goal modified. alter is random, so the check samples it: each sample must follow
the rules (one alteration, on the grid, not on the spot another goal names, the input unchanged),
and all samples together must show both kinds half the time each where a block is free, every
block and the whole grid, reproducibly from the rng passed in.
"""
import copy
from types import SimpleNamespace

import numpy as np

from taskexp_lib.geometry import on_same_spot

from .grader import NOT_DONE, Report, Wrong, graded, tiny_env

GRID = "goal positions lie on the action grid: (env.x_bins[i], env.y_bins[k]) for uniform i, k"
SPOT = ("the new position must not be the spot another goal names: no two blocks can meet both "
        "(geometry.on_same_spot says when two positions are one spot); draw again")

# (name, n_blocks, the blocks with a goal); case i has seed 500 + i
CASES = [("one goal, six blocks", 6, [2]), ("three goals, six blocks", 6, [0, 3, 5]),
         ("no free block (every block has a goal)", 6, range(6)),
         ("two blocks, one goal", 2, [1]), ("one block with a goal", 1, [0])]


def as_goals(goals):
    """{block: (x, y)} with plain ints and floats, so dicts of numpy values compare with ==."""
    out = {int(b): tuple(map(float, p)) for b, p in goals.items()}
    if any(len(p) != 2 for p in out.values()):
        raise ValueError("a goal position is a pair (x, y)")
    return out


def random_goals(env, rng, blocks):
    """A goal on the grid for each of `blocks`: the task the case alters."""
    return {int(b): (float(env.x_bins[rng.integers(37)]),
                     float(env.y_bins[rng.integers(env.n_blocks)])) for b in blocks}


def call_alter(alter, goals, env, rng):
    """The student's alter(goals, env, rng); raises Wrong if it raises or changes its input."""
    before = copy.deepcopy(goals)
    try:
        new = alter(goals, env, rng)
    except NotImplementedError:
        raise Wrong(NOT_DONE, "") from None
    except Exception as e:
        raise Wrong(f"raised {type(e).__name__}: {e}",
                    "with no free block you can only modify") from None
    if len(goals) != len(before) or any(not np.array_equal(goals.get(b), p)
                                        for b, p in before.items()):
        raise Wrong(f"changed its input to {goals}", "copy the dict first: new = dict(goals)")
    return new


def one_alteration(new, goals, env, i):
    """Sample i, new, as goals -> (new, blocks added, blocks modified); raises Wrong unless it
    keeps every goal, alters one and stays on the grid."""
    if (not isinstance(new, dict) or not set(goals) <= set(new)
            or not set(new) <= set(range(env.n_blocks))):
        raise Wrong(f"sample {i}: {new}", "keep every goal of the input; add only blocks 0..n-1")
    try:
        new = as_goals(new)                      # numpy positions are fine; compare as floats
    except (TypeError, ValueError):
        raise Wrong(f"sample {i}: {new}", "a goal position is a pair of numbers (x, y)") from None
    add = [b for b in new if b not in goals]
    mod = [b for b in goals if not np.allclose(new[b], goals[b])]
    if len(add) + len(mod) > 1:
        raise Wrong(f"sample {i}: {new} adds {add} and modifies {mod}",
                    "one alteration: add ONE goal for a free block, or modify ONE existing goal")
    if any(np.abs(env.x_bins - x).min() > 1e-9 or np.abs(env.y_bins - y).min() > 1e-9
           for x, y in (new[b] for b in add + mod)):
        raise Wrong(f"sample {i}: {new} has a goal off the grid", GRID)
    if any(on_same_spot(new[b], new[other]) for b in add + mod for other in new if other != b):
        raise Wrong(f"sample {i}: {new} gives block {(add + mod)[0]} a goal on another goal's "
                    "spot", SPOT)
    return new, add, mod


def sample_alterations(alter, goals, env, rng, samples):
    """`samples` calls of alter, each one alteration -> what they did: the kind of each, the
    blocks added and modified, the x's and y's of the new positions."""
    seen = SimpleNamespace(kinds=[], added=set(), modified=set(), xs=set(), ys=set())
    for i in range(samples):
        new, add, mod = one_alteration(call_alter(alter, goals, env, rng), goals, env, i)
        pos = [new[b] for b in add + mod]
        seen.kinds.append("add" if add else "modify" if mod else "none")
        seen.added.update(add), seen.modified.update(mod)
        seen.xs.update(np.round([x for x, _ in pos], 9))
        seen.ys.update(np.round([y for _, y in pos], 9))
    return seen


def judge_spread(seen, goals, n, samples):
    """Raises Wrong unless the samples change something, use both kinds when a block is free,
    every block, and (nearly) every x-bin and layer."""
    free = [b for b in range(n) if b not in goals]
    share = {k: seen.kinds.count(k) / samples for k in ("add", "modify", "none")}
    if share["none"] > 0.08:        # a modify may land on its old spot: 1 in 37 with one layer
        raise Wrong(f"{share['none']:.0%} of samples change nothing",
                    "a modification must move the goal (a uniform new position almost always "
                    "does)")
    if free and not 0.4 <= share["add"] <= 0.6:          # 4 standard deviations of 400 draws
        raise Wrong(f"adds {share['add']:.0%}, modifies {share['modify']:.0%} of the time",
                    "with a free block, choose add or modify at random (50/50), "
                    "so both cases occur half the time each")
    if set(free) - seen.added or set(goals) - seen.modified:
        raise Wrong(f"never added {sorted(set(free) - seen.added)}, never modified "
                    f"{sorted(set(goals) - seen.modified)}", "choose the block uniformly")
    if len(seen.xs) < 30 or len(seen.ys) < n:
        raise Wrong(f"used only {len(seen.xs)} of 37 x-bins and {len(seen.ys)} of {n} layers",
                    GRID)


def judge_reproducible(alter, goals, env, seed):
    """Raises Wrong unless alter draws only from the rng passed in."""
    draw = lambda: [as_goals(alter(goals, env, np.random.default_rng(seed))) for _ in range(5)]
    if draw() != draw():
        raise Wrong("two runs with the same seed differ",
                    "draw only from rng, not np.random or random")


@graded
def check_ex5(alter, samples=400):
    """alter(goals, env, rng) -> a new goal dict: exactly one goal added or one goal modified."""
    rep = Report("ex5")
    for seed, (name, n, blocks) in enumerate(CASES):
        env, rng = tiny_env(n), np.random.default_rng(500 + seed)
        goals = random_goals(env, rng, blocks)
        shown = {b: (round(x, 3), round(y, 3)) for b, (x, y) in goals.items()}
        detail = f"goals {shown}, n_blocks={n}, seed {500 + seed}"
        try:
            seen = sample_alterations(alter, goals, env, rng, samples)
            judge_spread(seen, goals, n, samples)
            judge_reproducible(alter, goals, env, seed)
            rep.case(name, detail, None, "")
        except Wrong as wrong:
            rep.case(name, detail, wrong.problem, wrong.hint)
    rep.done(f" ({samples} samples each: one alteration off the other goals' spots, both kinds "
             "half the time each, every block, the whole grid)")
