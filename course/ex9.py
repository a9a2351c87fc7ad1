"""course/ex9.py -- exercise 9: the expansion step of sec 4.2 (taskexp.join and
taskexp.expansion_step).

The student writes join(first, second, goals, success) -> Trajectory, and
expansion_step(agent, found, cfg, env, short_envs, rng, pieces) -> (demos, reached): for each
successful trajectory s0 -> sT, K one-alteration candidates, g* by pieces.select_goal, one episode
from sT toward g*, the joined trajectory on success, pieces.relabel of it on failure, and nothing
where relabel gives None.

The check runs it in real block worlds (env2d.BlockWorld) with stand-ins that draw nothing at
random, so the result does not depend on the order of the student's calls:
- a scripted agent (Scripted) that drops the lowest unmet goal block at its goal's x;
- pieces.alter replays candidates drawn once by taskexp.alter (ReplayAlter), K per trajectory;
- pieces.select_goal is a fixed function of (s0, sT, candidates) that is not equation (1)
  (PickBy), so that a wrong s0 or sT, or a pick of one's own, shows;
- pieces.relabel replays, for each joined trajectory that failed, what taskexp.relabel
  (exercise 6) returned, or None every third time, as where a block fell off, so that leaving
  those out shows (ReplayRelabel); it refuses any other trajectory.
Its expected demonstrations were made with the reference (taskexp.expansion_step).
"""
import numpy as np

import taskexp
from env2d import BlockWorld
from taskexp_lib.geometry import THRESHOLD, nearest_x_bin
from taskexp_lib.rollout import Trajectory, Worlds, run_episodes

from .grader import Report, call, diff, first, graded
from .vectors import case

# (name, n blocks, K candidates, trajectories to collect); case i has seed 900 + i
CASES = [("three blocks", 3, 4, 6), ("four blocks", 4, 8, 10), ("five blocks", 5, 8, 12),
         ("six blocks, K = 16", 6, 16, 12), ("one trajectory", 4, 8, 1),
         ("no successful trajectory", 4, 8, 0)]

START = ("a demonstration of s0 -> g* starts at s0: the successful trajectory first, then the "
         "episode from its sT")
ONCE = ("the episode from sT starts where the first trajectory ended: in the joined trajectory "
        "that state appears once (and there is an action between every two states)")
PICK = ("g* is the candidate that pieces.select_goal picks for a trajectory from its own s0 and "
        "sT, in equation (1)'s order, among its K = cfg.candidates candidates (see taskexp.py)")
RELABEL = ("on failure the demonstration is pieces.relabel of the joined trajectory s0 -> ... "
           "(under g*), not of one of its halves")
SUCCESS = "success: True for a joined trajectory whose episode reached g*"
DROP = "where pieces.relabel returns None there is no demonstration: leave it out of demos"
REACHED = ("reached: one bool per trajectory of `found`, in order, whether its episode from sT "
           "reached g*")
RUN = ("one episode per trajectory, from its sT toward its g*, in the short worlds short_envs "
       "(run_episodes)")


class Scripted:
    """A stand-in agent that draws nothing at random: it drops the lowest goal block not yet at
    its goal at that goal's x (block 0 where every goal holds). act, sample and value take
    observations (B, n, 6) as agent.Agent's do."""
    threads = 1

    def act(self, obs, deterministic=False, rng=None):
        actions = []
        for o in np.asarray(obs, dtype=np.float64):
            unmet = [b for b in range(len(o)) if o[b, 5] > 0
                     and np.hypot(o[b, 3] - o[b, 0], o[b, 4] - o[b, 1]) >= THRESHOLD]
            b = min(unmet, key=lambda i: (o[i, 4], i)) if unmet else 0
            actions.append([b, nearest_x_bin(o[b, 3] if unmet else o[b, 0]), 0])
        return np.array(actions, np.int64)

    def sample(self, obs, rng=None):
        return self.act(obs), np.zeros(len(obs)), self.value(obs)

    def value(self, obs):
        o = np.asarray(obs, dtype=np.float64)
        return np.exp(-(o[..., 5] * np.hypot(o[..., 3] - o[..., 0],
                                             o[..., 4] - o[..., 1])).sum(-1))


def goals_key(goals):
    """A dict of goals as a hashable key (its blocks and positions, rounded)."""
    return tuple(sorted((int(b), round(float(x), 6), round(float(y), 6))
                        for b, (x, y) in goals.items()))


