"""taskexp.py -- task expansion end to end: base skills, expansion rounds, zero-shot evaluation.

The pipeline of "Self-Generating Data for Goal-Conditioned Compositional Problems" (Yuan, Li, Wu),
sections 4 and 5, on the 2D block world of env2d.py with the numpy agent of agent.py:

  sec 4.1  base policy   single-block demos -> behaviour cloning -> PPO fine-tuning
  sec 4.2  expansion     successful trajectory s0 -> sT, K one-alteration candidates g,
                         g* = argmax_g V(sT, g) - V(s0, g)   (equation 1),
                         run the policy from sT toward g*: join on success, relabel on failure
  sec 4.3  distillation  BC on the generated demos, then PPO on the generated tasks; repeat
  sec 5    evaluation    zero-shot success on held-out shapes ("I", "Y", "3T") after every round

    python taskexp.py --rounds 3            # the laptop run behind the README's numbers
    python taskexp.py --select end2new      # an ablation of Table 3

A task is a pair (s0, goals): a state array (n_blocks, 6) and a dict {block: (x, y)}.
~800 lines; keep it there.
"""
import os

# Tiny matmuls are 10-100x slower with two BLAS threads here, and results drift: pin to one
# before numpy loads its BLAS.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import glob
import json
import sys
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from agent import Agent, gae
from env2d import BLOCK_H, BLOCK_W, BlockWorld, is_success, observation


@dataclass
class Config:
    """Every knob of a run. The defaults are the laptop run that the README reports."""
    seed: int = 0
    rounds: int = 3                 # rounds of task expansion + self-distillation (sec 4.2-4.3)
    n_blocks: int = 6
    max_steps: int = 10             # actions per episode before truncation
    short_steps: int = 3            # budget of the verification run (sec 4.2) and of stretch tasks
    hidden: int = 128               # width of the actor's and critic's per-block networks
    n_envs: int = 32                # environments stepped in lockstep (one batched policy call)
    # sec 4.1: base skills
    base_demos: int = 20000         # single-block demonstrations
    warmup: int = 8                 # up to this many random moves before a demo: stacks of all heights
    bc_epochs: int = 8
    bc_batch: int = 256
    bc_lr: float = 1e-3
    # PPO (used for base fine-tuning, self-distillation and the direct-PPO baseline)
    ppo_steps: int = 20000          # environment steps per PPO phase
    ppo_episodes: int = 256         # episodes per PPO update
    stretch: float = 0.5            # extra episodes per update on one-alteration "stretch" tasks
    ppo_epochs: int = 4
    ppo_minibatch: int = 256
    ppo_lr: float = 3e-4
    clip: float = 0.2
    ent_coef: float = 0.003
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    gamma: float = 0.9              # < 1 so V(s, g) also says how far the goal is
    gae_lambda: float = 0.95
    # sec 4.2: task expansion
    expand_episodes: int = 3000     # attempts on the previous round's tasks per round
    candidates: int = 64            # K one-alteration candidates per successful trajectory
    select: str = "ours"            # ours | end2new | init2new   (Table 3)
    restrict: bool = True           # False: candidates are unrelated random tasks (Table 3)
    # sec 4.3: self-distillation
    buffer_size: int = 60000        # demo steps, and tasks, kept (oldest dropped first): the memory bound
    # sec 5: evaluation
    eval_episodes: int = 100        # per shape and round
    baseline: str = ""              # "direct-ppo": PPO on the evaluation tasks instead (sec 5.3)
    shapes: tuple = ("I", "Y", "3T")


# --------------------------------------------------------------------------------------------
# Goals and shapes
# --------------------------------------------------------------------------------------------

def layer(y):
    """Layer index of a height y (layer 0 rests on the table)."""
    return int(round(y / BLOCK_H - 0.5))


def position(ix, k, env):
    """Centre (x, y) of x-bin ix in layer k."""
    return (float(env.x_bins[ix]), float(env.y_bins[k]))


# Held-out shapes (sec 5): (offset from the centre in block widths, layer). None of them can occur
# among the base tasks (at most 3 goals, at most one block moved), and each has >= 4 goals with
# >= 3 above the ground. Drawings are in the README.
SHAPES = {
    "I": [(0, 0), (0, 1), (0, 2), (0, 3)],                              # a tower of four
    "Y": [(-0.75, 0), (0.75, 0), (0, 1), (0, 2), (0, 3)],               # upside down: stem on two legs
    "3T": [(-1, 0), (0, 0), (1, 0), (-0.5, 1), (0.5, 1), (0, 2)],       # three tiers, 3-2-1
}


