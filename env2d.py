"""env2d.py -- the 2D side-view block world of taskexp (pymunk physics, Gymnasium API).

The world of "Self-Generating Data for Goal-Conditioned Compositional Problems" (Yuan, Li, Wu), sec
5, seen from the side: n_blocks rigid blocks (10 cm x 5 cm, 0.1 kg) on a table one metre wide,
under gravity. One action picks a block up and puts it down somewhere else: the block is teleported
to the centre of an x-bin (37 bins a quarter block apart) in a layer (y-bin, one block height
each), with angle 0 and no velocity, and then physics runs until everything rests. A pose that
overlaps another block makes the action a no-op -- the hand never pushes. A world made with
drop=True takes no layer: the block is let go just above whatever lies under its x, so the
same action lands on the table, on one block or on a tower of five (see drop_height). A block
put in mid air falls; a block put half over an edge may topple; a block that falls off the table
lands on a catch floor half a metre below and stays in the state (its y is negative). A task is
a set of goals {block: (x, y)}; it is solved when every goal block rests within THRESHOLD of its
target. The state is the array (n_blocks, 6) of x, y, angle, vx, vy, w, and the physics is reset
to it at every step (as good as a new pymunk Space, see BlockWorld._load), so a step depends on
(state, action) alone, bit for bit: a saved state replays exactly. The world's geometry is in
taskexp_lib/geometry.py, its pictures in taskexp_lib/draw.py.
"""
import math
from contextlib import nullcontext
from functools import partial

import gymnasium
import numpy as np
import pymunk
import pymunk.batch
from gymnasium import spaces
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from taskexp_lib.draw import draw_scene, rgb_array
from taskexp_lib.geometry import (
    BLOCK_H,
    BLOCK_W,
    N_X,
    SAME_SPOT,
    TABLE_X,
    THRESHOLD,
    X_BINS,
    block_count,
    is_success,
    layer_y,
    max_goal_y,
    nearest_x_bin,
    observation,
    same_spot,
)
from taskexp_lib.rollout import PhysicsPool, Worlds

# Physics. Measured with pymunk 7.3.1: thin segments let blocks tunnel (hence a thick table box);
# a 0.5 mm drop gap avoids the spin of a block born touching another; the default slop is far too
# loose for 5 cm blocks.
DT = 1 / 60
GRAVITY = -9.81
MASS = 0.1
FRICTION = 0.8
SLOP = 0.001                                # allowed penetration (m); resting blocks sink this much
# BIAS: fraction of an overlap left after one second; chipmunk's default (a tenth of it
# corrected per substep): stiffer values rock tall stacks (lab/notes.md, design choices).
BIAS = 0.9 ** 60
DROP_GAP = 0.0005                           # teleport this far above the layer centre
FLOOR_Y = -0.5                              # the catch floor under the table
# Rest: REST_SUBSTEPS consecutive substeps with |v| < REST_V, |w| < REST_W and no point of any
# block further than REST_MOVE from where it was when the quiet run began; at most MAX_SUBSTEPS
# (20 s; see _settle, and lab/bench/bench_settle.py for how far below it actions stay).
REST_V, REST_W, REST_MOVE, REST_SUBSTEPS, MAX_SUBSTEPS = 0.01, 0.05, 0.0005, 10, 1200
CHECK_EVERY = 5                             # read the bodies every 5th substep
# a rotation dtheta moves a corner by <= HALF_DIAG * dtheta
HALF_DIAG = 0.5 * np.hypot(BLOCK_W, BLOCK_H)
# |(dx, dy, dangle, vx, vy, w)| @ REST_CRITERIA: the three rest measures, each over its threshold
REST_CRITERIA = np.array([[1, 0, 0], [1, 0, 0], [HALF_DIAG, 0, 0], [0, 1, 0], [0, 1, 0], [0, 0, 1]]
                         ) / np.array([REST_MOVE, REST_V, REST_W])
