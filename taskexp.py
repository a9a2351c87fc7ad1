"""taskexp.py -- task expansion, the method, in the order of the paper.

"Self-Generating Data for Goal-Conditioned Compositional Problems" (Yuan, Li, Wu), sections 4 and
5, on the 2D block world of env2d.py with the numpy agent of agent.py:

  sec 4.1  base_skills     single-block demos -> behaviour cloning -> PPO fine-tuning
  sec 4.2  task_expansion  successful trajectory s0 -> sT, K one-alteration candidates g,
                           g* = argmax_g V(sT, g) - V(s0, g)   (equation 1),
                           run the policy from sT toward g*: join on success, relabel on failure
  sec 4.3  self_distill    BC on the generated demos, then PPO on the generated tasks
  sec 5    evaluate        zero-shot success on held-out shapes ("I", "Y", "3T") after every round;
                           zero_shot_tests names every test a round makes: the paper's, and
                           beyond it the families of blocks no goal names and other block counts
           train           the loop that calls them in order: read it last

Round 0 is base_skills; each round k >= 1 is task_expansion from the last round's tasks, then
self_distill on what it generated; every round ends with the tests of zero_shot_tests.

A task is a pair (s0, goals): a state array (n_blocks, 6) and a dict {block: (x, y)}.
The hyperparameters are in taskexp_lib/config.py, the batched episodes in taskexp_lib/rollout.py;
the plumbing above the method (arguments, run directory, resume, progress, tables and figures)
in the package taskexp_cli. `python taskexp.py --rounds 3` runs taskexp_cli.main().
"""
# `python taskexp.py` hands over to the CLI, which imports this file as taskexp: so the method is
# defined once, rather than once more as __main__.
if __name__ == "__main__":
    from taskexp_cli import main
    raise SystemExit(main())
import warnings
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from typing import Callable, NamedTuple

import numpy as np
from tqdm import tqdm

import agent as agent_lib
from agent import Agent, OtherWorldWarning
from env2d import drop_height, physics_pool, run_worlds
from taskexp_lib import one_blas_thread, rollout
from taskexp_lib.config import Config  # noqa: F401  (re-exported: taskexp.Config, a run's settings)
from taskexp_lib.geometry import BLOCK_H, BLOCK_W, N_X, is_success, layer, observation, on_same_spot
from taskexp_lib.hindsight import add_parts, learnt_from
from taskexp_lib.labels import labelled
from taskexp_lib.nn import mlp_backward
from taskexp_lib.orders import other_orders, with_other_orders
from taskexp_lib.rollout import Trajectory, cut, run_episodes, success_rate
from taskexp_lib.shapes import eval_tasks, family_tasks
from taskexp_lib.shards import SHARDS, read_only_map
from taskexp_lib.stats import order_stats, task_stats, unnamed_moves

silent = partial(tqdm, disable=True)     # the default progress bar: none (the CLI draws one)


def on_table(state, env):
    """True when every block rests on the table (none fell off the edge)."""
    return bool(np.all(state[:, 1] > 0) and np.all(np.abs(state[:, 0]) < env.table_x[1]))


@dataclass
class RunState:
    """What a run carries from one round to the next (checkpoint.py saves it as state.npz): the
    base skills start it, each self-distillation adds to it."""
    last_round: int = -1                # the last complete round; -1 before the base skills
    buffer_obs: np.ndarray = None       # demo steps (N, n, 6) for BC, the newest buffer_size
    buffer_act: np.ndarray = None       # their actions (N, 3)
    all_tasks: list = None              # every task so far, newest buffer_size: PPO replays some
    prev_tasks: list = None             # the tasks that the next task expansion starts from
    results: dict = field(default_factory=dict)    # config, one record per round, wall-clock


# --------------------------------------------------------------------------------------------
# sec 4.1: base skills -- one block moved, plus "stay where you are" goals for others
# --------------------------------------------------------------------------------------------

def random_move(env, rng, free_table=False):
    """A random single-block action: onto the table, or onto another block (offset by at most
    a quarter block, plus the rounding to the x grid). free_table: the table moves land on free
    table spots only (a block dropped at any x mostly lands on another block).

    Returns (block, action), or None when the drawn target is not a layer of the grid.
    """
    state, n = env.get_state(), env.n_blocks
    b = int(rng.integers(n))
    if rng.random() < 0.5:                                   # somewhere on the table
        xs = env.x_bins
        if free_table:                                       # where a drop lands on the table
            others = np.delete(state, b, axis=0)
            xs = [x for x in xs if drop_height(x, others) < BLOCK_H]
        if not len(xs):                                      # the table is full
            return None
        return b, env.encode_action(b, xs[rng.integers(len(xs))], env.y_bins[0])
    j = int(rng.choice([i for i in range(n) if i != b]))     # on top of block j
    k = layer(state[j, 1]) + 1
    if not 1 <= k < n:                                       # j is above the top layer or fell off
        return None
    x = state[j, 0] + rng.integers(-1, 2) * BLOCK_W / 4
    return b, env.encode_action(b, x, env.y_bins[k])


