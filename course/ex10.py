"""course/ex10.py -- exercise 10: the data of self-distillation, sec 4.3
(taskexp.distillation_data and taskexp.distillation_tasks).

The student writes distillation_data(run, demos, cfg) -> (obs, actions), what BC learns from in
a round, and distillation_tasks(run, demos, rng) -> (new, old), what PPO trains on. The first
draws nothing and is compared with the reference; the second draws the old tasks at random, so
the check asks for its contract rather than the reference's draws: the new tasks exactly, as many
old ones, each an earlier task, uniform over every earlier task (counted over many draws) and
drawn from the rng passed in.
"""
import copy

import numpy as np

import taskexp
from taskexp_lib.rollout import Trajectory

from .grader import Report, call, diff, first, graded
from .vectors import case

# distillation_data's cases: (name, n blocks, buffer steps, demos, buffer_size, with other orders
# and parts); case i has seed 1000 + i
DATA_CASES = [("room in the buffer", 4, 20, 3, 1000, False),
              ("other orders and parts", 5, 30, 4, 1000, True),
              ("the buffer full: the newest kept", 4, 50, 5, 40, True),
              ("the new steps alone overflow it", 3, 10, 6, 8, True)]

# distillation_tasks' cases: (name, earlier tasks, demos, with parts); case i has seed 1050 + i
TASK_CASES = [("a few demonstrations", 12, 5, False), ("with parts", 12, 6, True),
              ("one earlier task", 1, 4, True)]

BUFFER = ("BC learns from the kept buffer's steps (run.buffer_obs, run.buffer_act) followed by the "
          "new ones, of which the newest cfg.buffer_size stay")
LEARNT = ("every demonstration teaches its steps, then those of its other order and of each of "
          "its parts where it has them (observations under each trajectory's own goals)")
NEW = ("the new tasks: (s0, goals) of each demonstration, then of each of its parts, in order; "
       "an other order is the same task again")
RUN = "leave `run` as it is: self_distill updates it after both calls"
OLD = ("as many old tasks as new ones, each drawn uniformly, with replacement, from every earlier "
       "task (run.all_tasks), with the rng passed in: PPO must not forget the earlier rounds")


def made_up_trajectory(rng, n, T):
    """A trajectory of T random steps (states on no grid: the data are all that matters here)."""
    goals = {int(b): (float(rng.normal()), float(rng.random())) for b in
             rng.permutation(n)[:1 + int(rng.integers(n))]}
    return Trajectory(goals, rng.normal(size=(T + 1, n, 6)), rng.integers(0, 5, (T, 3)), True)


def made_up_demos(rng, n, count, extras):
    """`count` demonstrations; with extras, some have an other order and some parts."""
    demos = []
    for k in range(count):
        d = made_up_trajectory(rng, n, 1 + int(rng.integers(4)))
        if extras and k % 2 == 0:
            d.other_order = made_up_trajectory(rng, n, len(d.actions))
        if extras and k % 3 != 1:
            d.parts = [made_up_trajectory(rng, n, 1 + int(rng.integers(2)))
                       for _ in range(1 + int(rng.integers(2)))]
        demos.append(d)
    return demos


def as_fields(t):
    return dict(goals=t.goals, states=t.states, actions=t.actions, success=True,
                other_order=t.other_order and as_fields(t.other_order),
                parts=[as_fields(p) for p in t.parts])


def as_trajectory(f):
    return Trajectory(f["goals"], f["states"], f["actions"], True,
                      other_order=f["other_order"] and as_trajectory(f["other_order"]),
                      parts=[as_trajectory(p) for p in f["parts"]])


def make_data_case(n, steps, count, size, extras, seed):
    rng = np.random.default_rng(seed)
    run = taskexp.RunState(buffer_obs=rng.normal(size=(steps, n, 6)).astype(np.float32),
                           buffer_act=rng.integers(0, 5, (steps, 3)))
    demos = made_up_demos(rng, n, count, extras)
    obs, actions = taskexp.distillation_data(run, demos, taskexp.Config(buffer_size=size))
    return dict(buffer_obs=run.buffer_obs, buffer_act=run.buffer_act,
                demos=[as_fields(d) for d in demos], obs=obs, actions=actions)


