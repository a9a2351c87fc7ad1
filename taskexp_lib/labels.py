"""taskexp_lib/labels.py -- not in the paper: labelled outcomes as data for V(s, g).

Equation (1) asks V(s, g) which one-alteration candidates g are one composable step beyond s_T:
g* = argmax_g V(sT, g) - V(s0, g). Trained by PPO alone, V(sT, g) learns a good part of that,
but the difference with V(s0, g) is a small signal under two independent errors, and the argmax
over K candidates finds the noise. Here the agent's own rollouts answer the question instead: the
policy runs toward candidates from s_T and from s_0 on the short budget, each run labels its
states with its discounted outcome, and the critic is regressed on the labels and, pair by pair,
on the difference equation (1) ranks by (agent.pair_value_loss). No geometric rule and no
look-ahead scores a candidate at selection time: the critic still has to learn it.
Most of a labelling's cost is the value fit, and fewer epochs pick worse. It runs once, after the
base PPO: labelling again before every later expansion cost most of rounds 1-3's time and did not
raise zero-shot success (lab/notes.md).
"""
import numpy as np

from .rollout import run_episodes
from .shards import read_only_map


def discounted_outcome(traj, gamma):
    """Monte-Carlo value targets of an episode's states but the last: gamma^(T-1-t) at step t on
    success (reward 1 on the step that succeeds), else 0 -- what V(s_t, g) estimates (as in
    taskexp.ppo_batch, running out of steps is failure)."""
    T = len(traj.actions)
    return gamma ** np.arange(T - 1, -1, -1.0) if traj.success else np.zeros(T)


def top_candidates(agent, traj, cands, k, pieces, mode):
    """The indices of the k candidates that equation (1) ranks first, best first, found with the
    method's own select_goal (an argmax) on the candidates not picked yet."""
    left, top = list(range(len(cands))), []
    for _ in range(min(k, len(cands))):
        i = left[pieces.select_goal(agent, traj.states[0], traj.states[-1],
                                    [cands[j] for j in left], mode)]
        top.append(i)
        left.remove(i)
    return top


def labelled(agent, tasks, cfg, envs, short_envs, rng, pieces, candidates, bar, log):
    """Label, then fit V, cfg.label_iters times; each time on cfg.label_tasks / label_iters tasks
    and for cfg.label_epochs / label_iters epochs.

    1. run the policy on the tasks and keep the successes s0 -> sT;
    2. for each, draw K one-alteration candidates (candidates: taskexp.candidates, as task
       expansion does) and keep cfg.label_per of them: the cfg.label_top that equation (1) ranks
       first (where the critic errs, its argmax finds it) and random others;
    3. run the policy toward each kept candidate from sT and from s0 on the short budget: every
       state of a run is labelled with its discounted outcome, and a failure adds the
       configuration it did reach as a positive (hindsight relabelling, as in sec 4.2);
    4. regress V on all labels so far (Agent.fit_value), then, with cfg.label_pair > 0, on the
       pairs (V(sT, g), V(s0, g)) with that weight on their difference (Agent.fit_value_pairs).
    Each round labels the picks of the critic the last round left. Logs what it did and returns
    it as a record.
    """
    env = envs[0]
    obs, targets, pairs, pair_targets = [], [], [], []
    n_runs, n_reached, loss = 0, 0, []
    epochs = -(-cfg.label_epochs // cfg.label_iters)             # ceil(label_epochs / iters)
    for it in range(cfg.label_iters):
        size = cfg.label_tasks // cfg.label_iters
        batch = [tasks[i] for i in rng.integers(len(tasks), size=size)]
        with bar(total=len(batch), desc=f"collect {it + 1}") as progress:
            found = [t for t in run_episodes(agent, batch, envs, rng, progress=progress,
                                             values=False) if t.success]
        drawn = [candidates(traj, env, rng, cfg, pieces.alter) for traj in found]
        with bar(total=len(found), desc=f"rank {it + 1}") as progress:
            def rank(ag, job):
                progress.update(1)
                return top_candidates(ag, job[0], job[1], cfg.label_top, pieces, cfg.select)
            tops = read_only_map(agent, rank, list(zip(found, drawn)), agent.threads)
        asked = []                                    # (trajectory, candidate) pairs to label
        for traj, cands, top in zip(found, drawn, tops):
            rest = [i for i in rng.permutation(len(cands)) if i not in top]
            asked += [(traj, cands[i]) for i in (top + rest)[: cfg.label_per]]
        with bar(total=2 * len(asked), desc=f"label {it + 1}") as progress:
            from_end = run_episodes(agent, [(t.states[-1], g) for t, g in asked], short_envs,
                                    rng, progress=progress, values=False)
            from_start = run_episodes(agent, [(t.states[0], g) for t, g in asked], short_envs,
                                      rng, progress=progress, values=False)
        for a, b in zip(from_end, from_start):   # V(sT, g) and V(s0, g): what equation (1) reads
            pairs.append(np.stack([a.obs()[0], b.obs()[0]]))
            pair_targets.append([discounted_outcome(e, cfg.gamma)[0] for e in (a, b)])
        for run in from_end + from_start:
            for e in (run, None if run.success else pieces.relabel(run, env)):
                if e is not None:
                    obs.append(e.obs()[:-1])
                    targets.append(discounted_outcome(e, cfg.gamma))
        n_runs += 2 * len(asked)
        n_reached += sum(e.success for e in from_end + from_start)
        if not obs:                                   # nothing solved yet: nothing to label
            continue
        loss = agent.fit_value(np.concatenate(obs), np.concatenate(targets), epochs,
                               cfg.bc_batch, cfg.label_lr, rng, bar=bar)
        if cfg.label_pair > 0:
            loss = agent.fit_value_pairs(np.stack(pairs), np.array(pair_targets), cfg.label_pair,
                                         epochs, cfg.bc_batch, cfg.label_lr, rng, bar=bar)
    rows, shown = int(sum(len(t) for t in targets)), loss or [float("nan")]
    log(f"  V on {rows} labelled states from {n_runs} runs ({n_reached / max(n_runs, 1):.0%} "
        f"reached): loss {shown[0]:.3f} -> {shown[-1]:.3f}")
    return dict(label_runs=n_runs, label_rows=rows, label_success=n_reached / max(n_runs, 1),
                label_loss=loss)