def usable_moves(worlds, moves):
    """The random moves [(k, (block, action) or None)] of worlds[k], at most one per world,
    simulated side by side (in the physics workers, if the worlds have them) -> [(k, block,
    action, s0, s1)] of those a demonstration can show: the block moved (else there is nothing
    to learn), the scene came to rest, and no block fell off the table."""
    moves = [(k, *move, worlds[k].get_state()) for k, move in moves if move is not None]
    outcomes = rollout.simulate(worlds, [k for k, *_ in moves], [a for _, _, a, _ in moves])
    usable = []
    for (k, b, a, s0), outcome in zip(moves, outcomes):
        env = worlds[k]
        stable = env.finish_step(outcome)[-1]["stable"]
        s1 = env.get_state()
        if np.linalg.norm(s1[b, :2] - s0[b, :2]) >= env.threshold and stable and on_table(s1, env):
            usable.append((k, b, a, s0, s1))
    return usable


def base_demos(cfg, envs, rng, count, bar=silent):
    """Single-step demonstrations (sec 4.1): one random block teleported somewhere it can rest.

    A scene starts scattered and takes cfg.warmup + 1 random moves, each a demo if usable: so the
    k-th move comes after k - 1 random moves, as if warmed up by them, and stacks of every height
    occur (warmup = 0 is the paper's: scattered scenes only). Every move serves as a warm-up move
    and as a demo at once, which saves the physics of separate warm-up moves. The goal is where
    the block came to rest, so every demo is correct by construction; up to cfg.max_stay "stay
    where you are" goals for other blocks make the goal count uniform in 1..max_stay + 1.
    envs: the worlds (rollout.Worlds, or one BlockWorld), each with a scene of its own; their
    moves are simulated side by side (usable_moves).
    Returns (tasks, obs (count, n, 6), actions (count, 3)).
    """
    worlds = envs if isinstance(envs, list) else [envs]
    tasks, obs, actions = [], [], []
    n = worlds[0].n_blocks
    moves_left = [0] * len(worlds)                   # of each world's scene; 0: a new scene
    with bar(total=count, desc="demos") as progress:
        while len(tasks) < count:
            moves = []                               # (world, its move)
            for k, env in enumerate(worlds):
                if moves_left[k] == 0 or not on_table(env.get_state(), env):   # or one fell off
                    env.reset(seed=int(rng.integers(2**31)))
                    moves_left[k] = cfg.warmup + 1
                moves_left[k] -= 1
                moves.append((k, random_move(env, rng, cfg.free_table)))
            for _, b, a, s0, s1 in usable_moves(worlds, moves)[: count - len(tasks)]:
                others = [int(i) for i in rng.permutation([i for i in range(n) if i != b])]
                stay = others[: int(rng.integers(0, cfg.max_stay + 1))]
                goals = {i: (float(s1[i, 0]), float(s1[i, 1])) for i in [b] + stay}
                tasks.append((s0, goals))
                obs.append(observation(s0, goals))
                actions.append(a)
                progress.update(1)
    return tasks, np.stack(obs), np.stack(actions)


def onto_cleared_spot(env, rng, first):
    """The second move of a clearing pair: a block other than `first` (the (block, action, s0,
    s1) of the move before) dropped where `first`'s block stood, on the table now that it is
    gone."""
    b, _, s0, _ = first
    other = int(rng.choice([i for i in range(env.n_blocks) if i != b]))
    return other, env.encode_action(other, s0[b, 0], env.y_bins[0])