def data_case(distillation_data, i, name, n, steps, count, size, extras):
    """distillation_data case i -> (name, detail, problem, hint)."""
    c = case(f"ex10/data/{i}", lambda: make_data_case(n, steps, count, size, extras, 1000 + i))
    run = taskexp.RunState(buffer_obs=c["buffer_obs"], buffer_act=c["buffer_act"])
    got, err = call(distillation_data, run, [as_trajectory(d) for d in c["demos"]],
                    taskexp.Config(buffer_size=size))
    hint = BUFFER
    if err is None:
        if not (isinstance(got, (tuple, list)) and len(got) == 2):
            err = f"returned {type(got).__name__}, expected a pair (obs, actions)"
        else:
            err = first(diff("actions", got[1], c["actions"]), diff("obs", got[0], c["obs"]))
            got_n, want_n = len(np.asarray(got[1])), len(c["actions"])
            if err and got_n != want_n and want_n < size:     # nothing cut: steps missing/extra
                hint = LEARNT if extras else BUFFER
            elif err and extras and got_n == want_n and \
                    first_difference(got, c) >= want_n - new_steps(c):     # in the new steps
                hint = LEARNT
    if err is None and changes_run(lambda r: distillation_data(
            r, [as_trajectory(d) for d in c["demos"]], taskexp.Config(buffer_size=size)), run):
        err, hint = "run.buffer_obs or run.buffer_act changed", RUN
    detail = f"{steps} steps kept, {count} demos, buffer_size {size}"
    return f"distillation_data, {name}", detail, err, hint


def changes_run(fn, run):
    """Does fn(run), called on a copy that is not copied again, change the run's buffer or
    tasks? (call() hands the student copies, so it cannot see this.)"""
    mine = copy.deepcopy(run)
    try:
        fn(mine)
    except Exception:
        return False                      # what it raises, the other cases report
    same = lambda a, b: (a is None and b is None) or (
        a is not None and b is not None and len(a) == len(b) and all(
            np.array_equal(np.asarray(x[0] if isinstance(x, tuple) else x),
                           np.asarray(y[0] if isinstance(y, tuple) else y))
            for x, y in zip(a, b)))
    return not all(same(getattr(mine, f), getattr(run, f))
                   for f in ("buffer_obs", "buffer_act", "all_tasks", "prev_tasks"))


def new_steps(c):
    """How many of a case's expected BC steps are new (the rest come from the kept buffer)."""
    return min(len(c["actions"]), sum(len(t["actions"]) for d in c["demos"] for t in (
        d, *([d["other_order"]] if d["other_order"] else []), *d["parts"])))


def first_difference(got, c):
    """The first row where the student's BC data differ from the reference's."""
    try:
        bad = ~np.isclose(np.asarray(got[0], float), c["obs"]).all(axis=(1, 2)) | \
            (np.asarray(got[1]) != c["actions"]).any(axis=1)
        return int(np.argmax(bad))
    except Exception:
        return 0


def make_tasks_case(earlier, count, extras, seed):
    rng = np.random.default_rng(seed)
    tasks = [(rng.normal(size=(4, 6)), made_up_trajectory(rng, 4, 1).goals)
             for _ in range(earlier)]
    demos = made_up_demos(rng, 4, count, extras)
    new, _ = taskexp.distillation_tasks(taskexp.RunState(all_tasks=tasks), demos, rng)
    return dict(all_tasks=tasks, demos=[as_fields(d) for d in demos], new=new)


def same_task(a, b):
    try:
        return a[1] == b[1] and np.array_equal(np.asarray(a[0]), np.asarray(b[0]))
    except Exception:
        return False