OVERLAP_TOL = SLOP                          # penetration tolerated when testing a teleport pose
# pymunk's Space.step wraps chipmunk's cpSpaceStep with bookkeeping for callbacks and deferred
# adds/removes, which we do not use; that costs a fifth of a substep, so _settle calls chipmunk
# directly.
# Likewise _load and _refresh call chipmunk's functions, where pymunk's wrappers would cost more
# than what they wrap.
_lib, _ffi = pymunk._chipmunk_cffi.lib, pymunk._chipmunk_cffi.ffi
_space_step = _lib.cpSpaceStep
_update_position, _remove_shape, _add_shape = (_lib.cpBodyUpdatePosition, _lib.cpSpaceRemoveShape,
                                               _lib.cpSpaceAddShape)
_set_shape_id_counter, _set_current_time_step = (_lib.cpSpaceSetShapeIDCounter,
                                                 _lib.cpSpaceSetCurrentTimeStep)
_each_body = _lib.cpSpaceEachBody
_get_body_rows = _ffi.addressof(_lib, "pmSpaceBodyGetIteratorFuncBatched")   # pymunk's batch read


def overlap_depth(pose, others):
    """Penetration depth (m,) of an upright block at pose (x, y) into blocks `others` (m, >=3):
    x, y, angle.

    Separating axis test for two rectangles: along an axis n their projections overlap by
    r_A(n) + r_B(n) - |d . n| (d the offset of the centres, r(n) = W/2 |u . n| + H/2 |v . n| for a
    block with axes u, v); the depth is the least overlap over the four edge normals x, y, u, v.
    <= 0 means apart or touching. (A plain loop: 4x faster than numpy for a handful of blocks.)
    """
    hw, hh = BLOCK_W / 2, BLOCK_H / 2
    depth = []
    for x, y, angle in np.asarray(others, dtype=float)[:, :3].tolist():
        dx, dy, cos, sin = x - pose[0], y - pose[1], math.cos(angle), math.sin(angle)
        r_x = hw * abs(cos) + hh * abs(sin)              # r_B(x) = r_A(u)
        r_y = hw * abs(sin) + hh * abs(cos)              # r_B(y) = r_A(v)
        depth.append(min(hw + r_x - abs(dx), hh + r_y - abs(dy),
                         hw + r_x - abs(dx * cos + dy * sin), hh + r_y - abs(dy * cos - dx * sin)))
    return np.array(depth)


def drop_height(x, others):
    """Where a block let go at x comes to lie, before physics: its centre just above the highest
    of the blocks `others` (m, >=3: x, y, angle) that it would hit falling straight down, or on
    the table. A block's reach is its bounding box, r = W/2 |cos| + H/2 |sin| across and
    W/2 |sin| + H/2 |cos| up; blocks that fell off the table lie below it and never count."""
    top = 0.0
    for bx, by, angle in np.asarray(others, dtype=float)[:, :3].tolist():
        cos, sin = abs(math.cos(angle)), abs(math.sin(angle))
        if abs(bx - x) < BLOCK_W / 2 + BLOCK_W / 2 * cos + BLOCK_H / 2 * sin - 1e-9:
            top = max(top, by + BLOCK_W / 2 * sin + BLOCK_H / 2 * cos)
    return top + BLOCK_H / 2