def base_pairs(cfg, envs, rng, count, bar=silent):
    """Not in the paper: `count` two-move demonstrations, whose parts (hindsight.add_parts) show a
    block that no goal names move: in a scattered scene two different random blocks move one
    after the other (random_move, usable_moves), and the goals are where both came to rest. A
    part that names the second block alone needs the first move where it cleared or built the
    second one's spot. In a share cfg.clear_pairs of the scenes the second block goes where the
    first one stood (onto_cleared_spot): random second moves rarely land on a spot just cleared,
    so without them the parts show a support built far more often than a site cleared.
    Returns Trajectories."""
    pairs = []
    with bar(total=count, desc="pairs") as progress:
        while len(pairs) < count:
            for env in envs:
                env.reset(seed=int(rng.integers(2**31)))
            runs = {k: [] for k in range(len(envs))}           # each world's usable moves
            # drawn only when asked for, so that the pairs of clear_pairs = 0 stay as they were
            clearing = [bool(cfg.clear_pairs) and rng.random() < cfg.clear_pairs for _ in envs]
            for step in (1, 2):
                clears = lambda k: step == 2 and clearing[k]     # a clearing pair's second move
                moves = [(k, onto_cleared_spot(envs[k], rng, runs[k][0]) if clears(k)
                          else random_move(envs[k], rng, cfg.free_table)) for k in runs]
                for k, b, a, s0, s1 in usable_moves(envs, moves):
                    if b not in [m[0] for m in runs[k]]:        # not the block moved before
                        runs[k].append((b, a, s0, s1))
                runs = {k: r for k, r in runs.items() if len(r) == step}
            for (b1, a1, s0, s1), (b2, a2, _, s2) in list(runs.values())[: count - len(pairs)]:
                goals = {b: (float(s2[b, 0]), float(s2[b, 1])) for b in (b1, b2)}
                pairs.append(Trajectory(goals, np.stack([s0, s1, s2]), np.stack([a1, a2]), True))
                progress.update(1)
    return pairs


def demo_arrays(demos):
    """All (observation, action) pairs of a list of demonstrations: (N, n, 6), (N, 3)."""
    return (np.concatenate([d.obs()[:-1] for d in demos]),
            np.concatenate([d.actions for d in demos]))


def ppo_batch(trajs, cfg, gae=agent_lib.gae):
    """Flatten episodes into one sequence (T_total, 1) and compute GAE advantages and returns.

    The reward is 1 on the step that succeeds and 0 otherwise. Running out of steps counts as
    failure (no bootstrap): V(s, g) then estimates the discounted chance of reaching g within the
    budget, so a goal that cannot be reached has value 0 -- what equation (1) needs to compare.
    """
    obs, actions = demo_arrays(trajs)
    logp = np.concatenate([t.logp for t in trajs])
    column = lambda per_episode: np.concatenate(per_episode)[:, None]      # -> (T_total, 1)
    values = column([t.values for t in trajs])
    last_step = column([np.arange(len(t.actions)) == len(t.actions) - 1 for t in trajs]) * 1.0
    rewards = last_step * column([np.full(len(t.actions), t.success) for t in trajs])
    next_values = column([np.append(t.values[1:], 0.0) for t in trajs])   # V(s_{t+1}); 0 at the end
    # every episode end is terminal (success, or out of steps = failure), so nothing is truncated
    terminated, truncated = last_step, np.zeros_like(last_step)
    adv, ret = gae(rewards, values, terminated, truncated, next_values, cfg.gamma, cfg.gae_lambda)
    return obs, actions, logp, adv[:, 0], ret[:, 0]


def stretch_tasks(tasks, count, env, rng, p_add, alter):
    """Not in the paper: `count` tasks drawn from `tasks`, each with one alteration (as in sec 4.2).

    Base tasks take one step and PPO solves them all, so V(s, g) would learn "always 1" and
    equation (1) could not rank candidates. Run on the short budget, most stretch tasks fail, and
    that is their point; the ones the policy does reach teach it a step beyond its data.
    """
    drawn = (tasks[i] for i in rng.integers(len(tasks), size=count))
    return [(s0, alter(goals, env, rng, True, p_add)) for s0, goals in drawn]


@contextmanager
def phase(where):
    """Prefix a FloatingPointError raised by training (nn.check_finite) with where in the run."""
    try:
        yield
    except FloatingPointError as e:
        raise FloatingPointError(f"{where}: {e}") from None


