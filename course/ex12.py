"""course/ex12.py -- exercise 12, the capstone: the student's own pieces of the method grow the
tasks and lift zero-shot success.

Nothing new to write: the student's alter (exercise 5), select_goal and relabel (6), join and
expansion_step (9), distillation_data and distillation_tasks (10) are passed to the library's
task_expansion and self_distill (sec 4.2 and 4.3), which run two rounds at a tiny budget from the
round-0 agent of a default run (course/data/round0.npz, its base tasks drawn afresh). Its networks
learn with the student's backward passes and policy distribution too (exercises 1 to 4 and 8):
in a kit the library's own are stubs, so every piece the student wrote runs here. The check
passes when what their code generated grows and what it learnt shows on the held-out shapes:

- the moves per generated demonstration rise round by round (round 0's base tasks take one), by
  at least GROWTH each round;
- zero-shot greedy success on at least one held-out shape ("I", "Y", "3T"; sec 5) after round 2
  is at least LIFT above the round-0 agent's on the same tasks.

Measured on seeds 0, 1 and 2 of the capstone's own draws, with the library's pieces and with the
instructor notebooks' (lab/bench/capstone.py, lab/notes.md). The check runs seed 0 only,
deterministic on one machine: the same submission gets the same grade. Some wrong pieces still
pass here (PPO on new tasks alone does); their own exercise's check catches them.
"""
import time

import numpy as np

import taskexp
from agent import Agent
from env2d import BlockWorld, run_worlds
from taskexp_lib import nn, one_blas_thread
from taskexp_lib.geometry import BLOCK_H
from taskexp_lib.shapes import eval_tasks

from .ex6 import DistanceCritic
from .ex7 import unfinished as ex7_unfinished
from .ex11 import CHECKPOINT
from .grader import Report, graded, tiny_env
from .problems import CAPSTONE_NEEDS, FUNCTIONS, NOTEBOOKS

# the budget: the default's settings, smaller (about a minute on one core of an AMD EPYC: 54 to
# 71 s measured, lab/notes.md)
CAPSTONE = dict(seed=0, base_tasks=500, expand_episodes=600, candidates=64, ppo_steps=4000,
                distill_epochs=(8,), eval_episodes=100)
# the bars, set well below what the reference clears on seeds 0-2 (lab/bench/capstone.py): about
# 1.5 more moves each round; a best gain of 41 to 44 points with the library's pieces, 39 to 52
# with the instructor notebooks'
GROWTH = 0.5           # more moves per demonstration than the round before, at least
LIFT = 0.20            # zero-shot success above round 0's on one held-out shape, at least
LAST = {}              # the figures of the last check, for the notebook's plot


def capstone_pieces(gae, ppo_loss, alter, select_goal, relabel, expansion_step,
                    distillation_data, distillation_tasks):
    """taskexp.Pieces with the student's functions. The library calls alter with restrict and
    p_add, select_goal with the mode and expansion_step with a progress bar, which the exercises'
    versions do not take: the capstone uses their defaults (one alteration, half adds; equation
    1; no bar), so these are dropped."""
    return taskexp.Pieces(
        gae=gae, ppo_loss=ppo_loss,
        alter=lambda goals, env, rng, restrict=True, p_add=0.5: alter(goals, env, rng),
        select_goal=lambda agent, s0, sT, candidates, mode="ours":
            select_goal(agent, s0, sT, candidates),
        relabel=relabel, distillation_data=distillation_data,
        distillation_tasks=distillation_tasks,
        # the library passes its progress bar too, which exercise 9's contract leaves out
        expansion_step=lambda agent, found, cfg, env, short_envs, rng, pieces, bar=None:
            expansion_step(agent, found, cfg, env, short_envs, rng, pieces))


def students_agent(agent, mlp_backward=None, attention_backward=None, dist=None):
    """The agent, its networks' backward passes and its policy distribution replaced by the
    student's (exercises 1, 8 and 2) where given: every MLP's backward_fn, every self-attention
    layer's backward (the cache of its forward handed over as exercise 8 asks) and action_dist.
    A layer becomes an instance of a subclass whose backward runs theirs, so that the replicas
    the training makes of it (shards.py, copies) run it on their own caches.
    -> the agent, changed in place."""
    students = type("StudentsAttention", (nn.SelfAttention,), dict(
        backward=lambda layer, dout: attention_step(layer, attention_backward, dout)))
    for net in (agent.actor, agent.critic):
        for module in net.modules.values():
            if mlp_backward is not None and isinstance(module, nn.MLP):
                module.backward_fn = mlp_backward
            if attention_backward is not None and isinstance(module, nn.SelfAttention):
                module.__class__ = students
    if dist is not None:
        agent.action_dist = dist
    return agent