class BlockWorld(gymnasium.Env):
    """The block world as a Gymnasium environment (see the module docstring).

    action (block, x-bin, y-bin) in MultiDiscrete([n_blocks, N_X, n_blocks]): the block is put
    down at that x in that layer ("place"). With drop=True the action space is
    MultiDiscrete([n_blocks, N_X, 1]): the block is let go just above whatever lies under that x
    (the table, or the top of a stack) and physics finds its height ("drop"), so one skill,
    "drop a block on its goal x", serves every height.
    observation (n_blocks, 6) float32, see observation(); reward 1.0 on success (then terminated).
    """
    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(self, n_blocks=6, max_steps=10, render_mode=None, drop=False):
        n_blocks = block_count(n_blocks)                      # 2..MAX_BLOCKS: the table
        if not (isinstance(max_steps, (int, np.integer)) and not isinstance(max_steps, bool)
                and max_steps >= 1):
            raise ValueError(f"max_steps={max_steps!r}: need an int >= 1 (actions per episode)")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode={render_mode!r}: only None or 'rgb_array'")
        if not isinstance(drop, bool):
            raise ValueError(f"drop={drop!r}: need True (drop at an x) or False (place in a layer)")
        self.n_blocks, self.max_steps, self.render_mode = n_blocks, int(max_steps), render_mode
        self.drop = drop
        self.table_x, self.threshold = TABLE_X, THRESHOLD
        self.x_bins = X_BINS.copy()
        self.y_bins = layer_y(np.arange(self.n_blocks))          # the layers: where goals lie
        self.action_space = spaces.MultiDiscrete([self.n_blocks, N_X, 1 if drop else self.n_blocks])
        # Columns x, y, angle, goal_x, goal_y, has_goal. A block that falls off the table lands on
        # the catch floor (10 m wide); none can be higher than max_goal_y; "no goal" is all zeros.
        top = max_goal_y(self.n_blocks)
        low = np.array([-5.0, FLOOR_Y, -np.pi, TABLE_X[0], 0.0, 0.0], np.float32)
        high = np.array([5.0, top, np.pi, TABLE_X[1], top, 1.0], np.float32)
        self.observation_space = spaces.Box(np.tile(low, (self.n_blocks, 1)),
                                            np.tile(high, (self.n_blocks, 1)), dtype=np.float32)
        # Bodies, shapes and the Space are made once; _load resets at every step what the Space
        # remembers of earlier steps, so that results depend on the state only.
        self._table = pymunk.Body(body_type=pymunk.Body.STATIC)
        (left, right), bottom = TABLE_X, FLOOR_Y - 0.1
        # the table top is 5 cm thick: thin segments let blocks tunnel
        top = pymunk.Poly(self._table, [(left, -0.05), (right, -0.05), (right, 0), (left, 0)])
        floor = pymunk.Poly(self._table, [(-5, bottom), (5, bottom), (5, FLOOR_Y), (-5, FLOOR_Y)])
        self._bodies = [pymunk.Body(MASS, pymunk.moment_for_box(MASS, (BLOCK_W, BLOCK_H)))
                        for _ in range(self.n_blocks)]
        boxes = [pymunk.Poly.create_box(b, (BLOCK_W, BLOCK_H)) for b in self._bodies]
        shapes = [top, floor] + boxes
        for shape in shapes:
            shape.friction, shape.elasticity = FRICTION, 0.0
        self._everything, self._blocks = [self._table, *self._bodies, *shapes], shapes[2:]
        self._space = self._new_space()
        # For setting them: a buffer wrapping self._rows (n + 1, 6), the last row the table's.
        # It is never read into (a read could reallocate numpy's memory).
        self._rows, self._setter = np.zeros((self.n_blocks + 1, 6)), pymunk.batch.Buffer()
        self._setter.set_float_buf(self._rows)
        self._fields = (pymunk.batch.BodyFields.POSITION | pymunk.batch.BodyFields.ANGLE
                        | pymunk.batch.BodyFields.VELOCITY
                        | pymunk.batch.BodyFields.ANGULAR_VELOCITY)
        # For reading them: pymunk appends the rows to a C array that it grows as needed. After a
        # first read has grown it, every read refills the same memory, which self._now views
        # (n, 6): a read in _settle is then one C call (a fifth of pymunk.batch.get_space_bodies
        # and a numpy copy), its arguments made here once.
        self._buffer = pymunk.batch.Buffer()
        pymunk.batch.get_space_bodies(self._space, self._fields, self._buffer)
        self._now = np.frombuffer(self._buffer.float_buf(), np.float64)[: 6 * self.n_blocks]
        self._now = self._now.reshape(self.n_blocks, 6)
        self._rows_read = self._buffer._float_arr           # its .num: how many floats were read
        self._now_address = self._rows_read.arr
        self._batch = _ffi.new("pmBatchedData *", {"fields": self._fields.value,
                                                   "floatArray": self._rows_read,
                                                   "intArray": self._buffer._int_arr})
        self._state, self._goals = np.zeros((self.n_blocks, 6)), {}
        self._steps, self._stable, self._started = 0, True, False

    # -- state, goals, actions ------------------------------------------------------------------

    def get_state(self):
        """A copy of the state (n_blocks, 6) float64: x, y, angle, vx, vy, w."""
        return self._state.copy()

    @property
    def goals(self):
        """A copy of the goals {block: (x, y)}."""
        return dict(self._goals)

    def encode_action(self, block, x, y):
        """The action (3,) int64 whose bins are nearest to (x, y) for this block (when dropping,
        y is not part of the action: physics finds it)."""
        if not 0 <= int(block) < self.n_blocks or int(block) != block:
            raise ValueError(f"block {block!r} not in 0..{self.n_blocks - 1}")
        if not (np.isfinite(x) and np.isfinite(y)):
            raise ValueError(f"position ({x!r}, {y!r}) not finite")
        iy = np.abs(self.y_bins - y).argmin()
        return np.array([block, nearest_x_bin(x), 0 if self.drop else iy], np.int64)

    def decode_action(self, action):
        """(block, x, y) of an action (3,): the block id and the centre it is teleported to;
        y is None when dropping (it depends on what lies under x)."""
        b, ix, iy = self._check_action(action)
        return b, float(self.x_bins[ix]), None if self.drop else float(self.y_bins[iy])

    def _check_action(self, action):
        a = np.asarray(action)
        nvec = self.action_space.nvec
        if a.shape != (3,) or a.dtype.kind not in "iu" or not ((a >= 0) & (a < nvec)).all():
            raise ValueError(f"action {action!r} not 3 ints in MultiDiscrete({nvec.tolist()})")
        return int(a[0]), int(a[1]), int(a[2])

    def _check_goals(self, goals):
        if not isinstance(goals, dict) or not 1 <= len(goals) <= self.n_blocks:
            raise ValueError(f"goals {goals!r}: need a dict {{block: (x, y)}} "
                             f"of 1..{self.n_blocks} goals")
        checked = {}
        for b, xy in goals.items():
            if not isinstance(b, (int, np.integer)) or not 0 <= b < self.n_blocks:
                raise ValueError(f"goal for block {b!r}: no such block (0..{self.n_blocks - 1})")
            try:
                x, y = (float(v) for v in xy)
            except (TypeError, ValueError):
                raise ValueError(f"goal {xy!r} of block {b}: need two numbers (x, y)") from None
            if not (np.isfinite(x) and TABLE_X[0] <= x <= TABLE_X[1]):
                raise ValueError(f"goal {xy!r} of block {b}: x off the table {TABLE_X}")
            if not (np.isfinite(y) and y >= BLOCK_H / 2 - THRESHOLD):
                raise ValueError(f"goal {xy!r} of block {b}: y below the table top")
            top = max_goal_y(self.n_blocks)
            if y > top:
                raise ValueError(f"goal {xy!r} of block {b}: y above {top:.3f} m, higher than "
                                 f"{self.n_blocks} blocks stacked on end can reach")
            checked[int(b)] = (float(x), float(y))
        pair = same_spot(checked)
        if pair:
            raise ValueError(f"goals {goals!r}: blocks {pair[0]} and {pair[1]} have goals less "
                             f"than {SAME_SPOT * 100:.0f} cm apart, which two blocks can never "
                             "both meet")
        return checked

    # -- Gymnasium API --------------------------------------------------------------------------

    def reset(self, seed=None, options=None):
        """Start an episode. options: "state" (n_blocks, 6) to start from, "goals" {block: (x, y)}.

        Without a state the blocks are scattered on the table, keeping goal footprints free; without
        goals one random block gets a goal on a free table spot. Returns (obs (n, 6), info).
        """
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - {"state", "goals"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)}: only 'state' and 'goals'")
        goals = self._check_goals(options["goals"]) if "goals" in options else None
        if "state" in options:
            state = np.array(options["state"], dtype=np.float64)
            if state.shape != (self.n_blocks, 6) or not np.isfinite(state).all():
                raise ValueError(f"state of shape {state.shape} (need ({self.n_blocks}, 6), "
                                 f"finite): {options['state']!r}")
            low, high = self.observation_space.low[0, :3], self.observation_space.high[0, :3]
            outside = ~((state[:, :3] >= low) & (state[:, :3] <= high)).all(1)
            if outside.any():
                raise ValueError(f"state: block {np.flatnonzero(outside)[0]} lies outside the "
                                 f"world (x, y, angle within {low.tolist()} and {high.tolist()})")
            if goals is None:
                goals = self._random_goal(state)
        else:
            if goals is None:
                goals = {int(self.np_random.integers(self.n_blocks)):
                         (float(self.np_random.choice(self.x_bins)), float(self.y_bins[0]))}
            state = np.zeros((self.n_blocks, 6))
            state[:, 0], state[:, 1] = self._scatter(goals), BLOCK_H / 2
        self._state, self._goals, self._steps, self._started = state, goals, 0, True
        # (|vx| + |vy|) / REST_V and |w| / REST_W: a state given at rest counts as stable
        speeds = np.abs(state[:, 3:]) @ REST_CRITERIA[3:, 1:]
        self._stable = bool(speeds.max() < 1.0)
        return observation(self._state, self._goals), {"success": is_success(state, goals)}

    def step(self, action):
        """Teleport, then settle. Returns (obs (n, 6), reward, terminated, truncated, info).

        info: "noop" (the pose overlapped a block: nothing moved), "stable" (came to rest; after a
        no-op, as before), "success" (= terminated), "settle_steps" (substeps simulated, 0 for a
        no-op).
        """
        if not self._started:
            raise gymnasium.error.ResetNeeded("call reset() before step(): there is no scene yet")
        return self.finish_step(self.simulate(self._state, action))

    def simulate(self, state, action):
        """The physics of one action from `state` (n, 6): teleport, then settle.

        -> (state after, noop, stable, substeps); stable is None after a no-op. A pure function
        of (state, action), bit for bit, whichever world runs it: so worker processes can run it
        for the worlds of the main process (rollout.PhysicsPool), which then finish_step.
        """
        b, ix, iy = self._check_action(action)
        others = state[np.arange(self.n_blocks) != b, :3]
        x = self.x_bins[ix]
        if self.drop:              # let go above all it would hit falling: it overlaps nothing
            pose = (x, drop_height(x, others) + DROP_GAP)
        else:
            pose = (x, self.y_bins[iy] + DROP_GAP)
            if (overlap_depth(pose, others) > OVERLAP_TOL).any():
                return state, True, None, 0
        start = state.copy()
        start[b] = (*pose, 0.0, 0.0, 0.0, 0.0)
        self._load(start)
        substeps, stable, after = self._settle(start)
        angle = after[:, 2]                    # keep it in [-pi, pi] (a tumbled block may pass pi)
        wrapped = (angle + np.pi) % (2 * np.pi) - np.pi
        after[:, 2] = np.where(np.abs(angle) > np.pi, wrapped, angle)
        return after, False, stable, substeps

    def finish_step(self, outcome):
        """The rest of step() once simulate() has run: count the step, judge success and
        truncation. outcome: what simulate returned for this world's state."""
        after, noop, stable, substeps = outcome
        if not noop:
            self._state, self._stable = after, stable
        self._steps += 1
        success = is_success(self._state, self._goals) and self._stable
        truncated = self._steps >= self.max_steps and not success
        info = {"noop": noop, "stable": self._stable, "success": success, "settle_steps": substeps}
        return observation(self._state, self._goals), float(success), success, truncated, info

    def render(self):
        """The scene as an image (H, W, 3) uint8 when render_mode == "rgb_array", else None."""
        if self.render_mode != "rgb_array":
            return None
        fig = Figure(figsize=(6.4, 3.2), dpi=100)
        canvas = FigureCanvasAgg(fig)
        draw_scene(fig.add_subplot(), self._state, self._goals, title=f"step {self._steps}")
        return rgb_array(canvas)

    # -- scattering and goals -------------------------------------------------------------------

    def _scatter(self, goals):
        """x (n,) of blocks scattered on the table without overlaps, off the goals' footprints.

        The table minus the footprints is a set of free segments; n of the segments' block-sized
        slots are drawn at random, and within a segment holding k blocks the free length is split
        by k sorted uniform draws (stars and bars), so blocks never overlap. If the footprints
        leave too little room only the ground-layer goals are kept free, then none.
        """
        targets = list(goals.values())
        for keep in (targets, [g for g in targets if g[1] < BLOCK_H], []):
            segments = _free_segments([x for x, _ in keep])
            room = [int(np.floor((hi - lo) / BLOCK_W + 1e-9)) for lo, hi in segments]
            if sum(room) >= self.n_blocks:
                break
        owner = np.repeat(np.arange(len(segments)), room)
        counts = np.bincount(owner[self.np_random.choice(len(owner), self.n_blocks, replace=False)],
                             minlength=len(segments))
        xs = []
        for (lo, hi), k in zip(segments, counts):
            slack = max(hi - lo - k * BLOCK_W, 0.0)
            gaps = np.sort(self.np_random.uniform(0, slack, k))
            xs.extend(lo + gaps + BLOCK_W * (np.arange(k) + 0.5))
        return self.np_random.permutation(np.array(xs))

    def _random_goal(self, state):
        """One goal {block: (x, y_0)} on a table spot no block overlaps (any spot if none is
        free)."""
        free = [x for x in self.x_bins
                if not (overlap_depth((x, self.y_bins[0]), state) > OVERLAP_TOL).any()]
        b = int(self.np_random.integers(self.n_blocks))
        return {b: (float(self.np_random.choice(free or self.x_bins)), float(self.y_bins[0]))}

    # -- physics --------------------------------------------------------------------------------

    def _new_space(self):
        """A fresh Space holding the table and the blocks; _load keeps it as good as fresh."""
        space = pymunk.Space()
        space.gravity, space.collision_slop, space.collision_bias = (0.0, GRAVITY), SLOP, BIAS
        space.add(*self._everything)       # ids: table top 0, floor 1, blocks 2, 3, ... in order
        self._loads = 0                    # see _load
        return space

    def _load(self, state):
        """Pose the blocks as in state (n, 6) in a Space that is, for chipmunk, as good as fresh.

        What a chipmunk space remembers from one substep to the next, beyond the bodies: the
        contacts with their impulses (warm starting), the tree of shapes with its cached pairs, the
        shape ids, and the last time step. Taking the blocks' shapes out deletes every contact and
        pair (each involves a block: static shapes never collide) and empties the tree; putting them
        back in the same order with the same ids, after the last step is reset to 0, rebuilds the
        same tree a fresh space would: a step gives, bit for bit, what it gives in a fresh space
        (checked side by side on 100,000 actions), for 4 us where building a new Space took 30.
        The bodies' bias velocities (penetration correction) are zeroed by an update with dt = 0.
        The tree orders its pairs by 32-bit stamps that grow by one per substep and per insert,
        which would wrap after 2**32: a new Space every million loads (each <= 1208 stamps).
        """
        if self._loads == 10**6:
            self._space.remove(*self._everything)
            self._space = self._new_space()
        self._loads += 1
        space = self._space._space
        for shape in self._blocks:
            _remove_shape(space, shape._shape)
        for body in self._bodies:
            _update_position(body._body, 0.0)
        # all bodies in one call: dynamic ones in insertion order, then the table at (0, 0, 0)
        self._rows[:-1] = state
        pymunk.batch.set_space_bodies(self._space, self._fields, self._setter)
        _set_shape_id_counter(space, 2)
        _set_current_time_step(space, 0.0)
        for shape in self._blocks:
            _add_shape(space, shape._shape)

    def _read(self):
        """All blocks at once (n, 6): x, y, angle, vx, vy, w (dynamic bodies in insertion order)."""
        self._refresh()
        return self._now.copy()

    def _refresh(self):
        """Read all bodies into self._now (see __init__)."""
        self._rows_read.num = 0
        _each_body(self._space._space, _get_body_rows, self._batch)
        if self._rows_read.arr != self._now_address:   # pymunk moved its array: never for a
            raise RuntimeError("pymunk reallocated the read buffer")      # read of the same size

    def _settle(self, start):
        """Step until rest or MAX_SUBSTEPS. Returns (substeps, at rest, final state (n, 6)).

        Bodies are read every CHECK_EVERY substeps. A read is quiet when, for every block,
            (|dx| + |dy| + HALF_DIAG |dangle|) / REST_MOVE < 1   (no point moved REST_MOVE since
                                                                  the anchor)
            (|vx| + |vy|) / REST_V < 1  and  |w| / REST_W < 1
        (L1 norms: a little stricter than the euclidean ones), where the anchor is the last read
        that was not quiet. Rest = quiet reads for REST_SUBSTEPS substeps after the anchor.
        A read and its test cost about a substep: hence the in-place read, ndarray.dot (a third
        of the cost of the @ operator for so small arrays, the same numbers) and Python's max
        over a list (half the cost of numpy's max for 3 n numbers).
        """
        space, now = self._space._space, self._now
        anchor, quiet = start.copy(), 0      # start (n, 6): the state just loaded
        anchor[:, 3:] = 0.0                  # so |now - anchor| holds pose changes and speeds
        for k in range(CHECK_EVERY, MAX_SUBSTEPS + 1, CHECK_EVERY):
            for _ in range(CHECK_EVERY):
                _space_step(space, DT)
            self._refresh()
            if max(np.abs(now - anchor).dot(REST_CRITERIA).ravel().tolist()) >= 1.0:
                anchor[:, :3], quiet = now[:, :3], 0
            else:
                quiet += CHECK_EVERY
                if quiet >= REST_SUBSTEPS:
                    return k, True, now.copy()
        return MAX_SUBSTEPS, False, now.copy()