def ppo_phase(agent, tasks, cfg, envs, short_envs, rng, name, stretch=None, pieces=None,
              bar=silent):
    """PPO on tasks drawn uniformly from `tasks` for cfg.ppo_steps environment steps.

    Each update also runs stretch (default cfg.stretch) * ppo_episodes stretch tasks on the
    short budget of `short_envs`. Returns the per-update log (agent.ppo_update's metrics plus
    steps and success rates).
    """
    pieces = pieces or Pieces()
    log, steps = [], 0
    n_stretch = int((cfg.stretch if stretch is None else stretch) * cfg.ppo_episodes)
    with bar(total=cfg.ppo_steps, desc=name) as progress:
        while steps < cfg.ppo_steps:
            batch = [tasks[i] for i in rng.integers(len(tasks), size=cfg.ppo_episodes)]
            extra = stretch_tasks(tasks, n_stretch, envs[0], rng, cfg.p_add, pieces.alter)
            main = run_episodes(agent, batch, envs, rng)
            extra = run_episodes(agent, extra, short_envs, rng)
            obs, actions, logp, adv, ret = ppo_batch(main + extra, cfg, pieces.gae)
            with phase(f"{name} update {len(log) + 1}"):
                metrics = agent.ppo_update(
                    obs, actions, logp, adv, ret, epochs=cfg.ppo_epochs,
                    minibatch=cfg.ppo_minibatch, clip=cfg.clip, ent_coef=cfg.ent_coef,
                    vf_coef=cfg.vf_coef, lr=cfg.ppo_lr, max_grad_norm=cfg.max_grad_norm, rng=rng,
                    ppo_loss=pieces.ppo_loss)
            progress.update(min(len(actions), cfg.ppo_steps - steps))
            steps += len(actions)
            metrics.update(steps=steps, success=success_rate(main),
                           stretch_success=success_rate(extra))
            log.append(metrics)
            progress.set_postfix_str(f"success {metrics['success']:.2f}, "
                                     f"stretch {metrics['stretch_success']:.2f}")
    return log


def base_skills(agent, run, cfg, envs, short_envs, rng, pieces, bar=silent, log=print):
    """Sec 4.1: the base policy. Demos that move one block, behaviour cloning, then PPO on the
    demos' tasks. Starts `run` (its BC buffer and tasks); returns the round's record."""
    log(f"[round 0] base skills: {cfg.base_demos} single-block demos, BC, PPO")
    tasks, obs, actions = base_demos(cfg, envs, rng, cfg.base_demos, bar)
    if cfg.base_pairs:                  # not in the paper: parts of two-move demos (hindsight.py)
        pairs = base_pairs(cfg, envs, rng, cfg.base_pairs, bar)
        add_parts(pairs, envs, rng, draws=4)        # 4 draws find both parts of a pair 7 times in 8
        parts = [p for d in pairs for p in d.parts]
        log(f"  {len(parts)} parts of {cfg.base_pairs} two-move demos move a block no goal names")
        tasks = tasks + [(p.states[0], p.goals) for p in parts]
        obs, actions = (np.concatenate(a) for a in zip((obs, actions), demo_arrays(parts)))
    bc_loss = agent.bc(obs, actions, cfg.bc_epochs, cfg.bc_batch, cfg.bc_lr, rng, bar=bar)
    log(f"  BC loss {bc_loss[0]:.3f} -> {bc_loss[-1]:.3f}")
    ppo_log = ppo_phase(agent, tasks, cfg, envs, short_envs, rng, "PPO base", pieces=pieces,
                        bar=bar)
    stats = task_stats([g for _, g in tasks], [1] * len(tasks), cfg.n_blocks)
    record = dict(bc_loss=bc_loss, ppo_success=[m["success"] for m in ppo_log], **stats)
    if cfg.label_tasks:           # not in the paper: V(s, g) learns from labelled outcomes too
        record.update(labelled(agent, tasks, cfg, envs, short_envs, rng, pieces, candidates, bar,
                               log))
    run.buffer_obs, run.buffer_act = obs, actions
    run.all_tasks, run.prev_tasks = list(tasks), tasks
    return record


# --------------------------------------------------------------------------------------------
# sec 4.2: task expansion
# --------------------------------------------------------------------------------------------

def random_position(env, rng, others=()):
    """A goal position drawn uniformly over the action grid (any x-bin, any layer) among those
    that are not the same spot as one of the positions `others` (geometry.same_spot: no two blocks
    can meet both)."""
    while True:
        ix, k = int(rng.integers(len(env.x_bins))), int(rng.integers(len(env.y_bins)))
        x, y = float(env.x_bins[ix]), float(env.y_bins[k])
        if not any(on_same_spot((x, y), other) for other in others):
            return x, y


def alter(goals, env, rng, restrict=True, p_add=0.5):
    """One candidate task: exactly one alteration of `goals` (sec 4.2).

    With probability p_add add a goal for a block that has none, else modify the target of a
    block that has one; block uniform, position uniform over the spots no other goal names.
    Without the restriction ("w/o restriction", Table 3) the candidate is an unrelated random
    task: uniform goal count, blocks and positions.
    """
    if not restrict:
        new = {}
        for b in rng.permutation(env.n_blocks)[: int(rng.integers(1, env.n_blocks + 1))]:
            new[int(b)] = random_position(env, rng, new.values())
        return new
    new = dict(goals)
    free = [b for b in range(env.n_blocks) if b not in goals]
    b = int(rng.choice(free)) if free and rng.random() < p_add else int(rng.choice(list(goals)))
    new[b] = random_position(env, rng, [xy for other, xy in goals.items() if other != b])
    return new