class ReplayAlter:
    """pieces.alter for the check: replays, for the goals of each trajectory, the K candidates
    drawn for it when the case was made; draws nothing. Records how often it was called."""

    def __init__(self, drawn):
        self.left = {goals_key(g): list(cands) for g, cands in drawn}
        self.calls = 0

    def __call__(self, goals, env, rng, restrict=True, p_add=0.5):
        self.calls += 1
        left = self.left.get(goals_key(goals))
        if not left:
            raise ValueError("pieces.alter was called more than K = cfg.candidates times for one "
                             "trajectory's goals, or with goals no trajectory of `found` has")
        return dict(left.pop(0))


def trajectory_key(traj):
    """A trajectory as a hashable key: its goals, length, first and last states (rounded)."""
    ends = np.round(np.asarray(traj.states)[[0, -1], :, :2], 6)
    return goals_key(traj.goals), len(traj.states), tuple(ends.ravel().tolist())


class ReplayRelabel:
    """pieces.relabel for the check: what taskexp.relabel returned for each joined trajectory
    that failed, when the case was made (None or the fields of a Trajectory)."""

    def __init__(self, seen):
        self.seen = {trajectory_key(Trajectory(**t, success=False)): out for t, out in seen}

    def __call__(self, traj, env):
        key = trajectory_key(traj)
        if key not in self.seen:
            raise ValueError("pieces.relabel was given a trajectory that is not the joined "
                             "trajectory s0 -> ... of a failed episode, under its g*")
        out = self.seen[key]
        return out and Trajectory(**out)


def pick_by(agent, s0, sT, candidates, mode="ours"):
    """pieces.select_goal for the check: a fixed choice (not equation (1), which exercise 6
    checks) among the candidates with the lowest goals, which depends on s0 and sT too."""
    low = [round(sum(y for _, y in g.values()), 6) for g in candidates]
    mixed = [float(np.sum(np.abs(sT[:, :2]) * 3 - np.abs(s0[:, :2]))) * sum(
        x * (b + 2) for b, (x, _) in g.items()) % 1 for g in candidates]
    return int(np.lexsort((mixed, low))[0])


def worlds(n, steps, count):
    """`count` block worlds of n blocks that drop blocks, episodes of `steps` actions."""
    return Worlds([BlockWorld(n, max_steps=steps, drop=True) for _ in range(count)])


def config(n, K):
    return taskexp.Config(n_blocks=n, candidates=K, short_steps=3, max_steps=6)


def trajectory_fields(t):
    return dict(goals=t.goals, states=t.states, actions=t.actions, success=bool(t.success))


def make_case(n, K, count, seed):
    """Successful trajectories of the scripted agent on base-like tasks (some with two goals), the
    candidates drawn for each, and the reference's demonstrations and `reached`."""
    rng = np.random.default_rng(seed)
    cfg, env = config(n, K), BlockWorld(n, max_steps=6, drop=True)
    found = []
    while len(found) < count:                # the tasks of 4 trajectories a time, till enough
        tasks = []
        for _ in range(4):
            env.reset(seed=int(rng.integers(2**31)))
            blocks = rng.permutation(n)[:1 + int(rng.integers(min(n, 3)))]
            goals = {int(b): (float(env.x_bins[rng.integers(37)]), float(env.y_bins[0]))
                     for b in blocks}
            if len({round(x, 3) for x, _ in goals.values()}) < len(goals):   # one spot: one goal
                goals = dict(list(goals.items())[:1])
            tasks.append((env.get_state(), goals))
        found += [t for t in run_episodes(Scripted(), tasks, worlds(n, 6, 4)) if t.success]
        found = list({goals_key(t.goals): t for t in found}.values())[:count]  # goals differ
    drawn = [(t.goals, [taskexp.alter(t.goals, env, rng) for _ in range(K)]) for t in found]
    seen = []

    def relabel(traj, env):       # the reference, or None every third time; both recorded
        out = taskexp.relabel(traj, env) if len(seen) % 3 != 2 else None
        seen.append((dict(goals=traj.goals, states=traj.states, actions=traj.actions),
                     out and trajectory_fields(out)))
        return out
    pieces = taskexp.Pieces(alter=ReplayAlter(drawn), select_goal=pick_by, relabel=relabel)
    demos, reached = taskexp.expansion_step(Scripted(), found, cfg, env, worlds(n, 3, 4), rng,
                                            pieces)
    return dict(found=[trajectory_fields(t) for t in found], drawn=drawn, relabelled=seen,
                demos=[trajectory_fields(d) for d in demos], reached=[bool(r) for r in reached])


