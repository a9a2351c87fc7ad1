"""taskexp_lib/rollout.py -- episodes of the goal-conditioned policy in the block world (sec 3):
a batch of tasks run over several worlds at once, with one batched policy call per step, and the
physics of those worlds in worker processes when there is more than one core.

Results do not depend on the number of workers: a step is a pure function of (state, action)
(env2d.BlockWorld.simulate), and every random draw happens in the main process.
"""
import multiprocessing
import signal
from dataclasses import dataclass, field

import numpy as np

from .geometry import THRESHOLD, is_success, observation

_MAKE_WORLD, _WORLDS = None, {}   # a worker's own worlds, by block count, which simulate for
                                  # the main process


def _start_worker(make_world):
    global _MAKE_WORLD
    signal.signal(signal.SIGINT, signal.SIG_IGN)    # Ctrl-C is the main process's to handle
    _MAKE_WORLD = make_world


def _simulate(job):
    state, action = job
    if len(state) not in _WORLDS:
        _WORLDS[len(state)] = _MAKE_WORLD(len(state))
    return _WORLDS[len(state)].simulate(state, action)


class PhysicsPool:
    """Worker processes that run world.simulate for the worlds of the main process; each worker
    makes its own world of n blocks with make_world(n) (env2d.physics_pool: a BlockWorld) when it
    first meets a state of n blocks.

    Started with "spawn", which works the same on Linux, macOS and Windows and from a notebook.
    A worker whose main process dies (even by SIGKILL) finds its pipe closed and exits.
    """

    def __init__(self, workers, make_world):
        self.workers = workers
        context = multiprocessing.get_context("spawn")
        self._pool = context.Pool(workers, initializer=_start_worker, initargs=(make_world,))

    def simulate(self, states, actions):
        """[(state after, noop, stable, substeps)] for each (state, action), in order."""
        jobs = list(zip(states, actions))
        chunk = -(-len(jobs) // self.workers)        # one message per worker and step
        return self._pool.map(_simulate, jobs, chunksize=chunk)

    def close(self):
        self._pool.terminate()
        self._pool.join()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class Worlds(list):
    """Worlds that run_episodes steps together: a list, and the PhysicsPool (or None) that runs
    their physics (env2d.run_worlds makes a run's)."""

    def __init__(self, worlds, pool=None):
        super().__init__(worlds)
        self.pool = pool


@dataclass
class Trajectory:
    """One episode. states (T+1, n, 6), actions (T, 3); logp and values (T,) from the sampler."""
    goals: dict
    states: np.ndarray
    actions: np.ndarray
    success: bool
    logp: np.ndarray = None
    values: np.ndarray = None
    other_order: "Trajectory" = None    # the same task, its moves in another order (orders.py)
    parts: list = field(default_factory=list)    # parts of its goals, their moves (hindsight.py)

    def obs(self, goals=None):
        """Observations (T+1, n, 6) of the visited states under `goals` (default: its own)."""
        g = self.goals if goals is None else goals
        return np.stack([observation(s, g) for s in self.states])


def cut(traj, goals, threshold=THRESHOLD):
    """The trajectory under other goals, ended where they first hold, as its episode would have
    ended (success); None if they hold at the start (it achieves nothing) or never."""
    T = next((t for t, s in enumerate(traj.states) if is_success(s, goals, threshold)), None)
    if T is None or T == 0:
        return None
    return Trajectory(goals, traj.states[:T + 1], traj.actions[:T], True)


def simulate(envs, ks, actions):
    """The physics of one action in each world envs[k], k in ks -> [(state after, noop, stable,
    substeps)] in order: in the workers of envs.pool if there is one, else one after the other."""
    states = [envs[k].get_state() for k in ks]
    pool = getattr(envs, "pool", None)
    if pool is None:
        return [envs[k].simulate(state, a) for k, state, a in zip(ks, states, actions)]
    return pool.simulate(states, actions)


def run_episodes(agent, tasks, envs, rng=None, deterministic=False, progress=None, values=True):
    """Run one episode per task, len(envs) at a time with one batched policy call per step.

    tasks: list of (state (n, 6), goals); envs: a list of BlockWorlds, or Worlds whose pool
    runs the physics. Returns a list of Trajectory in the order of `tasks`.
    progress: a progress bar (a tqdm) to advance by one per finished episode.
    values: record log pi(a) and V(s, g) of every step, which PPO needs; without them (0s) the
    critic is not run, and the actions drawn are the same.
    """
    out = [None] * len(tasks)
    todo = iter(range(len(tasks)))
    slots = [None] * len(envs)

    def start(k):
        i = next(todo, None)
        if i is None:
            slots[k] = None
            return
        state, goals = tasks[i]
        obs, _ = envs[k].reset(options={"state": state, "goals": goals})
        slots[k] = dict(i=i, obs=obs, states=[envs[k].get_state()], actions=[], logp=[], values=[])

    for k in range(len(envs)):
        start(k)
    while True:
        active = [k for k, s in enumerate(slots) if s is not None]
        if not active:
            return out
        obs = np.stack([slots[k]["obs"] for k in active])
        if values and not deterministic:
            actions, logp, v = agent.sample(obs, rng)
        else:
            actions = agent.act(obs, deterministic, rng)
            logp = v = np.zeros(len(active))
        outcomes = simulate(envs, active, actions)
        for j, k in enumerate(active):
            s = slots[k]
            s["obs"], reward, terminated, truncated, _ = envs[k].finish_step(outcomes[j])
            s["states"].append(envs[k].get_state())
            s["actions"].append(actions[j])
            s["logp"].append(logp[j])
            s["values"].append(v[j])
            if terminated or truncated:
                out[s["i"]] = Trajectory(tasks[s["i"]][1], np.stack(s["states"]),
                                         np.stack(s["actions"]), bool(terminated),
                                         np.array(s["logp"]), np.array(s["values"]))
                if progress is not None:
                    progress.update(1)
                start(k)


def replay(tasks, plans, envs, progress=None):
    """Play fixed sequences of actions: for tasks[i] = (state, goals), the actions plans[i] (T, 3)
    in order, len(envs) tasks at a time, until the goals hold (stable) or the plan ends; the
    worlds' step budget does not cut a plan. Returns a list of Trajectory in the order of tasks,
    success True when the goals held at the end. progress: a progress bar to advance per task."""
    out = []
    for start in range(0, len(tasks), len(envs)):
        chunk = range(start, min(start + len(envs), len(tasks)))
        for k, i in enumerate(chunk):
            envs[k].reset(options={"state": tasks[i][0], "goals": tasks[i][1]})
        states = [[tasks[i][0]] for i in chunk]
        done = [False] * len(chunk)
        for t in range(max(len(plans[i]) for i in chunk)):
            ks = [k for k, i in enumerate(chunk) if not done[k] and t < len(plans[i])]
            if not ks:
                break
            outcomes = simulate(envs, ks, [plans[chunk[k]][t] for k in ks])
            for k, outcome in zip(ks, outcomes):
                done[k] = envs[k].finish_step(outcome)[2]                  # terminated: success
                states[k].append(envs[k].get_state())
        for k, i in enumerate(chunk):
            played = np.asarray(plans[i])[:len(states[k]) - 1]
            out.append(Trajectory(tasks[i][1], np.stack(states[k]), played, done[k]))
        if progress is not None:
            progress.update(len(chunk))
    return out


def success_rate(trajs):
    return float(np.mean([t.success for t in trajs])) if trajs else 0.0