def candidates(traj, env, rng, cfg, alter=alter):
    """K = cfg.candidates one-alteration candidates for a successful trajectory s0 -> sT, less any
    that already holds at sT: no new task, and equation (1) would favour it."""
    cands = [alter(traj.goals, env, rng, cfg.restrict, cfg.p_add) for _ in range(cfg.candidates)]
    return [g for g in cands if not is_success(traj.states[-1], g, env.threshold)] or cands


def select_goal(agent, s0, sT, candidates, mode="ours"):
    """Pick g* among candidate goals by the value function (equation 1 and its ablations).

    ours:     argmax_g V(sT, g) - V(s0, g)   hard from the start, easy from where we ended
    end2new:  argmax_g V(sT, g)              easy from where we ended (Table 3)
    init2new: argmin_g V(s0, g)              hard from the start (Table 3)
    Returns the index of g* in candidates.
    """
    v_T = agent.value(np.stack([observation(sT, g) for g in candidates]))
    v_0 = agent.value(np.stack([observation(s0, g) for g in candidates]))
    scores = {"ours": v_T - v_0, "end2new": v_T, "init2new": -v_0}[mode]
    return int(np.argmax(scores))


def join(first, second, goals, success):
    """Concatenate two trajectories (second starts where first ended) under new goals."""
    return Trajectory(goals, np.concatenate([first.states, second.states[1:]]),
                      np.concatenate([first.actions, second.actions]), success)


def relabel(traj, env):
    """Hindsight relabelling: the goal becomes where the goal blocks came to rest, and the
    trajectory ends where it first holds, as its episode would have (rollout.cut).

    Returns None when that is no usable demonstration: a block fell off the table, or the
    relabelled goal already held at the start (nothing was achieved).
    """
    sT = traj.states[-1]
    if not on_table(sT, env):
        return None
    goals = {b: (float(sT[b, 0]), float(sT[b, 1])) for b in traj.goals}
    return cut(traj, goals, env.threshold)


def expansion_step(agent, found, cfg, env, short_envs, rng, pieces, bar=silent):
    """Steps 2 and 3 of sec 4.2 for the successful trajectories `found` (s0 -> sT, in order).

    For each: K = cfg.candidates one-alteration candidates (`candidates`, with pieces.alter), g*
    among them by pieces.select_goal (equation 1, or the ablation cfg.select), and one episode
    from its sT toward g* in the short worlds `short_envs`. On success the joined trajectory
    demonstrates s0 -> g*; on failure pieces.relabel makes it a demonstration of what it did
    reach, or None, which is dropped. The random draws come in this order: every candidate, then
    the episodes, all in one run_episodes call (the order a run's bytes depend on).
    Returns (demos, reached): the demonstrations in the order of `found`, and per trajectory of
    `found` whether its episode reached g*.
    """
    asked = [candidates(traj, env, rng, cfg, pieces.alter) for traj in found]
    with bar(total=len(found), desc="eq. (1)") as progress:
        def pick(ag, job):      # equation (1) draws nothing at random: both cores share the work
            progress.update(1)
            return pieces.select_goal(ag, job[0].states[0], job[0].states[-1], job[1], cfg.select)
        picks = read_only_map(agent, pick, list(zip(found, asked)), agent.threads)
    chosen = [cands[i] for cands, i in zip(asked, picks)]
    onward = [(traj.states[-1], goals) for traj, goals in zip(found, chosen)]
    with bar(total=len(onward), desc="verify") as progress:
        verified = run_episodes(agent, onward, short_envs, rng, progress=progress, values=False)
    demos, reached = [], [more.success for more in verified]
    for traj, goals, more in zip(found, chosen, verified):
        joined = join(traj, more, goals, more.success)
        demo = joined if more.success else pieces.relabel(joined, env)
        if demo is not None:
            demos.append(demo)
    return demos, reached