def tasks_of(distillation_tasks, run, demos, seed):
    """The student's (new, old) as lists, or raise ValueError saying what is wrong."""
    got, err = call(distillation_tasks, run, demos, np.random.default_rng(seed))
    if err:
        raise ValueError(err)
    if not (isinstance(got, (tuple, list)) and len(got) == 2):
        raise ValueError(f"returned {type(got).__name__}, expected a pair (new, old)")
    return list(got[0]), list(got[1])


def tasks_problem(distillation_tasks, c, seed, earlier_only):
    """What is wrong with the new and old tasks of a case -> (problem, hint), (None, None)."""
    demos = [as_trajectory(d) for d in c["demos"]]
    run = taskexp.RunState(all_tasks=c["all_tasks"], prev_tasks=c["all_tasks"][-2:])
    try:
        new, old = tasks_of(distillation_tasks, run, demos, seed)
        again, other = (tasks_of(distillation_tasks, run, demos, s)[1] for s in (seed, seed + 1))
    except ValueError as e:
        return str(e), NEW
    if len(new) != len(c["new"]) or not all(map(same_task, new, c["new"])):
        bad = next((k for k, (a, b) in enumerate(zip(new, c["new"])) if not same_task(a, b)),
                   min(len(new), len(c["new"])))
        return f"{len(new)} new tasks, expected {len(c['new'])}; first differs at {bad}", NEW
    if len(old) != len(new):
        return f"{len(old)} old tasks for {len(new)} new ones", OLD
    if not all(any(same_task(t, e) for e in earlier_only) for t in old):
        return "an old task is none of the earlier tasks (run.all_tasks)", OLD
    if not all(map(same_task, old, again)) or (len(earlier_only) > 1 and
                                               all(map(same_task, old, other))):
        return "the old tasks do not follow the rng passed in (same seed, other draws)", OLD
    if changes_run(lambda r: distillation_tasks(r, demos, np.random.default_rng(seed)), run):
        return "run.all_tasks or run.prev_tasks changed", RUN
    return None, None


def uniform_problem(distillation_tasks):
    """Old tasks drawn 4000 times from 8 earlier ones: each about 500 times (binomial sd 21)."""
    rng = np.random.default_rng(1099)
    earlier = [(np.full((3, 6), k, float), {0: (float(k), 0.05)}) for k in range(8)]
    demos = [Trajectory({1: (0.0, 0.05)}, rng.normal(size=(2, 3, 6)), np.zeros((1, 3), int), True)
             for _ in range(4000)]
    run = taskexp.RunState(all_tasks=earlier, prev_tasks=earlier[-2:])
    try:
        _, old = tasks_of(distillation_tasks, run, demos, 1099)
        counts = np.bincount([int(t[1][0][0]) for t in old], minlength=8)
    except Exception as e:
        return f"could not count the old tasks' draws ({type(e).__name__}: {e})"
    if len(old) != 4000 or counts.min() < 400 or counts.max() > 600:
        return (f"{len(old)} old tasks, drawn {counts.tolist()} times from the 8 earlier "
                "tasks; expected 4000, each about 500 times")
    return None


@graded
def check_ex10(distillation_data, distillation_tasks):
    """distillation_data(run, demos, cfg) -> (obs, actions);  distillation_tasks(run, demos, rng)
    -> (new, old)."""
    rep = Report("ex10")
    for i, args in enumerate(DATA_CASES):
        rep.case(*data_case(distillation_data, i, *args))
    for i, (name, earlier, count, extras) in enumerate(TASK_CASES):
        c = case(f"ex10/tasks/{i}", lambda: make_tasks_case(earlier, count, extras, 1050 + i))
        rep.case(f"distillation_tasks, {name}", f"{earlier} earlier tasks, {count} demos",
                 *tasks_problem(distillation_tasks, c, 1050 + i, c["all_tasks"]))
    rep.case("distillation_tasks, uniform draws", "8 earlier tasks, 4000 demos",
             uniform_problem(distillation_tasks), OLD)
    rep.done(" (BC's data agree with the reference; PPO's tasks follow the contract)")
