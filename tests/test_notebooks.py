"""The notebooks under notebooks/ run top to bottom in quick mode, and draw.animate works.

Each notebook is executed in memory with nbclient (kernel "python3", working directory notebooks/,
TASKEXP_QUICK=1), so nothing is written into the repository: quick mode keeps its runs in
temporary directories. A cell that raises fails the test.
"""
import glob
import io
import os
import re

import nbformat
import numpy as np
import pytest
from nbclient import NotebookClient
from PIL import Image

from env2d import BlockWorld
from taskexp_lib.draw import animate, draw_scene
from taskexp_lib.geometry import BLOCK_H, X_BINS

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NOTEBOOKS = sorted(glob.glob(os.path.join(ROOT, "notebooks", "*.ipynb")))


def test_the_five_notebooks_are_there():
    names = [os.path.basename(p) for p in NOTEBOOKS]
    assert [n[:2] for n in names] == ["01", "02", "03", "04", "05"], names


@pytest.mark.parametrize("path", NOTEBOOKS, ids=os.path.basename)
def test_notebook_is_small_and_has_the_quick_switch(path):
    assert os.path.getsize(path) < 3 * 2**20, "a committed notebook must stay under 3 MB"
    nb = nbformat.read(path, as_version=4)
    assert "TASKEXP_QUICK" in nb.cells[1].source, "the first code cell holds the quick switch"
    first = nb.cells[0].source
    assert ("PROVENANCE" not in first and "How these outputs were made" in first
            and "jupyter execute" in first), \
        "the first cell must say which command made its outputs and how long it took"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=os.path.basename)
def test_notebook_figures_are_sharp_and_saved_progress_bars_show_their_end(path):
    nb = nbformat.read(path, as_version=4)
    dpi = re.search(r'"figure.dpi": (\d+)', nb.cells[1].source)
    assert dpi and int(dpi.group(1)) >= 100, "figures at 100 dpi or more"
    widgets = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs
               if "application/vnd.jupyter.widget-view+json" in o.get("data", {})]
    assert not widgets, "a saved progress widget reads 0% outside Jupyter: use text bars"
    overwritten = [c.source[:40] for c in nb.cells if c.cell_type == "code" for o in c.outputs
                   if o.output_type == "stream" and "\r" in o.text]
    assert not overwritten, ("a saved text bar keeps every update (0% first) in viewers without "
                             "a terminal: jupyter nbconvert --to notebook --coalesce-streams "
                             f"--inplace {os.path.relpath(path, ROOT)}; cells {overwritten}")


@pytest.mark.parametrize("path", NOTEBOOKS, ids=os.path.basename)
def test_notebook_runs_in_quick_mode(path, monkeypatch, tmp_path):
    monkeypatch.setenv("TASKEXP_QUICK", "1")
    monkeypatch.setenv("TASKEXP_RUNS", str(tmp_path / "runs"))  # never read the repository's runs/
    monkeypatch.setenv("TMPDIR", str(tmp_path))                  # quick mode's runs land here
    monkeypatch.setenv("MPLBACKEND", "module://matplotlib_inline.backend_inline")
    nb = nbformat.read(path, as_version=4)
    for cell in nb.cells:
        if cell.cell_type == "code":
            cell.outputs = []
    # raises CellExecutionError (naming the cell) on the first cell that raises
    NotebookClient(nb, timeout=600, kernel_name="python3",
                   resources={"metadata": {"path": os.path.dirname(path)}}).execute()
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs
              if o.output_type == "error"]
    assert not errors
    assert any(o.output_type == "display_data"
               for c in nb.cells if c.cell_type == "code" for o in c.outputs), \
        "a notebook that shows no picture"


def test_animate_gif_frames_and_html():
    env = BlockWorld(4)
    env.reset(seed=1)
    states = [env.get_state()]
    for block, k in [(0, 0), (1, 1)]:
        env.step(env.encode_action(block, 0.3, env.y_bins[k]))
        states.append(env.get_state())
    gif = animate(states, env.goals, fps=4)
    im = Image.open(io.BytesIO(gif))
    assert im.format == "GIF" and im.n_frames == len(states)
    durations = []
    for i in range(im.n_frames):
        im.seek(i)
        durations.append(im.info["duration"])
    assert durations == [250, 250, 750]                  # the last frame is held 3x
    # per-frame goals and titles; html=True wraps the same bytes in an <img> tag
    html = animate(np.stack(states), [None, env.goals, {1: (0.3, 0.075)}], ["a", "b", "c"],
                   html=True)
    assert html.startswith('<img src="data:image/gif;base64,') and html.endswith('">')


@pytest.mark.parametrize("n_blocks, figsize", [(6, (12, 4)), (6, (5.0, 2.6)), (4, (6, 3)),
                                               (8, (12, 4))])
def test_scene_tick_labels_never_repeat(n_blocks, figsize):
    """Notebook 3's map of 64 candidates (6 blocks, 12 x 4 inches) once read "0.3 m, 0.3 m, 0.2 m,
    0.2 m" up its y axis: ticks 0.05 m apart, labels with one decimal. Every label must differ."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=figsize, dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    state = np.zeros((n_blocks, 6))
    state[:, 0], state[:, 1] = X_BINS[::4][:n_blocks], BLOCK_H / 2
    draw_scene(ax, state, {0: (0.0, 2.5 * BLOCK_H)})
    fig.canvas.draw()
    for axis, (lo, hi) in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
        locs = [v for v in axis.get_majorticklocs() if lo <= v <= hi]
        labels = axis.get_major_formatter().format_ticks(locs)
        assert len(set(labels)) == len(labels), labels
        assert not any(label.startswith("-0.0") and set(label) <= set("-0. m")
                       for label in labels), labels


def test_the_library_never_imports_from_notebooks():
    for path in glob.glob(os.path.join(ROOT, "*.py")):
        with open(path) as f:
            assert not re.search(r"^\s*(from|import)\s+notebooks", f.read(), re.M), path


@pytest.mark.parametrize("path", NOTEBOOKS, ids=os.path.basename)
def test_notebook_writes_nothing_into_the_repository_docs(path):
    """docs/ holds committed files: a notebook writes next to the runs or in a temporary folder."""
    nb = nbformat.read(path, as_version=4)
    code = [line.split("#")[0] for c in nb.cells if c.cell_type == "code"
            for line in c.source.splitlines()]                      # without the comments
    assert not [line for line in code if '"docs"' in line or "docs/" in line]


def test_the_reader_sees_no_issue_numbers():
    """What a reader sees says what was measured, not which work item asked for it."""
    texts = {p: open(p, encoding="utf-8").read()
             for p in [os.path.join(ROOT, "README.md"), os.path.join(ROOT, "lab", "RESULTS.md"),
                       os.path.join(ROOT, "lab", "discussion.md"), *NOTEBOOKS]}
    found = {os.path.basename(p): re.findall(r"issue [0-9]+", t, re.IGNORECASE)
             for p, t in texts.items()}
    assert not any(found.values()), found