def task_expansion(agent, tasks, cfg, envs, short_envs, rng, pieces=None, bar=silent):
    """One round of sec 4.2. tasks: the previous round's tasks. Returns (demos, info).

    1. run the policy on the tasks and keep the successful trajectories s0 -> sT;
    2. for each, draw K candidates with one alteration and pick g* by equation (1);
    3. run the policy from sT toward g*: on success the joined trajectory demonstrates s0 -> g*,
       on failure the joined trajectory is relabelled with the goal it did reach (steps 2 and 3:
       pieces.expansion_step, by default expansion_step);
    4. not in the paper: the moves of each also in another order that physics allows (orders.py),
       and cfg.goal_parts parts of its goals, each with the moves it needs (hindsight.py).
    """
    env, pieces = envs[0], pieces or Pieces()
    batch = [tasks[i] for i in rng.integers(len(tasks), size=cfg.expand_episodes)]
    with bar(total=len(batch), desc="collect") as progress:
        found = [t for t in run_episodes(agent, batch, envs, rng, progress=progress,
                                         values=False) if t.success]
    demos, reached = pieces.expansion_step(agent, found, cfg, env, short_envs, rng, pieces, bar)
    other = 0
    if cfg.other_orders:
        with bar(total=sum(len(d.actions) > 1 for d in demos), desc="other orders") as progress:
            other = other_orders(demos, envs, rng, progress)
    if cfg.goal_parts:                   # off by default: no bar then (and add_parts draws nothing)
        longest = max((len(d.actions) for d in demos), default=0)       # the replay passes
        with bar(total=longest, desc="parts") as progress:
            add_parts(demos, envs, rng, cfg.goal_parts, progress)
    # picks_reached: the share of equation (1)'s picks that the policy reaches from s_T, the
    # leading indicator of whether V(s, g) tells a reachable goal from an unreachable one
    info = dict(attempts=len(batch), successful=len(found), joined=sum(reached),
                relabelled=len(demos) - sum(reached),
                picks_reached=sum(reached) / max(len(found), 1), other_orders=other,
                parts=sum(len(d.parts) for d in demos))
    return demos, info


def generated_stats(demos, info, cfg, log=print):
    """What a round of task expansion generated, logged: the paper's Table 1 and Figures 1-2
    (stats.task_stats), and, beyond it, the order its demonstrations move blocks in and how often
    they move a block that no goal names. Returns their figures."""
    stats = task_stats([d.goals for d in demos], [len(d.actions) for d in demos], cfg.n_blocks)
    stats.update(order_stats(with_other_orders(demos)),
                 unnamed_moves=unnamed_moves(learnt_from(demos)))
    runs = info["successful"]                     # one verification run from each s_T
    unusable = runs - info["joined"] - info["relabelled"]
    log(f"  {info['attempts']} attempts, {info['successful']} successful, {runs} runs from s_T: "
        f"{info['joined']} joined, {info['relabelled']} relabelled, {unusable} unusable "
        f"({info['picks_reached']:.0%} of the picks reached); "
        f"{stats['high_goal_tasks']} tasks with >= 3 high goals")
    if stats["higher_first"] is not None:          # the order the actor's data teach (stats.py)
        log(f"  {info['other_orders']} also in another order; {stats['higher_first']:.0%} of the "
            f"{stats['multi_layer_steps']} steps with goals on several layers move a higher one; "
            f"{info['parts']} parts: {stats['unnamed_moves']:.1%} of the steps move a block no "
            "goal names")
    return stats


# --------------------------------------------------------------------------------------------
# sec 4.3: self-distillation
# --------------------------------------------------------------------------------------------

def distillation_data(run, demos, cfg):
    """Sec 4.3: what BC learns from in a round -> (obs (N, n, 6), actions (N, 3)). The steps of
    the kept buffer (run.buffer_obs, run.buffer_act), then those of the new demonstrations, each
    followed by its other order and its parts where it has them (hindsight.learnt_from); of all
    these, the newest cfg.buffer_size (the memory bound of a long run). Draws nothing."""
    new_obs, new_act = demo_arrays(learnt_from(demos))
    return (np.concatenate([run.buffer_obs, new_obs])[-cfg.buffer_size:],
            np.concatenate([run.buffer_act, new_act])[-cfg.buffer_size:])


def distillation_tasks(run, demos, rng):
    """Sec 4.3: the tasks PPO trains on in a round -> (new, old). new: (s0, goals) of every new
    demonstration, each followed by those of its parts (an other order is the same task); old: as
    many tasks again, drawn uniformly with replacement from the earlier tasks (run.all_tasks: the
    newest cfg.buffer_size of them), so that PPO keeps the skills of earlier rounds while it learns
    the new tasks. Leaves `run` as it is (self_distill updates it)."""
    # s0 a copy: a view would keep the whole episode's states alive as long as the task
    new = [(t.states[0].copy(), t.goals) for d in demos for t in (d, *d.parts)]
    old = [run.all_tasks[i] for i in rng.integers(len(run.all_tasks), size=len(new))]
    return new, old


