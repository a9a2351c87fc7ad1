"""taskexp_cli/try_structure.py -- a trained agent builds a structure that a person writes,
zero-shot, in a world of any number of blocks: its success over fixed scenes, one attempt drawn.

    python -m taskexp_cli try runs/ours-seed0/round3.npz "0,0 0,1 1.5,0 1.5,1 0.75,2"
    python -m taskexp_cli try runs/ours-seed0/round3.npz 3T --blocks 7 --gif

The structure is written as cells "dx,layer" (read_structure) or named (I, Y, 3T). Each scene
places it at a random spot of the table, with random blocks for its cells, among the others
scattered as the evaluation scatters them (shapes.start_state). A scripted builder that clears the
site first (scripted_build) says whether the scenes can be built at all.
"""
import os
import warnings
from typing import NamedTuple

import numpy as np
from matplotlib.figure import Figure

from agent import Agent, OtherWorldWarning
from env2d import BlockWorld
from taskexp_lib import one_blas_thread
from taskexp_lib.config import Config
from taskexp_lib.draw import animate, draw_scene
from taskexp_lib.geometry import BLOCK_W, MAX_BLOCKS, X_BINS, block_count, is_success
from taskexp_lib.rollout import Trajectory, run_episodes
from taskexp_lib.shapes import SHAPES, blocks_needed, site_free, supports, tasks_of

from . import Parser  # a refusal is one line

# A structure a person writes: cells like shapes.SHAPES' as text, "dx,layer" each, separated by
# spaces, e.g. "0,0 0,1 1.5,0 1.5,1 0.75,2" (two towers and a block across). dx is in block widths
# from the structure's centre, on the action grid (a multiple of GRID); layer 0 rests on the
# table. A goal may be in the air: blocks that no goal names must go under it.
GRID = (X_BINS[1] - X_BINS[0]) / BLOCK_W            # 0.25: the x grid's spacing in block widths
SPAN = (X_BINS[-1] - X_BINS[0]) / BLOCK_W           # 9: the widest a structure's centres may lie
WRITE = 'write cells as dx,layer separated by spaces, e.g. "0,0 0,1 0,2"'


def read_structure(text, n_blocks=MAX_BLOCKS):
    """The cells [(dx, layer)] of a structure written as text (or a name in SHAPES) that a world
    of n_blocks can hold; anything else is a ValueError whose message is one line."""
    if text.strip() in SHAPES:
        cells = SHAPES[text.strip()]
    else:
        cells = [read_cell(word) for word in text.replace(";", " ").split()]
    if not cells:
        raise ValueError(f"no cells: {WRITE}")
    for i, (dx, k) in enumerate(cells):
        for dx2, k2 in cells[i + 1:]:
            if k == k2 and abs(dx - dx2) < 1:
                raise ValueError(f"cells {dx:g},{k} and {dx2:g},{k2} overlap: blocks in one layer "
                                 "lie at least 1 (a block width) apart")
    width = max(dx for dx, _ in cells) - min(dx for dx, _ in cells)
    if width > SPAN + 1e-9:
        raise ValueError(f"the cells lie {width:g} block widths apart; the action grid spans "
                         f"{SPAN:g}")
    need = blocks_needed(cells)
    if need > n_blocks:
        raise ValueError(f"the structure needs {need} blocks ({len(cells)} with goals, "
                         f"{need - len(cells)} under goals in the air); the world has {n_blocks}")
    return cells


def read_cell(word):
    """(dx, layer) of one cell written "dx,layer"; a one-line ValueError otherwise."""
    try:
        dx, k = (float(v) for v in word.split(","))
    except ValueError:
        raise ValueError(f"cell {word!r}: {WRITE}") from None
    if not np.isfinite([dx, k]).all():
        raise ValueError(f"cell {word!r}: dx and the layer must be finite numbers")
    if not abs(dx / GRID - round(dx / GRID)) < 1e-9:
        raise ValueError(f"cell {word!r}: dx must be a multiple of {GRID:g} (the action grid)")
    if not (k == int(k) and k >= 0):
        raise ValueError(f"cell {word!r}: the layer must be a whole number >= 0 (0: the table)")
    return dx, int(k)