def attention_step(layer, attention_backward, dout):
    """SelfAttention.backward(dout) by the student's attention_backward(params, cache, dout)."""
    B, n, D = np.shape(dout)
    cache = dict(x=layer.x2.reshape(B, n, D), Q=layer.Q, K=layer.K, V=layer.V, attn=layer.attn,
                 Y=layer.Y.reshape(B, n, D), heads=layer.heads, scale=layer.scale)
    grads, dx = attention_backward(layer.params, cache, dout)
    layer.dx = np.asarray(dx, dtype=layer.dtype).reshape(B, n, D)
    return {k: np.asarray(grads[k], dtype=layer.dtype) for k in layer.params}


def capstone_config(seed):
    c = CAPSTONE
    return taskexp.Config(seed=seed, expand_episodes=c["expand_episodes"],
                          candidates=c["candidates"], ppo_steps=c["ppo_steps"],
                          distill_epochs=c["distill_epochs"], eval_episodes=c["eval_episodes"])


def grow(pieces, seed=CAPSTONE["seed"], log=print, **networks):
    """Two rounds of task expansion and self-distillation with `pieces`, from the round-0 agent
    -> [per round 0, 1, 2: dict(round, moves, goals, height, demos, eval {shape: success})].
    networks: the student's mlp_backward, attention_backward and dist (students_agent).
    Stops after round 1 when its demonstrations did not grow (GROWTH): round 2 cannot mend it."""
    cfg, t0 = capstone_config(seed), time.time()
    agent = students_agent(Agent.load(CHECKPOINT), **networks)
    rng = np.random.default_rng(seed)
    with one_blas_thread():
        envs, short_envs = run_worlds(cfg)
        tests = eval_tasks(cfg, envs[0])
        tasks, obs, actions = taskexp.base_demos(cfg, envs, rng, CAPSTONE["base_tasks"])
        run = taskexp.RunState(last_round=0, buffer_obs=obs, buffer_act=actions,
                               all_tasks=list(tasks), prev_tasks=tasks)

        def figures(k, goals, moves):
            """Round k's record: its tasks (goal dicts), the moves of their demonstrations."""
            mean = lambda values: float(np.mean(values)) if goals else 0.0
            return dict(round=k, moves=mean(moves), goals=mean([len(g) for g in goals]),
                        height=mean([max(y for _, y in g.values()) / BLOCK_H - 0.5
                                     for g in goals]),
                        demos=len(goals), eval=taskexp.evaluate(agent, tests, envs))
        records = [figures(0, [g for _, g in tasks], [1] * len(tasks))]   # a base task: one move
        for k in (1, 2):
            demos, info = taskexp.task_expansion(agent, run.prev_tasks, cfg, envs, short_envs, rng,
                                                 pieces)
            taskexp.self_distill(agent, run, demos, k, cfg, envs, short_envs, rng, pieces,
                                 log=lambda *a: None)
            records.append(figures(k, [d.goals for d in demos], [len(d.actions) for d in demos]))
            log(f"  round {k}: {len(demos)} demonstrations, {records[-1]['moves']:.2f} moves "
                f"each; zero-shot " + ", ".join(f"{s} {v:.0%}"
                                                for s, v in records[-1]["eval"].items())
                + f" ({time.time() - t0:.0f} s)")
            if records[-1]["moves"] < records[-2]["moves"] + GROWTH:
                break
    return records


def problem_of(records):
    """What the figures of grow() miss, or None."""
    moves = [r["moves"] for r in records]
    if len(moves) < 3 or not all(b >= a + GROWTH for a, b in zip(moves, moves[1:])):
        return (f"moves per demonstration in rounds {', '.join(str(r['round']) for r in records)}:"
                f" {', '.join(f'{m:.2f}' for m in moves)}; each round must add at least {GROWTH}"
                + (" (round 2 not run)" if len(moves) < 3 else ""))
    lift = {s: records[-1]["eval"][s] - records[0]["eval"][s] for s in records[0]["eval"]}
    if max(lift.values()) < LIFT:
        return ("zero-shot success after round 2 against round 0: " + ", ".join(
            f"{s} {records[-1]['eval'][s]:.0%} (round 0: {records[0]['eval'][s]:.0%})"
            for s in lift) + f"; one shape must gain at least {100 * LIFT:.0f} points")
    return None