def self_distill(agent, run, demos, k, cfg, envs, short_envs, rng, pieces, bar=silent,
                 log=print):
    """Sec 4.3, in round k >= 1: BC on the new demos mixed with the kept ones
    (distillation_data), then PPO on the new tasks mixed with as many old ones
    (distillation_tasks). The task list, like the buffer, keeps the newest cfg.buffer_size
    entries. Updates `run`; returns the round's BC losses and PPO success, or nothing when the
    expansion generated no demonstration."""
    if not demos:
        log("  no demonstrations generated; keeping the current policy")
        return {}
    run.buffer_obs, run.buffer_act = pieces.distillation_data(run, demos, cfg)
    # round k's epochs: the k-th of cfg.distill_epochs, and its last for every round after
    epochs = cfg.distill_epochs[min(k, len(cfg.distill_epochs)) - 1]
    bc_loss = agent.bc(run.buffer_obs, run.buffer_act, epochs, cfg.bc_batch, cfg.bc_lr, rng,
                       bar=bar)
    log(f"  BC on {len(run.buffer_act)} steps: loss {bc_loss[0]:.3f} -> {bc_loss[-1]:.3f}")
    # parts_in "bc": PPO, and the next round's expansion, meet whole demonstrations' tasks only
    whole = demos if cfg.parts_in == "all" else [replace(d, parts=[]) for d in demos]
    new_tasks, old = pieces.distillation_tasks(run, whole, rng)
    ppo_log = ppo_phase(agent, new_tasks + old, cfg, envs, short_envs, rng, "PPO distil",
                        pieces=pieces, bar=bar)
    run.all_tasks = (run.all_tasks + new_tasks)[-cfg.buffer_size:]
    run.prev_tasks = new_tasks
    return dict(bc_loss=bc_loss, ppo_success=[m["success"] for m in ppo_log])


# --------------------------------------------------------------------------------------------
# sec 5: zero-shot evaluation on held-out shapes, and the direct-PPO baseline
# --------------------------------------------------------------------------------------------

def evaluate(agent, tasks_by_shape, envs, bar=silent, desc="zero-shot"):
    """Zero-shot success per shape with the greedy policy (the agent's rule, Config.greedy):
    {shape: rate}."""
    with bar(total=sum(map(len, tasks_by_shape.values())), desc=desc) as progress:
        return {name: success_rate(run_episodes(agent, tasks, envs, deterministic=True,
                                                progress=progress))
                for name, tasks in tasks_by_shape.items()}


class Test(NamedTuple):
    """A fixed test: tasks {name: [(s0, goals)]}, the same after every round, and the worlds they
    are run in."""
    tasks: dict
    worlds: list


def shapes_in_world(cfg, n, pool=None):
    """The Test of the held-out shapes in new worlds of n blocks (their physics in `pool`), on the
    fixed scenes eval_tasks makes for that world."""
    worlds = run_worlds(replace(cfg, n_blocks=n), pool)[0]
    return Test(eval_tasks(cfg, worlds[0]), worlds)


def zero_shot_tests(cfg, envs, pool=None):
    """Every Test a run makes after every round, by the name results.json records it under:

      eval      the held-out shapes of sec 5 in the run's own worlds, envs (the paper's Table 2)
      families  not in the paper: {family: Test}, tasks in which blocks that no goal names must
                move (shapes.FAMILIES: a site to clear, supports to build)
      blocks    not in the paper: {count: Test}, the held-out shapes in worlds of cfg.eval_blocks
                blocks (their physics in `pool`), tried with the weights learnt in this one
    """
    evals, families = eval_tasks(cfg, envs[0]), family_tasks(cfg, envs[0])
    return dict(eval=Test(evals, envs),
                families={f: Test(tasks, envs) for f, tasks in families.items()},
                blocks={str(n): shapes_in_world(cfg, n, pool) for n in cfg.eval_blocks})


def zero_shot(agent, tests, bar=silent):
    """evaluate on each Test of `tests` (zero_shot_tests), named and grouped as they are:
    {"eval": {shape: rate}, "families": {family: {task: rate}}, "blocks": {count: {...}}}."""
    with warnings.catch_warnings():                 # other worlds, asked for: no need to warn
        warnings.simplefilter("ignore", OtherWorldWarning)
        return {name: evaluate(agent, test.tasks, test.worlds, bar, desc=name)
                if isinstance(test, Test) else zero_shot(agent, test, bar)     # a group of Tests
                for name, test in tests.items()}


