"""The story notebooks' prose says what their cells print, and sends a reader to the student kit.

The rule for the figures the prose quotes, simple enough to follow when writing:

* A quoted figure is a percentage, `NN%`, in a markdown cell that comes after the notebook's
  first code cell with an output (the introduction above it announces; it does not quote).
* Each must be printed by the notebook's code cells: somewhere in their text outputs (stdout,
  text/plain, and the text/markdown of the tables they display), either as `NN%`, or as an
  entry of the per-seed bracket that follows a printed percentage, the way the tables print a
  mean and its seeds, `61% (61, 82, 41)`.
* A figure taken from a file instead says so: a sentence that names a markdown file of the
  repository (such as `lab/RESULTS.md`) may quote that file's percentages, checked there.
* A change is quoted as its two printed figures ("98% -> 98%"), never as a difference in
  points ("PPO adds one point"), which no output prints: such a phrase fails.
* A comparison `A%, higher than ... (B%)` or `lower than`, in prose or in a printed output,
  orders A and B as it says.

The committed outputs are read from the .ipynb JSON; nothing is executed, so this runs in a
second and checks the notebooks as a reader sees them.
"""
import glob
import json
import os
import re

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NOTEBOOKS = sorted(glob.glob(os.path.join(ROOT, "notebooks", "0*.ipynb")))

NUMBER = r"\d+(?:\.\d+)?"
PERCENT = re.compile(rf"(?<![\d.]){NUMBER}%")                # 8% but not the 8% of 98%
SEEDS = re.compile(rf"({NUMBER})% \(((?:{NUMBER}, )+{NUMBER})\)")     # 61% (61, 82, 41)
POINTS = re.compile(r"\b(\d+|one|two|three|four|five|six|seven|eight|nine|ten)"
                    r"(?: percentage)? points?\b", re.I)
COMPARED = re.compile(rf"({NUMBER})%,? (higher|lower) than [^(\n]*\(({NUMBER})%\)")
MARKDOWN_FILE = re.compile(r"[\w./-]+\.md\b")


def cells(path):
    with open(path, encoding="utf-8") as f:
        return json.load(f)["cells"]


def text(source):
    """A cell's source or an output's text: a string, or the list of lines nbformat keeps."""
    return source if isinstance(source, str) else "".join(source)


def printed(path):
    """Everything the notebook's code cells print as text, joined."""
    out = []
    for cell in cells(path):
        for o in cell.get("outputs", []):
            if o["output_type"] == "stream":
                out.append(text(o["text"]))
            for kind in ("text/plain", "text/markdown"):
                out.append(text(o.get("data", {}).get(kind, "")))
    return "\n".join(out)


def printed_percentages(out):
    """The set of percentages an output text shows: NN%, and each seed of `NN% (a, b, c)`."""
    found = set(PERCENT.findall(out))
    for _, seeds in SEEDS.findall(out):
        found.update(f"{s}%" for s in seeds.split(", "))
    return found


def prose(path):
    """[(cell index, markdown)] after the first code cell with an output."""
    cs = cells(path)
    start = next(i for i, c in enumerate(cs) if c["cell_type"] == "code" and c.get("outputs"))
    return [(i, text(c["source"])) for i, c in enumerate(cs) if i > start
            and c["cell_type"] == "markdown"]


def sentences(markdown):
    return re.split(r"(?<=[.!?:;])\s+(?=[A-Z(\"*])", markdown)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=os.path.basename)
def test_every_quoted_percentage_is_printed_or_sourced(path):
    shown, wrong = printed_percentages(printed(path)), []
    for i, markdown in prose(path):
        for sentence in sentences(markdown):
            sources = [os.path.join(ROOT, f) for f in MARKDOWN_FILE.findall(sentence)
                       if os.path.exists(os.path.join(ROOT, f))]
            elsewhere = set()
            for source in sources:
                with open(source, encoding="utf-8") as f:
                    elsewhere |= printed_percentages(f.read())
            wrong += [f"cell {i}: {p} in {sentence[:90]!r}" for p in PERCENT.findall(sentence)
                      if p not in shown | elsewhere]
    assert not wrong, "quoted but not printed (nor found in a file the sentence names):\n" + \
        "\n".join(wrong)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=os.path.basename)
def test_no_change_is_quoted_in_points(path):
    found = [f"cell {i}: {m.group()!r}" for i, markdown in prose(path)
             for m in POINTS.finditer(markdown)]
    assert not found, f"quote the two printed figures instead: {found}"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=os.path.basename)
def test_a_comparison_orders_its_figures_as_it_says(path):
    texts = [text(c["source"]) for c in cells(path) if c["cell_type"] == "markdown"]
    wrong = [m.group() for t in texts + [printed(path)] for m in COMPARED.finditer(t)
             if not (float(m.group(1)) > float(m.group(3)) if m.group(2) == "higher"
                     else float(m.group(1)) < float(m.group(3)))]
    assert not wrong, wrong


def test_the_rule_catches_a_contradiction():
    """The checks above can fail: the two sentences a reader once met are caught."""
    assert POINTS.search("behaviour cloning alone already solves 98%, and PPO adds one point")
    m = COMPARED.search("with a mean zero-shot success of 2%, lower than ours (2%).")
    assert m and not float(m.group(1)) < float(m.group(3))
    assert printed_percentages("| 3 | 61% (61, 82, 41) |") == {"61%", "82%", "41%"}
    assert "8%" not in printed_percentages("98%")


@pytest.mark.parametrize("name", ["02_base_policy.ipynb", "03_task_expansion_round1.ipynb"])
def test_a_value_outside_0_1_is_explained(name):
    """Notebook 2 prints a fitted V below 0 (after the labels), notebook 3 plots V from about
    -0.1 to 1.05, where V is explained as a discounted chance: the prose says why."""
    markdown = " ".join(" ".join(text(c["source"]).split())      # one line, single spaces
                        for c in cells(os.path.join(ROOT, "notebooks", name))
                        if c["cell_type"] == "markdown")
    assert "regression, not a probability" in markdown, name
    assert "[0, 1]" in markdown, name


@pytest.mark.parametrize("path", NOTEBOOKS, ids=os.path.basename)
def test_build_it_yourself_sends_the_reader_to_the_student_kit(path):
    """course/notebooks/ holds the instructor notebooks, every solution filled in: a reader who
    wants to do the exercises writes the student kit and works there."""
    last = [text(c["source"]) for c in cells(path) if c["cell_type"] == "markdown"][-1]
    assert "Build it yourself" in last
    assert "python -m course release KIT/" in last, last
    assert "course/notebooks" not in last, last
