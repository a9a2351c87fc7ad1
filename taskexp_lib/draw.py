"""taskexp_lib/draw.py -- pictures of the block world: a scene on a matplotlib Axes, an episode as
an animated GIF, a figure as an RGB array (BlockWorld.render)."""
import base64
import io

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle
from matplotlib.ticker import Formatter

from .geometry import BLOCK_H, BLOCK_W, TABLE_X

COLOURS = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink",
           "tab:olive"]


def rgb_array(canvas):
    """What a drawn FigureCanvasAgg shows, as an image (H, W, 3) uint8."""
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


class Metres(Formatter):
    """Tick labels in metres, "0.15 m", with as few decimals as keep them apart: a tall figure
    puts its ticks 0.05 m apart, where one decimal would read "0.1 m, 0.1 m, 0.2 m, 0.2 m"."""

    decimals = 1

    def set_locs(self, locs):
        """Called with the ticks before they are labelled: choose the decimals for them."""
        super().set_locs(locs)
        self.decimals = next((d for d in (1, 2, 3) if len({self.label(v, d) for v in locs})
                              == len(locs)), 3)

    @staticmethod
    def label(v, decimals):
        return f"{round(v, decimals) + 0.0:.{decimals}f} m"     # + 0.0: no "-0.0"

    def __call__(self, v, pos=None):
        return self.label(v, self.decimals)


def draw_scene(ax, state, goals=None, title=None):
    """Draw a state (n, 6) on a matplotlib Axes: the table, blocks with their ids, goals as dashed
    outlines in their block's colour. Fixed limits, so frames of an episode line up; axes in
    metres. Returns ax."""
    n = len(state)
    ax.add_patch(Rectangle((TABLE_X[0], -0.05), TABLE_X[1] - TABLE_X[0], 0.05, color="0.55"))
    for b, (x, y) in (goals or {}).items():
        ax.add_patch(Rectangle((x - BLOCK_W / 2, y - BLOCK_H / 2), BLOCK_W, BLOCK_H, fill=False,
                               ls="--", lw=1.5, ec=COLOURS[b % len(COLOURS)]))
    for b, (x, y, angle) in enumerate(state[:, :3]):
        ax.add_patch(Rectangle((x - BLOCK_W / 2, y - BLOCK_H / 2), BLOCK_W, BLOCK_H, alpha=0.85,
                               angle=np.degrees(angle), rotation_point="center",
                               fc=COLOURS[b % len(COLOURS)], ec="k", lw=0.8))
        ax.text(x, y, str(b), ha="center", va="center", fontsize=8, color="w")
    ax.set_xlim(TABLE_X[0] - 0.05, TABLE_X[1] + 0.05)
    ax.set_ylim(-0.05, n * BLOCK_H + 0.1)
    ax.set_aspect("equal")
    # the unit on every tick (axis labels would run into the titles below in a grid of scenes)
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_formatter(Metres())
    if title:
        ax.set_title(title)
    return ax


def animate(states, goals=None, titles=None, fps=2, dpi=60, html=False):
    """An episode as an animated GIF: one draw_scene frame per state (T, n, 6), the last held 3x.

    goals: one {block: (x, y)} for all frames, or a list with one per frame (None: no goals);
    titles: one per frame (default "step t"). Returns the GIF's bytes, or with html=True an
    <img> tag holding them: a self-contained HTML output for a notebook.
    """
    from PIL import Image  # matplotlib's own dependency; only animations need it
    states = np.asarray(states)
    per_frame = goals if isinstance(goals, (list, tuple)) else [goals] * len(states)
    titles = titles or [f"step {t}" for t in range(len(states))]
    fig = Figure(figsize=(5.0, 2.6), dpi=dpi)
    canvas, frames = FigureCanvasAgg(fig), []
    for state, g, title in zip(states, per_frame, titles):
        fig.clear()
        draw_scene(fig.add_subplot(), state, g, title=title).axis("off")
        fig.subplots_adjust(left=0.01, right=0.99, bottom=0.01, top=0.9)
        frames.append(Image.fromarray(rgb_array(canvas)).quantize(64))
    buf, ms = io.BytesIO(), int(1000 / fps)
    frames[0].save(buf, format="GIF", save_all=True, append_images=frames[1:], loop=0,
                   duration=[ms] * (len(frames) - 1) + [3 * ms])
    gif = buf.getvalue()
    return f'<img src="data:image/gif;base64,{base64.b64encode(gif).decode()}">' if html else gif