def unfinished(mlp_backward, gae, ppo_loss, alter, select_goal, relabel, attention_backward,
               join, expansion_step, distillation_data, distillation_tasks, dist=None):
    """The exercises among CAPSTONE_NEEDS whose functions still raise NotImplementedError, found
    by calling each once on tiny inputs (two rounds would stop at the first only)."""
    rng, env = np.random.default_rng(0), tiny_env(3)
    s = np.zeros((3, 6))
    s[:, 0], s[:, 1] = (-0.3, 0.0, 0.3), BLOCK_H / 2
    traj = taskexp.Trajectory({0: (0.0, BLOCK_H / 2)}, np.stack([s, s]), np.zeros((1, 3), int),
                              True)
    run = taskexp.RunState(buffer_obs=np.zeros((1, 3, 6)), buffer_act=np.zeros((1, 3), int),
                           all_tasks=[(s, traj.goals)])
    x = np.ones((1, 2, 2))
    cache = dict(x=x, Q=x[:, None], K=x[:, None], V=x[:, None], attn=np.full((1, 1, 2, 2), 0.5),
                 Y=x, heads=1, scale=1 / np.sqrt(2))
    probes = {"ex5": lambda: alter(traj.goals, env, rng),
              "ex6": lambda: (select_goal(DistanceCritic(), s, s, [traj.goals]),
                              relabel(traj, env)),
              "ex8": lambda: attention_backward({f"{w}{c}": np.eye(2) if w == "W" else np.zeros(2)
                                                 for w in "Wb" for c in "qkvo"}, cache, x),
              "ex9": lambda: (join(traj, traj, traj.goals, True),
                              expansion_step(None, [], taskexp.Config(n_blocks=3),
                                             BlockWorld(3), [], rng, taskexp.Pieces())),
              "ex10": lambda: (distillation_data(run, [traj], taskexp.Config()),
                               distillation_tasks(run, [traj], rng))}
    missing = ex7_unfinished(mlp_backward, gae, ppo_loss, dist)
    for ex, probe in probes.items():
        try:
            probe()
        except NotImplementedError:
            missing.append(ex)
        except Exception:                  # a wrong answer: the rounds show what it does
            pass
    return sorted(set(missing), key=lambda ex: int(ex[2:]))


@graded
def check_ex12(mlp_backward, gae, ppo_loss, alter, select_goal, relabel, attention_backward,
               join, expansion_step, distillation_data, distillation_tasks, dist=None):
    """Behavioural: with the student's pieces (dist: their exercise 2's distribution, or None for
    agent.ActionDist), two rounds grow the tasks and lift zero-shot success on a held-out shape
    (GROWTH, LIFT)."""
    rep, secs = Report("ex12"), 0.0
    missing = unfinished(mlp_backward, gae, ppo_loss, alter, select_goal, relabel,
                         attention_backward, join, expansion_step, distillation_data,
                         distillation_tasks, dist)
    LAST.clear()
    if missing:
        names = [f"{ex} ({', '.join(FUNCTIONS[ex])} in {NOTEBOOKS[ex]})" for ex in missing]
        problem = (f"not done yet (raises NotImplementedError): {'; '.join(names)}. The capstone "
                   f"runs every piece you wrote ({', '.join(CAPSTONE_NEEDS)}): do them first")
    else:
        print("ex12: two rounds of task expansion and self-distillation with your pieces "
              "(about a minute) ...", flush=True)
        t0 = time.time()
        try:
            records = grow(capstone_pieces(gae, ppo_loss, alter, select_goal, relabel,
                                           expansion_step, distillation_data, distillation_tasks),
                           mlp_backward=mlp_backward, attention_backward=attention_backward,
                           dist=dist)
            LAST.update(records=records)
            problem = problem_of(records)
        except Exception as e:
            problem = f"the rounds raised {type(e).__name__}: {e}"
        secs = time.time() - t0
    rep.case("two rounds", f"seed {CAPSTONE['seed']}, from course/data/round0.npz", problem,
             "pass the checks of the exercises it runs first; if they pass, look at what your "
             "expansion step returns in a round (demonstrations of tasks one alteration beyond "
             "the last round's, from s0) and at the tasks PPO trains on")
    rep.done(f" (the tasks grew and zero-shot success rose, {secs:.0f} s)")
