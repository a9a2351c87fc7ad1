"""taskexp_lib/features.py -- what the networks see of a block (sec 3): the features of each block
token, computed from an observation.

"plain": a block's pose and its goal, on their own (the default). "relations": plus stacking
preconditions computed by hand (RELATIONS), which a network over plain features must learn by
comparing blocks (self-attention does). "relations+leave": plus, for a block in the way, a code
of the spot it must leave (issue 53's lever L). "relations+leave+stay": plus, for a block that
already stands under a goal not met yet, that it is a support in place (lever S). The world's
geometry comes from geometry.py.

relation_targets gives the same relations as targets instead (AUX_FACTS): with
Config.aux_relations the actor learns to predict them from any features (agent.aux_loss).
"""
import numpy as np

from .geometry import BLOCK_H, BLOCK_W, TABLE_X, THRESHOLD, observation

N_RBF = 21                      # RBF centres spaced BLOCK_W / 2 across the table


# The feature layout: (name, width) of each column group, in order; n_y (the number of layers)
# scales heights.
# Tests and notebooks find a feature by name (feature_columns), never by its column number.
# The features: "plain" (what one block and its goal are), "relations" (plus RELATIONS,
# stacking preconditions computed by hand, which a network over plain features must learn) or
# "relations+leave" (plus where a block in the way stands: the spot it must leave) or
# "relations+leave+stay" (plus whether a block is a support in place, which must stay).
FEATURES = ("plain", "relations", "relations+leave", "relations+leave+stay")


def feature_layout(n_y, features):
    plain = [("x", 1), ("y", 1), ("cos", 1), ("sin", 1), ("has_goal", 1), ("goal_x", 1),
             ("goal_y", 1), ("to_goal_x", 1), ("to_goal_y", 1), ("at_goal", 1),
             ("x_rbf", N_RBF), ("goal_x_rbf", N_RBF)]
    if features == "plain":
        return plain
    relations = plain + [*[(name, 1) for name in RELATIONS], ("support_wanted_rbf", N_RBF)]
    if features == "relations":
        return relations
    leave = relations + [("spot_to_leave_rbf", N_RBF)]
    return leave if features == "relations+leave" else leave + [("support_in_place", 1)]


def feature_columns(n_y, features):
    """{feature name: slice of its columns} for features made with n_y layers."""
    out, start = {}, 0
    for name, width in feature_layout(n_y, features):
        out[name], start = slice(start, start + width), start + width
    return out


