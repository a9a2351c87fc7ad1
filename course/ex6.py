"""course/ex6.py -- exercise 6: goal selection by equation (1) (taskexp.select_goal)
and hindsight relabelling on failure (taskexp.relabel).

The student writes select_goal(agent, s0, sT, candidates) -> the index of g*, checked with a
stand-in critic (DistanceCritic) whose values are known, and relabel(traj, env) -> Trajectory or
None, checked against the reference on random trajectories and the two cases that give None.
"""
import numpy as np

import taskexp
from taskexp_lib.geometry import BLOCK_H, X_BINS, observation

from .grader import Report, call, diff, first, graded, tiny_env
from .vectors import case

# select_goal's cases: (number of candidates K, ties: the candidates twice over); case i has
# seed 600 + i and n = 4 + i % 3 blocks
SELECT_CASES = [(1, False), (2, False), (8, False), (8, False), (16, False), (16, True),
                (32, False)]

# relabel's cases: (name, n blocks, T steps, goal blocks, a block falls off, the goal blocks
# stay where they started: nothing achieved, so None); case i has seed 650 + i
RELABEL_CASES = [("random", 4, 3, [1], False, False),
                 ("random, two goal blocks", 5, 4, [0, 2], False, False),
                 ("long, three goal blocks", 6, 6, [1, 2, 4], False, False),
                 ("one step", 3, 1, [0], False, False),
                 ("a block fell off the table", 4, 3, [1], True, False),
                 ("random", 4, 2, [0], False, False),
                 ("goal blocks end where they started", 5, 3, [1], False, True),
                 ("random", 6, 4, [2], False, False), ("random", 4, 5, [3], False, False),
                 ("random", 5, 2, [0], False, False), ("random", 6, 3, [1], False, False),
                 ("random", 4, 4, [2], False, False), ("random", 5, 5, [3], False, False)]

# relabel's hints say what is wrong, not the line that mends it
FELL = ("a block that fell off the table (on_table of the last state is False) makes the "
        "trajectory no usable demonstration")
NONE = ("None means no usable demonstration: a block fell off the table, or the new goals hold "
        "at the first state already (nothing was achieved)")
BLOCKS = "the new goals are for only those blocks that traj.goals names"
WHERE = "a block's new goal is where it rests in the trajectory's last state"
CUT = ("cut at the first step where the new goals hold: an episode toward them would have ended "
       "there, so what follows is no part of its demonstration")
HOLDS = "the relabelled trajectory reaches its goals by construction: it is a success"
EQUATION_1 = ("equation (1): g* = argmax_g V(s_T, g) - V(s_0, g), "
              "with V from agent.value(observation(s, g))")


class DistanceCritic:
    """A stand-in for agent.Agent.value: V(s, g) = exp(-sum of goal distances / 0.3), which is high
    when the goals are near the blocks.  obs (n, 6) -> float, or (B, n, 6) -> (B,)."""

    def value(self, obs):
        o = np.asarray(obs, dtype=np.float64)
        v = np.exp(-(o[..., 5] * np.hypot(o[..., 3] - o[..., 0],
                                          o[..., 4] - o[..., 1])).sum(-1) / 0.3)
        return float(v) if o.ndim == 2 else v


def scene(rng, n):
    """A state (n, 6): blocks on the table at distinct x-bins."""
    s = np.zeros((n, 6))
    s[:, 0], s[:, 1] = rng.choice(X_BINS[::4], n, replace=False), BLOCK_H / 2
    return s


def trajectory(rng, n, T, goal_blocks, fall=False):
    """T random single-block moves onto the grid from a scattered scene; optionally one falls
    off."""
    states = [scene(rng, n)]
    for t in range(T):
        s = states[-1].copy()
        b = int(rng.choice(goal_blocks)) if rng.random() < 0.6 else int(rng.integers(n))
        s[b, :2] = X_BINS[rng.integers(37)], (rng.integers(3) + 0.5) * BLOCK_H
        if fall and t == T - 1:
            s[b, :2] = 0.6, -0.475                       # off the edge, onto the catch floor
        states.append(s)
    goals = {int(b): (float(X_BINS[rng.integers(37)]), BLOCK_H / 2) for b in goal_blocks}
    return dict(goals=goals, states=np.stack(states), actions=rng.integers(0, 6, (T, 3)))


def make_select_case(n, K, ties, seed):
    """s0, sT and K candidates, each one alteration (taskexp.alter) of a one-goal task; with
    ties, the first 8 twice (their scores tie)."""
    rng = np.random.default_rng(seed)
    s0, sT = scene(rng, n), scene(rng, n)
    cands = [taskexp.alter({int(rng.integers(n)): (0.0, BLOCK_H / 2)}, tiny_env(n), rng)
             for _ in range(K)]
    return dict(s0=s0, sT=sT, cands=cands[:8] * 2 if ties else cands)


