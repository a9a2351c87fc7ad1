"""taskexp_lib/hindsight.py -- not in the paper: a demonstration of goals g is also one of any part
of g.

Every demonstration task expansion makes moves only blocks that its goals name: a base demo names
the block it moves, an alteration adds or modifies a goal (sec 4.2's restriction), and relabelling
names the goal blocks where they came to rest. So the policy never sees a block that no goal names
move, and cannot clear a site or build a support under a goal in the air. Yet a demonstration
that builds a tower also shows how to put its top block up there with the blocks below carrying no
goal; one that moves a block off a spot and puts another there shows how to clear a site. Here a
demonstration is learnt once more under random parts of its goals, each cut where it first holds
and without the moves it does not need: the simulator replays the moves from s_0 without each one
in turn, and a move is left out when the part still holds without it (as relabelling and
orders.py use the simulator, not a rule about blocks). A part is kept where a block that no goal
of it names still moves: what the demonstration did not show already.
"""
import numpy as np

from .rollout import Trajectory, cut, replay


def goal_part(goals, rng):
    """A random part of goals {block: (x, y)}: 1 to len(goals) - 1 of them, uniform in number,
    then in which."""
    blocks = list(goals)
    keep = rng.permutation(blocks)[: int(rng.integers(1, len(blocks)))]
    return {int(b): goals[int(b)] for b in keep}


def needed_moves(demos, envs, progress=None):
    """The demonstrations (each successful, under its own goals) without the moves their goals
    hold without: one pass over the moves, first to last, each tried by playing from s_0 the
    moves kept so far minus that one (rollout.replay; a pass replays every demonstration at once).
    Returns new Trajectories, in order. progress: a progress bar, advanced per pass.

    The physics is a function of the state and the action (BlockWorld.simulate), so the moves
    kept before t need not be played again: each try starts from the state they reached in the
    last trajectory that held (out[i]). That leaves about half the actions to simulate and a
    third less time, where the parts' replays were a quarter of a run's rounds 2-3 (lab/notes.md),
    and gives the same trajectories as a replay from s_0, bit for bit."""
    out = list(demos)
    keep = [np.ones(len(d.actions), bool) for d in demos]
    for t in range(max((len(d.actions) for d in demos), default=0)):
        tried = [i for i, d in enumerate(demos) if t < len(d.actions) and keep[i].sum() > 1]
        played_before = {i: int(keep[i][:t].sum()) for i in tried}       # the moves kept before t
        # out[i] ends where its goals first hold: if that is within the moves before t, the goals
        # hold without move t (and without every later one), as a replay from s_0 would find
        held = [i for i in tried if played_before[i] >= len(out[i].actions)]
        tried = [i for i in tried if played_before[i] < len(out[i].actions)]
        starts, plans = [], []
        for i in tried:
            later = keep[i].copy()
            later[: t + 1] = False                                      # the kept moves after t
            starts.append((out[i].states[played_before[i]], demos[i].goals))
            plans.append(demos[i].actions[later])
        for i in held:
            keep[i][t] = False
        for i, again in zip(tried, replay(starts, plans, envs)):
            if again.success:                    # the goals hold without move t: leave it out
                keep[i][t] = False
                k = played_before[i]
                out[i] = Trajectory(out[i].goals,
                                    np.concatenate([out[i].states[:k + 1], again.states[1:]]),
                                    np.concatenate([out[i].actions[:k], again.actions]), True)
        if progress is not None:
            progress.update(1)
    return out


def add_parts(demos, envs, rng, draws, progress=None):
    """Adds to each demonstration with two goals or more (demo.parts) the parts of its goals that
    move a block no goal of the part names: up to `draws` parts drawn (goal_part; a part drawn
    twice counts once), each cut where it first holds (rollout.cut), with only the moves it needs
    (needed_moves). The other parts show nothing their demonstration does not.
    progress: as needed_moves'."""
    drawn = []
    for d in demos:
        if len(d.goals) < 2:
            continue
        parts = {tuple(sorted(p)): p for p in (goal_part(d.goals, rng) for _ in range(draws))}
        drawn += [(d, c) for c in (cut(d, p) for p in parts.values()) if c is not None]
    needed = needed_moves([c for _, c in drawn], envs, progress)
    for (d, _), c in zip(drawn, needed):
        if any(int(a[0]) not in c.goals for a in c.actions):
            d.parts.append(c)


def learnt_from(demos):
    """What BC learns from: each demonstration, then its other order (orders.py) and its parts
    where it has them."""
    return [t for d in demos for t in (d, d.other_order, *d.parts) if t is not None]