def featurize(obs, n_y, features):
    """obs (B, n, 6) [x, y, angle, goal_x, goal_y, has_goal] -> features (B, n, F), laid out as
    feature_layout(n_y, features) says (F = 10 + 2 N_RBF plain, 16 + 3 N_RBF with the relations,
    16 + 4 N_RBF with relations+leave, 17 + 4 N_RBF with relations+leave+stay).

    Besides normalised pose, goal and offset to goal, each block gets RBF codes of its x and goal
    x: what it is and where it wants to be, on its own. Heights are numbers only. A one-hot code
    of the layer (as until 2026-12-04) gives every layer weights of its own, and a layer no
    demonstration has reached yet meets weights that never learnt: the policy then dropped the
    top block of a tower of four a bin or two off its goal x (lab/bench/build_order.py). A number
    carries what the lower layers taught up to the next one.
    Which block rests under which, or whose goal lies on whose, is a relation between two blocks:
    features="relations" adds hand-computed ones (RELATIONS); with "plain" the network must find
    them itself (self-attention compares every pair of blocks). Two relations come with an RBF
    code of a place: where a goal waits for a support (needs_support: where a free block should
    go), and, with "relations+leave", where a block in the way stands (in_the_way: the spot it
    must leave). The x-head scores the x-bins of a block from its token, and a block to clear
    away has no goal to aim at: with "relations" its x-head kept 26-61% of its mass within a
    block width of where it stood after round 0 (seeds 0-4), so that a cleared block often
    landed back on the site (lab/notes.md, 2026-12-07, lever L). "relations+leave+stay" adds
    support_in_place, the mirror of needs_support as in_the_way is of blocked: the block head
    picks a block from its token, and a block that already stands under a goal in the air looks,
    on its own, like the free block the goal wants there (its x code is the wanted spot's). With
    lever L the policy picked such a support again and dropped it back into its column (pulled
    from under a stack, a block lands on top: nothing built) in 64% of seed 2's "3 up" scenes
    after round 3 (lab/notes.md, 2026-12-07, night).
    Goal columns are multiplied by has_goal, so "no goal" is all zeros; heights are divided by
    the height of n_y layers.
    """
    if features not in FEATURES:
        raise ValueError(f"features {features!r}: one of {FEATURES}")
    obs = np.asarray(obs, dtype=np.float64)
    if obs.ndim != 3 or obs.shape[-1] != 6:
        raise ValueError(f"obs must have shape (B, n, 6), got {obs.shape}")
    w, h = BLOCK_W, BLOCK_H
    half, mid = (TABLE_X[1] - TABLE_X[0]) / 2, (TABLE_X[1] + TABLE_X[0]) / 2
    x, y, ang, gx, gy, g, at_goal = _poses(obs)
    centres = np.linspace(TABLE_X[0], TABLE_X[1], N_RBF)
    rbf = lambda v: np.exp(-0.5 * ((v[..., None] - centres) / (w / 4)) ** 2)
    cols = [(x - mid) / half, y / (n_y * h), np.cos(ang), np.sin(ang), g,
            g * (gx - mid) / half, g * gy / (n_y * h), g * (gx - x) / w, g * (gy - y) / h, at_goal]
    x_code = rbf(x)                             # where a block is; relations+leave reuses it
    plain = [np.stack(cols, -1), x_code, g[..., None] * rbf(gx)]
    if features == "plain":
        return np.concatenate(plain, axis=-1)
    rel = relations(x, y, gx, gy, g, at_goal)
    spots = [rel["needs_support"][..., None] * rbf(gx)]
    if features != "relations":
        spots.append(rel["in_the_way"][..., None] * x_code)
    if features == "relations+leave+stay":
        spots.append(rel["support_in_place"][..., None])
    return np.concatenate([*plain, np.stack([rel[name] for name in RELATIONS], -1), *spots],
                          axis=-1)


def _poses(obs):
    """obs (B, n, 6) -> x, y, angle, goal x, goal y, has_goal and at_goal (a goal met: its block's
    centre nearer than THRESHOLD), each (B, n); has_goal and at_goal are 0 or 1."""
    x, y, ang, gx, gy, g = (obs[..., j] for j in range(6))
    g = (g > 0.5).astype(np.float64)
    return x, y, ang, gx, gy, g, g * (np.hypot(gx - x, gy - y) < THRESHOLD)


# Hand-computed stacking preconditions: what self-attention over blocks would have to learn.
RELATIONS = ("blocked", "supported", "wait", "first", "covered", "in_the_way")