def shape_goals(name, env, rng):
    """Goals for a held-out shape at a random place, with randomly assigned blocks.

    Returns {block: (x, y)}; the shape's centre lies on the x grid so every goal is reachable.
    """
    cells = SHAPES[name]
    if len(cells) > env.n_blocks:
        raise ValueError(f"shape {name!r} needs {len(cells)} blocks, the world has {env.n_blocks}")
    reach = max(abs(dx) for dx, _ in cells) * BLOCK_W
    centres = env.x_bins[(env.x_bins - reach >= env.x_bins[0] - 1e-9) & (env.x_bins + reach <= env.x_bins[-1] + 1e-9)]
    cx = centres[rng.integers(len(centres))]
    blocks = rng.permutation(env.n_blocks)[: len(cells)]
    return {int(b): (float(cx + dx * BLOCK_W), float(env.y_bins[k])) for b, (dx, k) in zip(blocks, cells)}


def start_state(env, goals, rng):
    """A random scattered scene for these goals (the env keeps goal footprints clear)."""
    env.reset(seed=int(rng.integers(2**31)), options={"goals": goals})
    return env.get_state()


def on_table(state, env):
    """True when every block rests on the table (none fell off the edge)."""
    return bool(np.all(state[:, 1] > 0) and np.all(np.abs(state[:, 0]) < env.table_x[1]))


# --------------------------------------------------------------------------------------------
# Rollouts
# --------------------------------------------------------------------------------------------

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


