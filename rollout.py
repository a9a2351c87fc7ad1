"""rollout.py -- episodes of the goal-conditioned policy in the block world (sec 3): a batch of
tasks run over several environments at once, with one batched policy call per step."""
from dataclasses import dataclass

import numpy as np

from env2d import observation


@dataclass
class Trajectory:
    """One episode. states (T+1, n, 6), actions (T, 3); logp and values (T,) from the sampler."""
    goals: dict
    states: np.ndarray
    actions: np.ndarray
    success: bool
    logp: np.ndarray = None
    values: np.ndarray = None

    def obs(self, goals=None):
        """Observations (T+1, n, 6) of the visited states under `goals` (default: its own)."""
        g = self.goals if goals is None else goals
        return np.stack([observation(s, g) for s in self.states])


def run_episodes(agent, tasks, envs, rng=None, deterministic=False, bar=None):
    """Run one episode per task, len(envs) at a time with one batched policy call per step.

    tasks: list of (state (n, 6), goals). Returns a list of Trajectory in the order of `tasks`.
    bar: a progress bar (tqdm) to advance by one per finished episode.
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
        if deterministic:
            no_stats = np.zeros(len(active))
            actions, logp, values = agent.act(obs, deterministic=True), no_stats, no_stats
        else:
            actions, logp, values = agent.sample(obs, rng)
        for j, k in enumerate(active):
            s = slots[k]
            s["obs"], reward, terminated, truncated, _ = envs[k].step(actions[j])
            s["states"].append(envs[k].get_state())
            s["actions"].append(actions[j])
            s["logp"].append(logp[j])
            s["values"].append(values[j])
            if terminated or truncated:
                out[s["i"]] = Trajectory(tasks[s["i"]][1], np.stack(s["states"]),
                                         np.stack(s["actions"]), bool(terminated),
                                         np.array(s["logp"]), np.array(s["values"]))
                if bar is not None:
                    bar.update(1)
                start(k)


def success_rate(trajs):
    return float(np.mean([t.success for t in trajs])) if trajs else 0.0