def direct_ppo(agent, evals, cfg, envs, short_envs, rng, pieces, bar=silent):
    """Not the method: the baseline of sec 5.3, plain PPO on the evaluation tasks themselves.
    No stretch tasks, which would be a curriculum of altered test tasks."""
    tasks = [t for per_shape in evals.values() for t in per_shape]
    ppo_log = ppo_phase(agent, tasks, cfg, envs, short_envs, rng, "PPO direct", stretch=0.0,
                        pieces=pieces, bar=bar)
    return dict(ppo_success=[m["success"] for m in ppo_log])


# --------------------------------------------------------------------------------------------
# The whole method: base skills, then rounds of expansion and distillation, evaluated each round
# --------------------------------------------------------------------------------------------

@dataclass
class Pieces:
    """The parts of the method that the course's exercises ask a student to write. train() uses
    these; exercise 7 passes the student's mlp_backward, gae and ppo_loss instead, the capstone
    (exercise 12) those and their alter, select_goal, relabel, expansion_step, distillation_data
    and distillation_tasks.
    alter and select_goal are called with the library's extra arguments too (restrict, p_add;
    the mode of the Table 3 ablations), which a student's version from exercises 5 and 6 does
    not take."""
    mlp_backward: Callable = mlp_backward
    gae: Callable = agent_lib.gae
    ppo_loss: Callable = agent_lib.ppo_loss
    alter: Callable = alter
    select_goal: Callable = select_goal
    relabel: Callable = relabel
    expansion_step: Callable = expansion_step
    distillation_data: Callable = distillation_data
    distillation_tasks: Callable = distillation_tasks


def make_agent(cfg, mlp_backward=mlp_backward):
    """The untrained agent of a run with settings cfg (its network, features, action heads and
    greedy rule)."""
    return Agent(cfg.n_blocks, n_x=N_X, n_y=1 if cfg.action == "drop" else cfg.n_blocks,
                 hidden=cfg.hidden, seed=cfg.seed, mlp_backward=mlp_backward, dtype=cfg.dtype,
                 network=cfg.network, features=cfg.features, greedy=cfg.greedy,
                 aux=cfg.aux_relations)


def train(cfg, agent=None, run=None, rng=None, pieces=None, on_round=None, bar=silent, log=print,
          workers=1):
    """Base skills (round 0), then cfg.rounds rounds of task expansion and self-distillation, each
    evaluated zero-shot. Returns the RunState; its results hold one record per round.

    To go on with a stopped run, pass its agent, RunState and Generator. on_round(k, agent, run,
    rng), if given, is called after every round (the CLI saves checkpoints there). workers > 1
    runs the physics in that many processes and shares each network minibatch between two
    threads (taskexp_lib/shards.py); the results are the same for any number.
    """
    pieces = pieces or Pieces()
    rng = np.random.default_rng(cfg.seed) if rng is None else rng
    agent = agent or make_agent(cfg, pieces.mlp_backward)
    run = run or RunState(results=dict(config=asdict(cfg), rounds=[], wallclock={}))
    agent.threads = min(workers, SHARDS)      # both cores on every minibatch (the same results)
    with one_blas_thread(), physics_pool(workers, cfg.action == "drop") as pool:
        envs, short_envs = run_worlds(cfg, pool)
        tests = zero_shot_tests(cfg, envs, pool)       # sec 5's, and those beyond the paper
        for k in range(run.last_round + 1, cfg.rounds + 1):
            with phase(f"round {k}"):
                if k == 0:                                                      # sec 4.1
                    record = base_skills(agent, run, cfg, envs, short_envs, rng, pieces, bar, log)
                elif cfg.baseline == "direct-ppo":                 # sec 5.3, not the method
                    log(f"[round {k}] direct PPO on the evaluation tasks")
                    record = direct_ppo(agent, tests["eval"].tasks, cfg, envs, short_envs, rng,
                                        pieces, bar)
                else:
                    log(f"[round {k}] task expansion from {len(run.prev_tasks)} tasks")
                    demos, info = task_expansion(agent, run.prev_tasks, cfg, envs, short_envs,
                                                 rng, pieces, bar)                     # sec 4.2
                    stats = generated_stats(demos, info, cfg, log)
                    distilled = self_distill(agent, run, demos, k, cfg, envs, short_envs, rng,
                                             pieces, bar, log)                         # sec 4.3
                    record = dict(expansion=info, **distilled, **stats)
            run.results["rounds"].append(dict(round=k, **zero_shot(agent, tests, bar), **record))
            run.last_round = k
            if on_round:
                on_round(k, agent, run, rng)
    return run
