"""taskexp_lib/orders.py -- not in the paper: the generated demonstrations in other orders.

Behaviour cloning learns the order of a demonstration's moves along with the moves. Where that
order is an accident of how the data were made, the policy learns the accident: task expansion
(sec 4.2) joins s0 -> sT and sT -> g*, so its demonstrations move the base task's blocks first,
and the one-step extensions equation (1) picks mostly do not depend on them. The simulator can
tell which orders matter, as it tells in relabelling where the blocks came to rest.
"""
import numpy as np

from .rollout import replay


def other_orders(demos, envs, rng, progress=None):
    """Not in the paper: each demonstration's moves in another order that physics allows.

    A demonstration shows one order of its moves, and BC learns that order's habits with it. A
    joined one moves the blocks of s0 -> sT first and g*'s after, so where g*'s new goal does not
    depend on them (a block put on a free table spot, say) the data insist on "the goals already
    met first", which is "the higher goal first" whenever the base task put its block on
    another; and every round passes on the order the last round's policy happened to choose.
    Here the moves of each demonstration are replayed from s0 in a random other order (the
    reverse, where the draw gives its own): where the simulator meets the same goals, that order
    is kept too (demo.other_order), so the only order the data insist on is the one physics
    demands, a support before what it carries. Like relabelling, a use of the simulator, not a
    rule. progress: a progress bar to advance per demonstration replayed. Returns how many other
    orders were kept.
    """
    moved = [d for d in demos if len(d.actions) > 1]
    plans = []
    for d in moved:
        order = rng.permutation(len(d.actions))
        if (order == np.arange(len(order))).all():
            order = order[::-1]
        plans.append(d.actions[order])
    others = replay([(d.states[0], d.goals) for d in moved], plans, envs, progress)
    for demo, other in zip(moved, others):
        demo.other_order = other if other.success else None
    return sum(other.success for other in others)


def with_other_orders(demos):
    """The demonstrations, each followed by its task in the other order where there is one."""
    return [t for d in demos for t in (d, d.other_order) if t is not None]