def demo_problem(got, want, found):
    """What differs between a student's demonstration and the reference's -> (problem, hint)."""
    try:
        states, actions = np.asarray(got.states), np.asarray(got.actions)
        if not any(np.allclose(states[0], f["states"][0]) for f in found if len(states)):
            return "its first state is no s0 of a trajectory in `found`", START
        if sorted(got.goals) != sorted(want["goals"]) or first(
                *(diff(f"goals[{b}]", got.goals[b], want["goals"][b]) for b in want["goals"])):
            hint = RELABEL if not want["success"] else PICK
            return f"goals {got.goals}, expected {want['goals']}", hint
        if len(states) != len(actions) + 1:
            return f"{len(states)} states and {len(actions)} actions", ONCE
        where = first(diff("states", states, want["states"]),
                      diff("actions", actions, want["actions"]))
        if where:
            return where, (ONCE if len(states) == len(want["states"]) + 1 else
                           RELABEL if not want["success"] else RUN)
        if bool(got.success) != want["success"]:
            return f"success={got.success!r}, expected {want['success']}", SUCCESS
        return None, None
    except Exception as e:
        return (f"a demonstration is malformed ({type(e).__name__}: {e})",
                "demos: a list of Trajectory(goals, states, actions, success)")


def expansion_case(expansion_step, i, name, n, K, count):
    """Case i -> (name, detail, problem, hint)."""
    c = case(f"ex9/step/{i}", lambda: make_case(n, K, count, 900 + i))
    found = [Trajectory(**f) for f in c["found"]]
    pieces = taskexp.Pieces(alter=ReplayAlter(c["drawn"]), select_goal=pick_by,
                            relabel=ReplayRelabel(c["relabelled"]))
    detail = f"n={n}, K={K}, {len(found)} successful trajectories, seed {900 + i}"
    env, short_envs = BlockWorld(n, max_steps=6, drop=True), worlds(n, 3, 4)   # no copies

    def step(found, cfg, pieces):      # call() copies these (the student cannot spoil them)
        return expansion_step(Scripted(), found, cfg, env, short_envs,
                              np.random.default_rng(900 + i), pieces)
    got, err = call(step, found, config(n, K), pieces)
    hint, want = RUN, c["demos"]
    if err is None and not (isinstance(got, (tuple, list)) and len(got) == 2):
        err, hint = f"returned {type(got).__name__}, expected a pair (demos, reached)", REACHED
    elif err and "pieces.relabel was given" in err:
        hint = f"{RELABEL}; {ONCE}"
    elif err is None:
        demos, reached = got
        demos = list(demos)
        if any(d is None for d in demos):
            err, hint = f"demos holds None ({sum(d is None for d in demos)} times)", DROP
        elif [bool(r) for r in reached] != c["reached"]:
            err, hint = (f"reached {[bool(r) for r in reached]}, expected {c['reached']}",
                         REACHED if len(reached) != len(c["reached"]) else
                         f"{REACHED}; a wrong g* changes it too: {PICK}")
        elif len(demos) != len(want):
            err, hint = f"{len(demos)} demonstrations, expected {len(want)}", DROP
        else:
            err, hint = next(((p, h) for p, h in (demo_problem(d, w, c["found"])
                                                   for d, w in zip(demos, want)) if p),
                             (None, None))
    return f"expansion_step, {name}", detail, err, hint


def join_case(join):
    """join on a small made-up pair -> (name, detail, problem, hint)."""
    a = Trajectory({0: (0.0, 0.05)}, np.arange(12.0).reshape(3, 2, 2), np.ones((2, 3), int), True)
    b = Trajectory({1: (0.1, 0.05)}, np.arange(8.0, 16.0).reshape(2, 2, 2),
                   np.zeros((1, 3), int), False)
    goals = {1: (0.2, 0.15)}
    got, err = call(join, a, b, goals, True)
    hint = START + "; " + ONCE
    if err is None:
        try:
            err = first(diff("states", got.states, np.arange(16.0).reshape(4, 2, 2)),
                        diff("actions", got.actions, [[1, 1, 1], [1, 1, 1], [0, 0, 0]]))
            if err is None and (got.goals != goals or got.success is not True):
                err, hint = (f"goals {got.goals}, success {got.success!r}; expected {goals}, "
                             "True"), "the joined trajectory has the goals and success passed in"
        except Exception as e:
            err, hint = f"returned {type(got).__name__} ({type(e).__name__}: {e})", (
                "return a Trajectory(goals, states, actions, success)")
    return "join", "3 states, then 2 that start where they end", err, hint


@graded
def check_ex9(join, expansion_step):
    """join(first, second, goals, success) -> Trajectory;  expansion_step(agent, found, cfg, env,
    short_envs, rng, pieces) -> (demos, reached)."""
    rep = Report("ex9")
    rep.case(*join_case(join))
    for i, args in enumerate(CASES):
        rep.case(*expansion_case(expansion_step, i, *args))
    rep.done(" (the expansion step agrees with the reference, taskexp.expansion_step)")
