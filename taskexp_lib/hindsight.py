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

from .geometry import is_success
from .rollout import Trajectory, replay, simulate


def goal_part(goals, rng):
    """A random part of goals {block: (x, y)}: 1 to len(goals) - 1 of them, uniform in number,
    then in which."""
    blocks = list(goals)
    keep = rng.permutation(blocks)[: int(rng.integers(1, len(blocks)))]
    return {int(b): goals[int(b)] for b in keep}


def cut(traj, goals):
    """The trajectory under other goals, cut where they first hold; None if they hold at the start
    or never."""
    held = [t for t in range(len(traj.states)) if is_success(traj.states[t], goals)]
    if not held or held[0] == 0:
        return None
    end = held[0] + 1                            # the states up to the first where they hold
    return Trajectory(goals, traj.states[:end], traj.actions[:end - 1], True)


def needed_moves(demos, envs, bar=None):
    """The demonstrations (each successful, under its own goals) with every move their goals hold
    without left out: one pass over the moves, first to last, each tried by replaying from s_0 the
    moves kept so far minus that one (rollout.replay; a pass replays every demonstration at once).
    Updates each demo's states and actions in place. bar: a progress bar, advanced per pass."""
    moves = [d.actions for d in demos]                 # as given; each demo takes shorter ones
    keep = [np.ones(len(m), bool) for m in moves]
    for t in range(max(map(len, moves), default=0)):
        tried = [i for i, m in enumerate(moves) if t < len(m) and keep[i].sum() > 1]
        plans = []
        for i in tried:
            without = keep[i].copy()
            without[t] = False
            plans.append(moves[i][without])
        played = replay([(demos[i].states[0], demos[i].goals) for i in tried], plans, envs)
        for i, again in zip(tried, played):
            if again.success:                    # the goals hold without move t: leave it out
                keep[i][t] = False
                demos[i].states, demos[i].actions = again.states, again.actions
        if bar is not None:
            bar.update(1)


def part_demos(demos, envs, rng, draws, bar=None):
    """Up to `draws` parts of the goals of each demonstration with two goals or more: each drawn
    part (goal_part; a part drawn twice counts once) cut where it first holds (cut), with only the
    moves it needs (needed_moves). Kept in demo.parts are those that move a block no goal of the
    part names: the others show nothing their demonstration does not. Returns how many were kept.
    bar: as needed_moves'."""
    drawn = []
    for d in demos:
        if len(d.goals) < 2:
            continue
        parts = {tuple(sorted(p)): p for p in (goal_part(d.goals, rng) for _ in range(draws))}
        drawn += [(d, c) for c in (cut(d, p) for p in parts.values()) if c is not None]
    needed_moves([c for _, c in drawn], envs, bar)
    for d, c in drawn:
        if any(int(a[0]) not in c.goals for a in c.actions):
            d.parts.append(c)
    return sum(len(d.parts) for d in demos)


def move_pairs(envs, rng, count, move, on_table, bar):
    """`count` two-move demonstrations for the parts of round 0 (taskexp.base_skills): in a
    scattered scene two different random blocks move one after the other, move(env, rng) ->
    (block, action) or None (taskexp.random_move); the goals are where both came to rest. Moves
    that change nothing, leave the scene unstable or a block off the table (on_table(state, env)
    False) are dropped, as in taskexp.base_demos. A part that names the second block alone needs
    the first move where it cleared or built the second one's spot. Returns Trajectories."""
    pairs = []
    with bar(total=count, desc="pairs") as progress:
        while len(pairs) < count:
            for env in envs:
                env.reset(seed=int(rng.integers(2**31)))
            runs = {k: ([env.get_state()], [], []) for k, env in enumerate(envs)}   # s, a, blocks
            for step in (1, 2):
                moves = {k: move(envs[k], rng) for k in runs}
                moves = {k: m for k, m in moves.items() if m is not None}
                outcomes = simulate(envs, list(moves), [a for _, a in moves.values()])
                for (k, (b, a)), outcome in zip(moves.items(), outcomes):
                    info, s1 = envs[k].finish_step(outcome)[-1], envs[k].get_state()
                    states, actions, blocks = runs[k]
                    moved = np.linalg.norm(s1[b, :2] - states[-1][b, :2]) >= envs[k].threshold
                    if moved and b not in blocks and info["stable"] and on_table(s1, envs[k]):
                        states.append(s1)
                        actions.append(a)
                        blocks.append(b)
                runs = {k: runs[k] for k in moves if len(runs[k][1]) == step}   # usable so far
            for states, actions, blocks in list(runs.values())[: count - len(pairs)]:
                goals = {b: (float(states[-1][b, 0]), float(states[-1][b, 1])) for b in blocks}
                pairs.append(Trajectory(goals, np.stack(states), np.stack(actions), True))
                progress.update(1)
    return pairs


def pair_parts(envs, rng, count, move, on_table, bar):
    """The parts of `count` two-move demonstrations (move_pairs) that move a block no goal of
    theirs names (part_demos; 4 draws find both parts of a pair 7 times in 8)."""
    pairs = move_pairs(envs, rng, count, move, on_table, bar)
    part_demos(pairs, envs, rng, draws=4)
    return [p for d in pairs for p in d.parts]


def learnt_from(demos):
    """What BC learns from: each demonstration, then its other order (orders.py) and its parts
    where it has them."""
    return [t for d in demos for t in (d, d.other_order, *d.parts) if t is not None]