def scripted_build(env, state, goals):
    """A scripted builder, to tell whether a scene can be built at all (here, and in the tests of
    the families): clear every block off the columns the goals and their supports need,
    then fill those spots bottom-up, goal blocks at their goals and blocks that no goal names at
    the supports. env: a world that drops (BlockWorld(drop=True)) with room for the moves.
    Returns True when the goals hold."""
    spots = [(xy, b) for b, xy in goals.items()] + [(xy, None) for xy in supports(goals)]
    columns = [x for (x, _), _ in spots]
    env.reset(options={"state": state, "goals": goals})

    def drop(b, x):
        env.step(env.encode_action(b, x, env.y_bins[0]))

    def apart(x, others):                                  # no overlap, touching allowed
        return all(abs(x - o) > BLOCK_W - 1e-6 for o in others)

    away = [x for x in env.x_bins if apart(x, columns)]
    if not away:
        return False
    for b in [b for b in np.argsort(-state[:, 1]) if not apart(state[b, 0], columns)]:
        others = np.delete(env.get_state(), b, axis=0)[:, 0]      # the highest in the way first
        on_table = [x for x in away if apart(x, others)]        # else onto a block out of the way
        drop(int(b), (on_table or away)[0])
    spare = sorted(set(range(env.n_blocks)) - set(goals))         # for the supports
    for (x, y), b in sorted(spots, key=lambda spot: spot[0][1]):
        if b is None:
            if not spare:
                return False
            b = spare.pop()
        drop(b, x)
    return is_success(env.get_state(), goals, env.threshold)


class Tried(NamedTuple):
    """What try_structure measured: the cells, one episode per scene (Trajectory, in order), and
    per scene whether its site was free at the start and whether a scripted builder built it."""
    cells: list
    episodes: list
    free: list
    scripted: list

    def rate(self, which=None):
        """Success over all scenes, or over the scenes where which[i] is True (None if none)."""
        won = [t.success for i, t in enumerate(self.episodes) if which is None or which[i]]
        return float(np.mean(won)) if won else None


def try_structure(agent, structure, n_blocks=None, scenes=50, seed=0, max_steps=Config.max_steps):
    """The greedy policy of `agent` on `scenes` fixed scenes of a structure (text or a name of
    SHAPES) in a world of n_blocks (default: the one it learnt in) -> Tried. The scenes come from
    a Generator seeded with `seed`. ValueError (one line): what no world of n_blocks can build."""
    n_blocks = block_count(agent.n_blocks if n_blocks is None else n_blocks, name="blocks")
    if not scenes >= 1:
        raise ValueError(f"scenes: at least 1, got {scenes!r}")
    cells = read_structure(structure, n_blocks)
    rng = np.random.default_rng(seed)
    worlds = [BlockWorld(n_blocks, max_steps=max_steps, drop=agent.drops) for _ in range(16)]
    tasks = tasks_of(cells, worlds[0], rng, scenes, name="the structure")
    with warnings.catch_warnings():            # another world, asked for: main() says so
        warnings.simplefilter("ignore", OtherWorldWarning)
        episodes = run_episodes(agent, tasks, worlds, deterministic=True, values=False)
    builder = BlockWorld(n_blocks, max_steps=4 * n_blocks, drop=True)
    return Tried(cells, episodes, [site_free(s0, goals) for s0, goals in tasks],
                 [scripted_build(builder, s0, goals) for s0, goals in tasks])


def frame_titles(episode):
    """A title per state of an episode: the start, each action, and how it ended."""
    moved = [f"step {t + 1}: block {b}" for t, (b, _, _) in enumerate(episode.actions)]
    end = "built" if episode.success else "not built"
    return ["start, goals dashed", *moved[:-1], f"{moved[-1]}: {end}" if moved else end]