def _free_segments(goal_xs):
    """Free stretches [(lo, hi), ...] of the table without the footprints of goals at goal_xs."""
    segments, lo = [], TABLE_X[0]
    for x in sorted(goal_xs):
        if x - BLOCK_W / 2 > lo:
            segments.append((lo, min(x - BLOCK_W / 2, TABLE_X[1])))
        lo = max(lo, x + BLOCK_W / 2)
    if lo < TABLE_X[1]:
        segments.append((lo, TABLE_X[1]))
    return segments


# `gymnasium.make("taskexp/BlockWorld-v0")` builds the world every run of the method uses, the one
# that drops (keywords pass through: n_blocks=7, or drop=False for the world that places).
gymnasium.register(id="taskexp/BlockWorld-v0", entry_point=BlockWorld, kwargs=dict(drop=True))


# ---- the worlds of a run: many at once, their physics in worker processes (rollout.py) ----

def physics_pool(workers, drop=False):
    """A PhysicsPool of BlockWorlds (of any number of blocks) for workers > 1; with one, the main
    process steps the worlds itself."""
    make_world = partial(BlockWorld, drop=drop)       # picklable, for "spawn"
    return PhysicsPool(workers, make_world) if workers > 1 else nullcontext()


def run_worlds(cfg, pool=None):
    """The worlds of a run with settings cfg -> (envs, short_envs): cfg.n_envs each, episodes of
    cfg.max_steps actions, and of cfg.short_steps for verification, labels and stretch tasks."""
    worlds = lambda steps: Worlds([BlockWorld(cfg.n_blocks, max_steps=steps,
                                              drop=cfg.action == "drop")
                                   for _ in range(cfg.n_envs)], pool)
    return worlds(cfg.max_steps), worlds(cfg.short_steps)