def make_relabel_case(n, T, blocks, fall, still, seed):
    """A random trajectory (the first goal block kept still if `still`) and the reference's
    relabelling of it (None, or its fields)."""
    traj = trajectory(np.random.default_rng(seed), n, T, blocks, fall)
    if still:
        traj["states"][1:, blocks[0]] = traj["states"][0, blocks[0]]
    want = taskexp.relabel(taskexp.Trajectory(**traj, success=False), tiny_env(n))
    return dict(traj=traj, want=want and dict(goals=want.goals, states=want.states,
                                              actions=want.actions, success=want.success))


def select_case(select_goal, critic, i, K, ties):
    """Select case i -> (name, detail, problem, hint); a wrong index that one of equation (1)'s
    ablations would pick gets that ablation's hint."""
    n = 4 + i % 3
    c = case(f"ex6/select/{i}", lambda: make_select_case(n, K, ties, 600 + i))
    v_0, v_T = (critic.value(np.stack([observation(s, g) for g in c["cands"]]))
                for s in (c["s0"], c["sT"]))
    want = int(np.argmax(v_T - v_0))
    got, err = call(select_goal, critic, c["s0"], c["sT"], c["cands"])
    hint = EQUATION_1 + ("; on ties the first index, as np.argmax" if ties else "")
    ablations = [(np.argmax(v_T), "argmax V(s_T, g) alone (end2new): also subtract V(s_0, g)"),
                 (np.argmin(v_0), "argmin V(s_0, g) alone (init2new): also add V(s_T, g)"),
                 (np.argmax(v_0 - v_T), "argmax V(s_0, g) - V(s_T, g): the sign is reversed")]
    if err is None and got != want:
        err = f"got index {got}, expected {want} (scores {np.round(v_T - v_0, 3).tolist()})"
        guesses = [h for index, h in ablations if index == got]
        hint = "did you pick " + " -- or ".join(guesses) if guesses else hint
    return f"select_goal, K={K} candidates", f"n={n}, seed {600 + i}", err, hint


def trajectory_problem(got, want):
    """What differs, if anything, between the student's relabelled trajectory and the
    reference's (its fields) -> (problem or None, the hint for it)."""
    try:
        if sorted(got.goals) != sorted(want["goals"]):
            return f"goal blocks {sorted(got.goals)}, expected {sorted(want['goals'])}", BLOCKS
        where = first(*(diff(f"goals[{b}]", got.goals[b], want["goals"][b])
                        for b in want["goals"]))
        if where:
            return where, WHERE
        cut = first(diff("states", got.states, want["states"]),
                    diff("actions", got.actions, want["actions"]))
        if cut:
            return cut, CUT
        return (None if bool(got.success) else f"success={got.success!r}, expected True"), HOLDS
    except Exception as e:
        return (f"the returned trajectory is malformed ({type(e).__name__}: {e})",
                "return a Trajectory(goals, states, actions, success), or None")


def relabel_case(relabel, i, name, n, T, blocks, fall, still):
    """Relabel case i -> (name, detail, problem, hint)."""
    c = case(f"ex6/relabel/{i}", lambda: make_relabel_case(n, T, blocks, fall, still, 650 + i))
    want = c["want"]
    got, err = call(relabel, taskexp.Trajectory(**c["traj"], success=False), tiny_env(n))
    hint = FELL if fall else NONE
    if err is None and (got is None) != (want is None):
        err = (f"got {'None' if got is None else 'a trajectory'}, "
               f"expected {'None' if want is None else 'one'}")
    elif err is None and want is not None:
        err, hint = trajectory_problem(got, want)
    return (f"relabel, {name}", f"n={n}, T={T}, goal blocks {blocks}, seed {650 + i}", err, hint)


@graded
def check_ex6(select_goal, relabel):
    """select_goal(agent, s0, sT, candidates) -> index of g*;  relabel(traj, env) -> Trajectory
    or None."""
    rep, critic = Report("ex6"), DistanceCritic()
    for i, (K, ties) in enumerate(SELECT_CASES):
        rep.case(*select_case(select_goal, critic, i, K, ties))
    for i, relabel_args in enumerate(RELABEL_CASES):
        rep.case(*relabel_case(relabel, i, *relabel_args))
    rep.done(" (select_goal follows equation (1); relabel agrees with the reference, "
             "taskexp.relabel)")