def attempt_figure(episode: Trajectory, columns=4):
    """One attempt, step by step: the start with the goals dashed, then the scene after each
    action, the last titled with how it ended. A matplotlib Figure (no display needed)."""
    titles, n = frame_titles(episode), len(episode.states)
    rows = -(-n // columns)
    fig = Figure(figsize=(3.2 * min(n, columns), 2.2 * rows))
    for i, (state, title) in enumerate(zip(episode.states, titles)):
        draw_scene(fig.add_subplot(rows, min(n, columns), i + 1), state, episode.goals, title)
        fig.axes[-1].tick_params(labelsize=6)
    fig.tight_layout()
    return fig


def summary(tried):
    """What a person reads: success, how often the site was free, and what a scripted builder
    that clears the site first achieved on the same scenes."""
    scenes, free, scripted = len(tried.episodes), sum(tried.free), sum(tried.scripted)
    won, n_blocks = sum(t.success for t in tried.episodes), len(tried.episodes[0].states[0])
    on_free = tried.rate(tried.free)
    why = ("so it stands, and the scenes leave room to build it" if scripted == scenes else
           "where it does not, the structure falls or the table leaves no room")
    return "\n".join([
        f"built in {won} of {scenes} scenes ({won / scenes:.0%}) of {n_blocks} blocks",
        f"the site was free at the start in {free} of {scenes}"
        + (f"; built in {on_free:.0%} of those" if free else ""),
        f"a scripted builder that first clears the site builds it in {scripted} of {scenes} "
        f"({why})"])


def parser():
    p = Parser(prog="python -m taskexp_cli try",
               description="A trained agent builds a structure you write, zero-shot, in a world "
                           "of any number of blocks.",
               epilog="structure: cells dx,layer separated by spaces (dx in block widths from "
                      "the centre, a multiple of 0.25; layer 0 on the table), or I, Y or 3T")
    p.add_argument("checkpoint", help="an agent checkpoint, e.g. runs/ours-seed0/round3.npz")
    p.add_argument("structure", help='e.g. "0,0 0,1 1.5,0 1.5,1 0.75,2" (an arch), or 3T')
    p.add_argument("--blocks", type=int, default=None,
                   help=f"blocks in the world, 2..{MAX_BLOCKS} (default: the checkpoint's)")
    p.add_argument("--scenes", type=int, default=50, help="fixed scenes to try (default 50)")
    p.add_argument("--seed", type=int, default=0, help="seeds the scenes (default 0)")
    p.add_argument("--steps", type=int, default=Config.max_steps,
                   help=f"actions per scene (default {Config.max_steps})")
    p.add_argument("--scene", type=int, default=0, help="the scene drawn (default 0, the first)")
    p.add_argument("--out", default="tried.png", help="the drawing (default tried.png)")
    p.add_argument("--gif", action="store_true", help="also an animated GIF next to it")
    return p


def main(argv=None):
    p = parser()
    a = p.parse_args(argv)
    for name, low in (("scenes", 1), ("steps", 1), ("seed", 0)):
        if getattr(a, name) < low:
            p.error(f"--{name} must be >= {low}, got {getattr(a, name)}")
    if not 0 <= a.scene < a.scenes:
        p.error(f"--scene must be in 0..{a.scenes - 1}, got {a.scene}")
    folder, kind = os.path.dirname(os.path.abspath(a.out)), os.path.splitext(a.out)[1][1:].lower()
    if not os.path.isdir(folder):
        p.error(f"--out {a.out}: no folder {folder} to draw in")
    if kind not in Figure().canvas.get_supported_filetypes():
        p.error(f"--out {a.out}: name a picture, e.g. tried.png")
    try:                                             # every argument checked before a word
        agent = Agent.load(a.checkpoint)
        n = block_count(agent.n_blocks if a.blocks is None else a.blocks, name="--blocks")
        read_structure(a.structure, n)
    except ValueError as e:
        p.error(str(e).splitlines()[0])
    print(f"{a.checkpoint}: learnt in a world of {agent.n_blocks} blocks, tried in one of {n}"
          + (" (the same weights)" if n != agent.n_blocks else ""))
    with one_blas_thread():
        tried = try_structure(agent, a.structure, n, a.scenes, a.seed, a.steps)
    print(summary(tried))
    episode = tried.episodes[a.scene]
    attempt_figure(episode).savefig(a.out, dpi=100)
    print(f"drew scene {a.scene} ({'built' if episode.success else 'not built'}, "
          f"{len(episode.actions)} actions): {a.out}")
    if a.gif:
        gif = os.path.splitext(a.out)[0] + ".gif"
        with open(gif, "wb") as f:
            f.write(animate(episode.states, episode.goals, frame_titles(episode), fps=1.5,
                            dpi=80))
        print("and", gif)