def relations(x, y, gx, gy, g, at_goal):
    """Pairwise facts about blocks and goals, pooled over the other blocks j (what attention finds).

    All inputs (B, n).  Returns {name: (B, n)} for the RELATIONS, needs_support and
    support_in_place:
      blocked     another block overlaps my goal spot now (placing me there would be a no-op)
      supported   my goal is on the table, or another block rests right under my goal spot now
      wait        another unreached goal lies under mine: that block must go first
      first       my goal lies under another block's goal: I am its support
      covered     a block rests on me now
      in_the_way  I stand on the spot of another block's goal not met yet: "blocked" seen from
                  the block that must move away first (what the policy picks is a block, so the
                  fact must be in the blocker's token, not only in the goal block's)
      held        my goal is on the table, or blocks now under my goal spot hold a block up
                  there: one under its centre ("supported"), or one under each of its halves
                  (the stem of "Y" on its two legs, which "supported" misses)
      needs_support  has goal, not reached, not held: a free block must go under it, and
                  the RBF code of its goal x (pooled) tells the free blocks where
      support_in_place  I stand right under a goal spot not met yet (my centre within half a
                  block width of its x, on a lower layer), and in no goal's way: I am part of
                  its support, and moving me undoes it (pulled from under a stack, a block
                  lands on top of it)
    """
    w, h = BLOCK_W, BLOCK_H
    other = 1.0 - np.eye(x.shape[1])                                   # (n, n): j != i
    # (B, i, j): is |a_j - b_i| < tol
    near = lambda a, b, tol: (np.abs(a[:, None, :] - b[:, :, None]) < tol)
    any_j = lambda m: (m * other).max(-1)
    pending = g * (1.0 - at_goal)                                      # goals not reached yet
    # (B, i, j): block j is in the layer under i's goal spot (below), its centre dx to the right
    # of the spot's; under: below and overlapping the spot, so that it carries part of it
    below, dx = near(y, gy - h, h / 2), x[:, None, :] - gx[:, :, None]
    under = below & (np.abs(dx) < w)
    # (B, i, j): block j overlaps i's goal spot now; read the other way round (B, j, i), block i
    # stands on j's goal spot
    on_spot = near(x, gx, w * 0.95) & near(y, gy, h * 0.95)
    out = dict(
        blocked=g * any_j(on_spot),
        supported=g * np.maximum(gy < h, any_j(below & (np.abs(dx) < w / 2))),
        wait=g * any_j(pending[:, None, :] * (near(gx, gx, w) & near(gy, gy - h, h / 2))),
        first=g * any_j(g[:, None, :] * (near(gx, gx, w) & near(gy - h, gy, h / 2))),
        covered=any_j(near(x, x, w) & near(y - h, y, h / 2)),
        in_the_way=any_j(pending[:, None, :] * on_spot.transpose(0, 2, 1)))
    both_halves = any_j(under & (dx < 0)) * any_j(under & (dx > 0))
    out["held"] = np.maximum(out["supported"], g * both_halves)
    out["needs_support"] = pending * (1.0 - out["held"])
    # (B, i, j): block i stands in the column under j's goal spot, below it
    column = near(gx, x, w / 2) & (y[:, :, None] < gy[:, None, :] - h / 2)
    out["support_in_place"] = any_j(pending[:, None, :] * column) * (1.0 - out["in_the_way"])
    return out


# The facts that an auxiliary loss (Config.aux_relations) asks each actor token for, with plain
# features: the RELATIONS that say what must move first and what must stay, as the hand-computed
# features would give them, but learnt, so that the network still sees only the blocks and goals.
AUX_FACTS = ("blocked", "held", "wait", "first", "covered", "in_the_way", "needs_support",
             "support_in_place")


def relation_targets(obs, chunk=4096):
    """obs (B, n, 6) -> (B, n, len(AUX_FACTS)) float32 in {0, 1}: the facts of AUX_FACTS for
    every block (relations), in chunks of `chunk` scenes to bound the (chunk, n, n) pair arrays."""
    obs = np.asarray(obs, dtype=np.float64)
    out = np.zeros((*obs.shape[:2], len(AUX_FACTS)), dtype=np.float32)
    for i in range(0, len(obs), chunk):
        x, y, _, gx, gy, g, met = _poses(obs[i:i + chunk])       # as featurize reads them
        known = relations(x, y, gx, gy, g, met)
        out[i:i + chunk] = np.stack([known[name] for name in AUX_FACTS], -1)
    return out


def one_drop_away(state, goals, threshold=THRESHOLD):
    """True when every goal of `goals` not yet met in `state` (its block's centre `threshold` or
    farther from the target) can be met by one drop of its block: no other block overlaps its
    spot, and the table or another block right under it holds it up. The test of what one more
    action can meet, by which the course and lab/bench/feasible_goals.py judge the goals that
    equation (1) and its ablations pick."""
    # relations' "blocked" and "supported", for the goals not yet met
    o = observation(state, goals)[None].astype(np.float64)
    x, y, gx, gy, g = (o[..., j] for j in (0, 1, 3, 4, 5))
    at_goal = g * (np.hypot(gx - x, gy - y) < threshold)
    facts = relations(x, y, gx, gy, g, at_goal)
    pending = g * (1.0 - at_goal)                   # a goal met already needs no drop
    # held up by a block right under it ("supported"), as this test has always been written
    unsupported = pending * (1.0 - facts["supported"])
    return bool((unsupported + pending * facts["blocked"]).max() == 0)