def run_episodes(agent, tasks, envs, rng, deterministic=False, progress=None):
    """Run one episode per task, len(envs) at a time with one batched policy call per step.

    tasks: list of (state (n, 6), goals). Returns a list of Trajectory in the order of `tasks`.
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
            actions, logp, values = agent.act(obs, deterministic=True), np.zeros(len(active)), np.zeros(len(active))
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
                out[s["i"]] = Trajectory(tasks[s["i"]][1], np.stack(s["states"]), np.stack(s["actions"]),
                                         bool(terminated), np.array(s["logp"]), np.array(s["values"]))
                if progress:
                    progress.update(1)
                start(k)


def success_rate(trajs):
    return float(np.mean([t.success for t in trajs])) if trajs else 0.0


# --------------------------------------------------------------------------------------------
# sec 4.1: base tasks -- one block moved, plus "stay where you are" goals for up to two others
# --------------------------------------------------------------------------------------------

def random_move(env, rng):
    """A random single-block action: onto the table, or onto another block (offset by at most
    a quarter block, plus the rounding to the x grid).

    Returns (block, action), or None when the drawn target is not a layer of the grid.
    """
    state, n = env.get_state(), env.n_blocks
    b = int(rng.integers(n))
    if rng.random() < 0.5:                                   # somewhere on the table
        return b, env.encode_action(b, env.x_bins[rng.integers(len(env.x_bins))], env.y_bins[0])
    j = int(rng.choice([i for i in range(n) if i != b]))     # on top of block j
    k = layer(state[j, 1]) + 1
    if not 1 <= k < n:                                       # j is above the top layer or fell off
        return None
    return b, env.encode_action(b, state[j, 0] + rng.integers(-1, 2) * BLOCK_W / 4, env.y_bins[k])


def base_demos(cfg, env, rng, count, progress=None):
    """Single-step demonstrations (sec 4.1): one random block teleported somewhere it can rest.

    Scenes start scattered and get up to cfg.warmup random moves first, so stacks of every height
    occur and the demos place blocks on every layer. The goal is relabelled with where the block
    came to rest, so every demo is correct by construction; up to two "stay where you are" goals
    for other blocks make the goal count uniform in 1..3.
    Returns (tasks, obs (count, n, 6), actions (count, 3)).
    """
    tasks, obs, actions = [], [], []
    n = env.n_blocks
    while len(tasks) < count:
        env.reset(seed=int(rng.integers(2**31)))
        for _ in range(int(rng.integers(0, cfg.warmup + 1))):  # warm-up: build some random stacks
            move = random_move(env, rng)
            if move is not None:
                env.step(move[1])
        s0, move = env.get_state(), random_move(env, rng)
        if move is None or not on_table(s0, env):
            continue
        b, a = move
        _, _, _, _, info = env.step(a)
        s1 = env.get_state()
        if info["noop"] or not info["stable"] or not on_table(s1, env):
            continue
        if np.linalg.norm(s1[b, :2] - s0[b, :2]) < env.threshold:
            continue                                         # nothing moved: nothing to learn
        others = [int(i) for i in rng.permutation([i for i in range(n) if i != b])]
        stay = others[: int(rng.integers(0, 3))]
        goals = {i: (float(s1[i, 0]), float(s1[i, 1])) for i in [b] + stay}
        tasks.append((s0, goals))
        obs.append(observation(s0, goals))
        actions.append(a)
        if progress:
            progress.update(1)
    return tasks, np.stack(obs), np.stack(actions)


# --------------------------------------------------------------------------------------------
# PPO phase
# --------------------------------------------------------------------------------------------

def ppo_phase(agent, tasks, cfg, envs, short, rng, label, stretch=None):
    """PPO on tasks drawn uniformly from `tasks` for cfg.ppo_steps environment steps.

    Each update also runs stretch (default cfg.stretch) * ppo_episodes "stretch" tasks: a drawn
    task with one alteration (as in sec 4.2), on the short budget of `short` envs. Most of them cannot be reached
    in time, and that is their point: V(s, g) must see goals it cannot reach to rank candidates by
    equation (1); the ones the policy does reach teach it a step beyond its data.
    Returns the per-update log (agent.ppo_update's metrics plus steps and success rates).
    """
    log, steps = [], 0
    n_stretch = int((cfg.stretch if stretch is None else stretch) * cfg.ppo_episodes)
    progress = Progress(cfg.ppo_steps, label)
    while steps < cfg.ppo_steps:
        batch = [tasks[i] for i in rng.integers(len(tasks), size=cfg.ppo_episodes)]
        stretch_tasks = [(s, alter(g, envs[0], rng)) for s, g in
                         (tasks[i] for i in rng.integers(len(tasks), size=n_stretch))]
        main, extra = run_episodes(agent, batch, envs, rng), run_episodes(agent, stretch_tasks, short, rng)
        trajs = main + extra
        obs, actions, logp, adv, ret = ppo_batch(trajs, cfg)
        with phase(f"{label.strip()} update {len(log) + 1}"):
            metrics = agent.ppo_update(obs, actions, logp, adv, ret, epochs=cfg.ppo_epochs,
                                       minibatch=cfg.ppo_minibatch, clip=cfg.clip, ent_coef=cfg.ent_coef,
                                       vf_coef=cfg.vf_coef, lr=cfg.ppo_lr, max_grad_norm=cfg.max_grad_norm,
                                       rng=rng)
        steps += len(actions)
        metrics.update(steps=steps, success=success_rate(main), stretch_success=success_rate(extra))
        log.append(metrics)
        progress.update(len(actions), f"success {metrics['success']:.2f}, stretch {metrics['stretch_success']:.2f}")
    progress.close()
    return log


def ppo_batch(trajs, cfg):
    """Flatten episodes into one sequence (T_total, 1) and compute GAE advantages and returns.

    The reward is 1 on the step that succeeds and 0 otherwise. Running out of steps counts as
    failure (no bootstrap): V(s, g) then estimates the discounted chance of reaching g within the
    budget, so a goal that cannot be reached has value 0 -- what equation (1) needs to compare.
    """
    obs = np.concatenate([t.obs()[:-1] for t in trajs])
    actions = np.concatenate([t.actions for t in trajs])
    logp = np.concatenate([t.logp for t in trajs])
    column = lambda per_episode: np.concatenate(per_episode)[:, None]      # -> (T_total, 1)
    values = column([t.values for t in trajs])
    last_step = column([np.arange(len(t.actions)) == len(t.actions) - 1 for t in trajs]) * 1.0
    rewards = last_step * column([np.full(len(t.actions), t.success) for t in trajs])
    next_values = column([np.append(t.values[1:], 0.0) for t in trajs])   # V(s_{t+1}); 0 after the end
    # every episode end is terminal (success, or out of steps = failure), so nothing is truncated
    adv, ret = gae(rewards, values, last_step, np.zeros_like(last_step), next_values, cfg.gamma, cfg.gae_lambda)
    return obs, actions, logp, adv[:, 0], ret[:, 0]


# --------------------------------------------------------------------------------------------
# sec 4.2: task expansion
# --------------------------------------------------------------------------------------------

def random_position(env, rng):
    """A goal position drawn uniformly over the action grid: any x-bin, any layer."""
    return position(int(rng.integers(len(env.x_bins))), int(rng.integers(len(env.y_bins))), env)


def alter(goals, env, rng, restrict=True):
    """One candidate task: exactly one alteration of `goals` (sec 4.2).

    Add a goal for a block that has none, or modify the target of a block that has one, with the
    block and the position uniform. Without the restriction ("w/o restriction", Table 3) the
    candidate is an unrelated random task: uniform goal count, blocks and positions.
    """
    if not restrict:
        m = int(rng.integers(1, env.n_blocks + 1))
        return {int(b): random_position(env, rng) for b in rng.permutation(env.n_blocks)[:m]}
    new = dict(goals)
    free = [b for b in range(env.n_blocks) if b not in goals]
    if free and rng.random() < 0.5:
        new[int(rng.choice(free))] = random_position(env, rng)       # add one goal
    else:
        new[int(rng.choice(list(goals)))] = random_position(env, rng)  # modify one goal
    return new


def select_goal(agent, s0, sT, candidates, mode="ours"):
    """Pick g* among candidate goals by the value function (equation 1 and its ablations).

    ours:     argmax_g V(sT, g) - V(s0, g)   hard from the start, easy from where we ended
    end2new:  argmax_g V(sT, g)              easy from where we ended (Table 3)
    init2new: argmin_g V(s0, g)              hard from the start (Table 3)
    Returns (index of g*, scores (K,)).
    """
    v_T = agent.value(np.stack([observation(sT, g) for g in candidates]))
    v_0 = agent.value(np.stack([observation(s0, g) for g in candidates]))
    scores = {"ours": v_T - v_0, "end2new": v_T, "init2new": -v_0}[mode]
    return int(np.argmax(scores)), scores


def join(first, second, goals, success):
    """Concatenate two trajectories (second starts where first ended) under new goals."""
    return Trajectory(goals, np.concatenate([first.states, second.states[1:]]),
                      np.concatenate([first.actions, second.actions]), success)


def relabel(traj, env):
    """Hindsight relabelling: the goal becomes where the goal blocks came to rest.

    Returns None when that is no usable demonstration: a block fell off the table, or the
    relabelled goal already held at the start (nothing was achieved).
    """
    sT = traj.states[-1]
    if not on_table(sT, env):
        return None
    goals = {b: (float(sT[b, 0]), float(sT[b, 1])) for b in traj.goals}
    if is_success(traj.states[0], goals, env.threshold):
        return None
    # the episode would have ended the first time the relabelled goal held: cut the rest
    T = next(t for t in range(1, len(traj.states)) if is_success(traj.states[t], goals, env.threshold))
    return Trajectory(goals, traj.states[: T + 1], traj.actions[:T], True)


def task_expansion(agent, tasks, cfg, envs, short, rng):
    """One round of sec 4.2. tasks: the previous round's tasks. Returns (demos, info).

    1. run the policy on the tasks and keep the successful trajectories s0 -> sT;
    2. for each, draw K candidates with one alteration and pick g* by equation (1);
    3. run the policy from sT toward g*; on success the joined trajectory demonstrates s0 -> g*,
       on failure the joined trajectory is relabelled with the goal it did reach.
    """
    env = envs[0]
    batch = [tasks[i] for i in rng.integers(len(tasks), size=cfg.expand_episodes)]
    progress = Progress(len(batch), "  collect")
    trajs = [t for t in run_episodes(agent, batch, envs, rng, progress=progress) if t.success]
    progress.close()
    chosen = []
    for t in trajs:
        cands = [alter(t.goals, env, rng, cfg.restrict) for _ in range(cfg.candidates)]
        # a candidate that already holds at sT is no new task (equation 1 would favour it)
        cands = [g for g in cands if not is_success(t.states[-1], g, env.threshold)] or cands
        i, _ = select_goal(agent, t.states[0], t.states[-1], cands, cfg.select)
        chosen.append(cands[i])
    progress = Progress(len(trajs), "  verify")
    ext = run_episodes(agent, [(t.states[-1], g) for t, g in zip(trajs, chosen)], short, rng, progress=progress)
    progress.close()
    demos, n_joined = [], 0
    for t, g, e in zip(trajs, chosen, ext):
        joined = join(t, e, g, e.success)
        if e.success:
            demos.append(joined)
            n_joined += 1
        else:
            r = relabel(joined, env)
            if r is not None:
                demos.append(r)
    info = dict(attempts=len(batch), successful=len(trajs), joined=n_joined,
                relabelled=len(demos) - n_joined)
    return demos, info


def demo_arrays(demos):
    """All (observation, action) pairs of a list of demonstrations: (N, n, 6), (N, 3)."""
    return (np.concatenate([d.obs()[:-1] for d in demos]), np.concatenate([d.actions for d in demos]))


def task_stats(goals, lengths, n_blocks):
    """Figures 1 and 2 and Table 1 of the paper for one round's tasks.

    goals: list of goal dicts; lengths: the episode length of each task's demonstration.
    """
    counts = [len(g) for g in goals]
    heights = [max(layer(y) for _, y in g.values()) for g in goals]
    high = [sum(layer(y) >= 1 for _, y in g.values()) >= 3 for g in goals]
    return dict(tasks=len(goals),
                goal_count_hist=np.bincount(counts, minlength=n_blocks + 1)[1:].tolist(),
                max_height_hist=np.bincount(heights, minlength=n_blocks)[:n_blocks].tolist(),
                high_goal_tasks=int(np.sum(high)),
                mean_episode_length=float(np.mean(lengths)) if goals else 0.0)


# --------------------------------------------------------------------------------------------
# sec 5: evaluation
# --------------------------------------------------------------------------------------------

def eval_tasks(cfg, env, seed):
    """Fixed evaluation tasks per shape: the same scenes after every round (own seed)."""
    rng = np.random.default_rng([seed, 12345])
    out = {}
    for name in cfg.shapes:
        out[name] = []
        for _ in range(cfg.eval_episodes):
            g = shape_goals(name, env, rng)
            out[name].append((start_state(env, g, rng), g))
    return out


def evaluate(agent, tasks_by_shape, envs, rng):
    """Zero-shot success per shape with the greedy policy: {shape: rate}."""
    return {name: success_rate(run_episodes(agent, tasks, envs, rng, deterministic=True))
            for name, tasks in tasks_by_shape.items()}


# --------------------------------------------------------------------------------------------
# The whole run
# --------------------------------------------------------------------------------------------

class Progress:
    """A progress line with elapsed time and ETA on stderr: redrawn in place on a terminal,
    a new line every 10 s in a log file."""

    def __init__(self, total, label):
        self.total, self.label, self.done, self.t0, self.last = total, label, 0, time.time(), 0.0
        self.tty = sys.stderr.isatty()

    def update(self, k=1, extra=""):
        self.done += k
        now = time.time()
        if now - self.last < (0.5 if self.tty else 10) and self.done < self.total:
            return
        self.last, el = now, now - self.t0
        eta = el / max(self.done, 1) * max(self.total - self.done, 0)
        msg = (f"{self.label}: {self.done}/{self.total} ({100 * min(self.done / self.total, 1):.0f}%) "
               f"{el:.0f}s, ETA {eta:.0f}s" + ("  " + extra if extra else ""))
        print("\r" + msg if self.tty else msg, end="" if self.tty else "\n", file=sys.stderr, flush=True)

    def close(self):
        if self.tty:
            print(file=sys.stderr, flush=True)


def save_json(path, obj):
    """Write JSON atomically, like agent.save_npz: a run killed mid-write leaves the previous file intact."""
    tmp = f"{path}.tmp{os.getpid()}"
    try:
        with open(tmp, "w") as f:
            json.dump(obj, f, indent=1)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


@contextmanager
def phase(where):
    """Prefix a FloatingPointError raised by training (agent.check_finite) with where in the run."""
    try:
        yield
    except FloatingPointError as e:
        raise FloatingPointError(f"{where}: {e}") from None


def peak_memory_mb():
    """Peak resident memory of this process so far (MB), or None where `resource` is missing."""
    try:
        import resource
    except ImportError:                                      # Windows
        return None
    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / (2**20 if sys.platform == "darwin" else 2**10))


# --------------------------------------------------------------------------------------------
# Resuming: after every round, state.npz holds all a run needs to go on exactly as if never stopped
# --------------------------------------------------------------------------------------------

STATE_VERSION = 1
STATE_KEYS = ("state_version", "round", "results", "run_rng", "buffer_obs", "buffer_act", "all_tasks.states",
              "all_tasks.goals", "prev_tasks.states", "prev_tasks.goals")


def tasks_to_arrays(tasks, n_blocks):
    """[(s0 (n, 6), {block: (x, y)})] -> states (N, n, 6), goals (N, n, 3) of x, y and the goal's
    place in the dict (nan: no goal). The order matters: alter() draws from list(goals)."""
    states = np.stack([s0 for s0, _ in tasks])
    goals = np.full((len(tasks), n_blocks, 3), np.nan)
    for i, (_, g) in enumerate(tasks):
        for order, (b, (x, y)) in enumerate(g.items()):
            goals[i, b] = (x, y, order)
    return states, goals


def arrays_to_tasks(states, goals):
    """Inverse of tasks_to_arrays."""
    out = []
    for s0, g in zip(states, goals):
        blocks = sorted(np.flatnonzero(~np.isnan(g[:, 2])), key=lambda b: g[b, 2])
        out.append((s0, {int(b): (float(g[b, 0]), float(g[b, 1])) for b in blocks}))
    return out


def save_state(path, k, agent, rng, kept, results):
    """After round k: the agent with its optimiser, the run's Generator, the kept data, the results."""
    arrays = {"state_version": np.array(STATE_VERSION), "round": np.array(k),
              "results": np.array(json.dumps(results)), "run_rng": np.array(json.dumps(rng.bit_generator.state)),
              "buffer_obs": kept["buffer_obs"], "buffer_act": kept["buffer_act"], **agent.training_state()}
    for name in ("all_tasks", "prev_tasks"):
        arrays[f"{name}.states"], arrays[f"{name}.goals"] = tasks_to_arrays(kept[name], agent.n_blocks)
    agent.save(path, extra=arrays)


class ResumeError(ValueError):
    """state.npz is missing, unreadable, or from a run with other settings."""


def load_state(path, cfg, agent, rng):
    """Read what save_state wrote, for an agent like `agent`; restore rng -> (agent, round,
    results, kept). ValueError naming the file when it is unreadable or from other settings."""
    saved, data = Agent.load(path, extra=STATE_KEYS + tuple(agent.training_state()), **agent.geometry)
    if int(data["state_version"]) != STATE_VERSION:
        raise ValueError(f"{path}: state_version {data['state_version']}, expected {STATE_VERSION}")
    results = json.loads(str(data["results"]))
    ours, theirs = asdict(cfg), dict(results["config"])
    ours["shapes"], theirs["rounds"] = list(ours["shapes"]), ours["rounds"]    # rounds may be extended
    if ours != theirs:
        diff = {k: (theirs.get(k), v) for k, v in ours.items() if theirs.get(k) != v}
        raise ValueError(f"{path}: saved by a run with other settings (saved, now): {diff}")
    results["config"] = asdict(cfg)
    saved.load_training_state(data, path)
    rng.bit_generator.state = json.loads(str(data["run_rng"]))
    kept = {"buffer_obs": data["buffer_obs"], "buffer_act": data["buffer_act"]}
    for name in ("all_tasks", "prev_tasks"):
        kept[name] = arrays_to_tasks(data[f"{name}.states"], data[f"{name}.goals"])
    return saved, int(data["round"]), results, kept


def run(cfg, out_dir, log=print, resume=False):
    """Train the base policy, run cfg.rounds rounds, evaluate after each. Returns results dict.

    After round k: round{k}.npz (the agent), state.npz (for resume=True, which goes on from the
    last complete round and gives the same results as a run never stopped), results.json.
    """
    os.makedirs(out_dir, exist_ok=True)
    rng = np.random.default_rng(cfg.seed)
    envs = [BlockWorld(cfg.n_blocks, max_steps=cfg.max_steps) for _ in range(cfg.n_envs)]
    short = [BlockWorld(cfg.n_blocks, max_steps=cfg.short_steps) for _ in range(cfg.n_envs)]
    agent = Agent(cfg.n_blocks, n_x=len(envs[0].x_bins), hidden=cfg.hidden, seed=cfg.seed,
                  block_size=envs[0].block_size, table_x=envs[0].table_x, threshold=envs[0].threshold)
    evals = eval_tasks(cfg, envs[0], cfg.seed)
    state_path = os.path.join(out_dir, "state.npz")
    if resume:
        try:
            agent, done, results, kept = load_state(state_path, cfg, agent, rng)
        except (OSError, ValueError) as e:
            raise ResumeError(f"cannot resume: {e}") from None
        # state.npz is written before results.json, so a kill between the two leaves results.json a round behind
        save_json(os.path.join(out_dir, "results.json"), results)
        log(f"resuming {out_dir} after round {done}")
    else:
        done, results, kept = -1, dict(config=asdict(cfg), rounds=[], wallclock={}), {}
    clock = results["wallclock"]
    t_start = time.time() - clock.get("total_s", 0.0)

    def finish_round(k, stats, t0):
        ev = evaluate(agent, evals, envs, rng)
        results["rounds"].append(dict(round=k, eval=ev, **stats))
        clock[f"round{k}_s"] = round(time.time() - t0, 1)
        clock["total_s"] = round(time.time() - t_start, 1)
        clock["peak_memory_mb"] = peak_memory_mb()
        agent.save(os.path.join(out_dir, f"round{k}.npz"))
        save_state(state_path, k, agent, rng, kept, results)          # the commit point of round k
        save_json(os.path.join(out_dir, "results.json"), results)
        log(f"round {k}: zero-shot " + ", ".join(f"{s} {v:.0%}" for s, v in ev.items())
            + f"  ({clock['total_s']:.0f}s so far, peak memory {clock['peak_memory_mb']} MB)")

    if done < 0:                                     # sec 4.1 -- base skills
        t0 = time.time()
        log(f"[round 0] base skills: {cfg.base_demos} single-block demos, BC, PPO")
        p = Progress(cfg.base_demos, "  demos")
        base_tasks, obs, actions = base_demos(cfg, envs[0], rng, cfg.base_demos, p)
        p.close()
        with phase("round 0, BC"):
            bc_loss = agent.bc(obs, actions, cfg.bc_epochs, cfg.bc_batch, cfg.bc_lr, rng)
        log(f"  BC loss {bc_loss[0]:.3f} -> {bc_loss[-1]:.3f}")
        with phase("round 0"):
            ppo_log = ppo_phase(agent, base_tasks, cfg, envs, short, rng, "  PPO base")
        # demos kept for self-distillation; tasks kept to mix into later PPO phases
        kept = dict(buffer_obs=obs, buffer_act=actions, all_tasks=list(base_tasks), prev_tasks=base_tasks)
        finish_round(0, dict(bc_loss=bc_loss, ppo_success=[m["success"] for m in ppo_log],
                             **task_stats([g for _, g in base_tasks], [1] * len(base_tasks), cfg.n_blocks)), t0)

    eval_list = [t for ts in evals.values() for t in ts]
    for k in range(max(done, 0) + 1, cfg.rounds + 1):
        t0 = time.time()
        if cfg.baseline == "direct-ppo":             # sec 5.3: no expansion, PPO on the test tasks
            # plain PPO: no stretch tasks, which would be a curriculum of altered test tasks
            log(f"[round {k}] direct PPO on the evaluation tasks")
            with phase(f"round {k}"):
                ppo_log = ppo_phase(agent, eval_list, cfg, envs, short, rng, "  PPO direct", stretch=0.0)
            finish_round(k, dict(ppo_success=[m["success"] for m in ppo_log]), t0)
            continue
        log(f"[round {k}] task expansion from {len(kept['prev_tasks'])} tasks")
        demos, info = task_expansion(agent, kept["prev_tasks"], cfg, envs, short, rng)
        stats = task_stats([d.goals for d in demos], [len(d.actions) for d in demos], cfg.n_blocks)
        log(f"  {info['successful']}/{info['attempts']} successful, {info['joined']} joined, "
            f"{info['relabelled']} relabelled; {stats['high_goal_tasks']} tasks with >= 3 high goals")
        if not demos:
            log("  no demonstrations generated; keeping the current policy")
            finish_round(k, dict(expansion=info, **stats), t0)
            continue
        # sec 4.3 -- self-distillation on the new demos mixed with the old. The buffer and the task
        # list keep the newest cfg.buffer_size entries: the memory bound of a long run.
        new_obs, new_act = demo_arrays(demos)
        kept["buffer_obs"] = np.concatenate([kept["buffer_obs"], new_obs])[-cfg.buffer_size:]
        kept["buffer_act"] = np.concatenate([kept["buffer_act"], new_act])[-cfg.buffer_size:]
        with phase(f"round {k}, BC"):
            bc_loss = agent.bc(kept["buffer_obs"], kept["buffer_act"], cfg.bc_epochs, cfg.bc_batch, cfg.bc_lr, rng)
        log(f"  BC on {len(kept['buffer_act'])} steps: loss {bc_loss[0]:.3f} -> {bc_loss[-1]:.3f}")
        new_tasks = [(d.states[0].copy(), d.goals) for d in demos]     # a copy: not the whole episode
        all_tasks = kept["all_tasks"]
        old = [all_tasks[i] for i in rng.integers(len(all_tasks), size=len(new_tasks))]
        with phase(f"round {k}"):
            ppo_log = ppo_phase(agent, new_tasks + old, cfg, envs, short, rng, "  PPO distil")
        kept["all_tasks"], kept["prev_tasks"] = (all_tasks + new_tasks)[-cfg.buffer_size:], new_tasks
        finish_round(k, dict(expansion=info, bc_loss=bc_loss,
                             ppo_success=[m["success"] for m in ppo_log], **stats), t0)
    return results


# --------------------------------------------------------------------------------------------
# Reports: Tables 1 and 2 as markdown, Figures 1 and 2 as PNG
# --------------------------------------------------------------------------------------------

def tables(results):
    """Table 1 (generated tasks per round) and Table 2 (zero-shot success) as markdown."""
    rounds = results["rounds"]
    shapes = list(rounds[0]["eval"])
    t1 = ["| round | generated tasks | # high goals (>= 3 above ground) | mean episode length |",
          "|---|---|---|---|"]
    t1 += [f"| {r['round']} | {r['tasks']} | {r['high_goal_tasks']} | {r['mean_episode_length']:.2f} |"
           for r in rounds if "tasks" in r]
    t2 = ["| round | " + " | ".join(shapes) + " |", "|---" * (len(shapes) + 1) + "|"]
    t2 += [f"| {r['round']} | " + " | ".join(f"{100 * r['eval'][s]:.0f}%" for s in shapes) + " |"
           for r in rounds]
    return "\n".join(["Table 1: generated tasks", *t1, "", "Table 2: zero-shot success", *t2])


def figures(results, out_dir):
    """Figure 1 (maximum goal height) and Figure 2 (number of goals) per round, as PNG files."""
    from matplotlib.figure import Figure
    rounds = [r for r in results["rounds"] if "tasks" in r]
    paths = []
    for key, fname, xlabel in (("max_height_hist", "fig1_max_goal_height.png", "highest goal (layer, 0 = table)"),
                               ("goal_count_hist", "fig2_goal_count.png", "number of goals")):
        fig = Figure(figsize=(5, 3.2))
        ax = fig.add_subplot()
        width = 0.8 / max(len(rounds), 1)
        for i, r in enumerate(rounds):
            h = np.array(r[key], float)
            x = np.arange(len(h)) + (1 if key == "goal_count_hist" else 0) + (i - (len(rounds) - 1) / 2) * width
            ax.bar(x, h / max(h.sum(), 1), width, label=f"round {r['round']}" + (" (base)" if r["round"] == 0 else ""))
        ax.set_xlabel(xlabel)
        ax.set_ylabel("fraction of generated tasks")
        ax.legend()
        fig.tight_layout()
        paths.append(os.path.join(out_dir, fname))
        fig.savefig(paths[-1], dpi=100)
    return paths


RUN_FILES = ("results.json", "state.npz", "round*.npz")      # what a run leaves in its directory


def parse_args(argv=None):
    """-> (Config, output directory, resume?). Refuses bad settings with a one-line reason."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    d = Config()
    p.add_argument("--rounds", type=int, default=None, help=f"rounds of task expansion, >= 1 (default {d.rounds})")
    p.add_argument("--seed", type=int, default=None, help=f"a non-negative int (default {d.seed})")
    p.add_argument("--blocks", type=int, default=None,
                   help=f"blocks in the world (default {d.n_blocks}; the held-out shapes need 6, the table holds 8)")
    p.add_argument("--out", default=None, help="output directory (default runs/<settings>-seed<seed>)")
    p.add_argument("--select", choices=["ours", "end2new", "init2new"], default=None,
                   help="goal selection rule (equation 1 and the Table 3 ablations; default ours)")
    p.add_argument("--no-restrict", action="store_true", default=None,
                   help="candidates are unrelated random tasks instead of one alteration (Table 3)")
    p.add_argument("--baseline", choices=["direct-ppo"], default=None,
                   help="skip task expansion; PPO directly on the evaluation tasks (sec 5.3)")
    p.add_argument("--scale", type=float, default=None,
                   help="multiply every data and step budget (e.g. 0.05 for a smoke test; default 1)")
    p.add_argument("--resume", action="store_true",
                   help="go on from the last complete round of the run in --out, with its settings "
                        "(--rounds may raise the number of rounds)")
    a = p.parse_args(argv)
    if a.rounds is not None and a.rounds < 1:
        p.error(f"--rounds must be >= 1, got {a.rounds}")
    if a.resume:
        given = [f for f in ("seed", "blocks", "select", "no_restrict", "baseline", "scale") if getattr(a, f) is not None]
        if given:
            p.error(f"--resume uses the settings saved in --out; drop --{given[0].replace('_', '-')}")
        if a.out is None:
            p.error("--resume needs --out, the directory of the run to go on with")
        try:
            with open(os.path.join(a.out, "results.json")) as f:
                saved = json.load(f)
            cfg = Config(**{**saved["config"], "shapes": tuple(saved["config"]["shapes"])})
            done = saved["rounds"][-1]["round"]
        except (OSError, ValueError, KeyError, TypeError, IndexError) as e:
            p.error(f"--resume: {a.out} holds no readable run ({type(e).__name__}: {e})")
        cfg.rounds = cfg.rounds if a.rounds is None else a.rounds
        if done >= cfg.rounds:
            p.error(f"--resume: {a.out} has finished all {cfg.rounds} rounds; pass a larger --rounds to extend it")
        return cfg, a.out, True
    given = {k: v for k, v in dict(seed=a.seed, rounds=a.rounds, n_blocks=a.blocks, select=a.select,
                                   baseline=a.baseline, restrict=False if a.no_restrict else None).items()
             if v is not None}
    cfg = Config(**given)
    if cfg.seed < 0:
        p.error(f"--seed must be >= 0, got {cfg.seed}")
    need = max(len(SHAPES[s]) for s in cfg.shapes)
    if not need <= cfg.n_blocks <= 8:
        p.error(f"--blocks must be in {need}..8 (the held-out shapes need {need} blocks, the table holds 8), "
                f"got {cfg.n_blocks}")
    scale = 1.0 if a.scale is None else a.scale
    if not 0 < scale <= 100:
        p.error(f"--scale must be in (0, 100], got {scale}")
    if scale != 1.0:
        for name in ("base_demos", "ppo_steps", "expand_episodes", "eval_episodes", "ppo_episodes"):
            setattr(cfg, name, max(4, int(round(getattr(cfg, name) * scale))))
    tag = cfg.baseline or f"{cfg.select}{'' if cfg.restrict else '-norestrict'}"
    tag += "" if cfg.n_blocks == d.n_blocks else f"-{cfg.n_blocks}blocks"
    out = a.out or os.path.join("runs", f"{tag}-seed{cfg.seed}")
    found = [f for pattern in RUN_FILES for f in glob.glob(os.path.join(glob.escape(out), pattern))]
    if found:
        p.error(f"{out} already holds a run ({os.path.basename(sorted(found)[0])}); "
                f"continue it with --resume --out {out}, or choose another --out")
    return cfg, out, False


def saved_round(out):
    """The last complete round of the run in `out` (from its results.json), or -1 if there is none."""
    try:
        with open(os.path.join(out, "results.json")) as f:
            return json.load(f)["rounds"][-1]["round"]
    except (OSError, ValueError, KeyError, IndexError):
        return -1


def last_round(out):
    """What a stopped run left in `out`, and how to go on from it."""
    k = saved_round(out)
    if k < 0:
        return f"no round was complete, so there is nothing to resume in {out}."
    return f"rounds 0..{k} are saved in {out}; go on with:\n    python taskexp.py --resume --out {out}"


def main(argv=None):
    cfg, out, resume = parse_args(argv)
    try:
        with threadpool_limits(limits=1):
            results = run(cfg, out, resume=resume)
        print()
        print(tables(results))
        for path in figures(results, out):
            print("wrote", path)
    except KeyboardInterrupt:
        print(f"\ninterrupted; {last_round(out)}", file=sys.stderr)
        sys.exit(130)
    except ResumeError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    except FloatingPointError as e:
        print(f"\nerror: training diverged: {e}\n{last_round(out)}", file=sys.stderr)
        sys.exit(1)
    print(f"wrote {out}/results.json and round0..{cfg.rounds}.npz in {results['wallclock']['total_s']:.0f}s")


if __name__ == "__main__":
    main()
