"""course/kit.py -- the student kit, and the nbgrader course that makes the same kit.

    python -m course release OUT   the student kit: hand OUT to students
    python -m course course DIR    an nbgrader course (its nbgrader_config.py:
                                                  course/notebooks/nbgrader_config.py)

A kit is self-contained: copied anywhere, with only requirements.txt installed, its notebooks
import and its checks run. It holds no answer: the library's reference solution of every
exercise (EXERCISED) is a stub that raises NotImplementedError, found by its line numbers in
the syntax tree (docstrings stay), and the checks read recorded cases (vectors.py) instead of
calling the reference.
"""
import ast
import contextlib
import glob
import io
import json
import os
import re
import shutil

import numpy as np

from . import vectors
from .checks import CHECKS
from .notebooks import COURSE, NOTEBOOK_DIR, PACKAGES, REPOSITORY, write_notebooks
from .problems import FUNCTIONS, MANUAL, NOTEBOOKS, POINTS

# the modules the wheel installs (pyproject.toml), as dotted names
LIBRARY = ["taskexp", "env2d", "agent"] + sorted(
    f"{os.path.basename(package)}.{os.path.basename(p)[:-3]}"
    for package in PACKAGES for p in glob.glob(os.path.join(package, "*.py")))
ASSIGNMENT = "taskexp"                                           # the nbgrader assignment's name

# The reference solutions: what each exercise asks for, as the library has it. In a kit each is
# a stub. ex2: agent.ActionDist's log-probabilities, entropy and their gradient, with its two
# helpers; the kit's notebooks use exercises.action_dist() instead, the same interface run on
# the student's functions (sampling and the mode are ActionDist's own, on the student's
# log_softmax). ex5: taskexp.random_position is the reference's draw of a new position. ex6:
# taskexp_lib.rollout.cut is the second half of the reference's relabel (where the goals first
# hold).
EXERCISED = {
    "ex1": [("taskexp_lib.nn", "mlp_backward")],
    "ex2": [("agent", "log_softmax"), ("agent", "entropy_of"), ("agent", "ActionDist.log_prob"),
            ("agent", "ActionDist.entropy"), ("agent", "ActionDist.backward")],
    "ex3": [("agent", "gae")],
    "ex4": [("agent", "ppo_loss")],
    "ex5": [("taskexp", "alter"), ("taskexp", "random_position")],
    "ex6": [("taskexp", "select_goal"), ("taskexp", "relabel"), ("taskexp_lib.rollout", "cut")],
    "ex8": [("taskexp_lib.nn", "softmax_backward"), ("taskexp_lib.nn", "SelfAttention.backward")],
    "ex9": [("taskexp", "join"), ("taskexp", "expansion_step")],
    "ex10": [("taskexp", "distillation_data"), ("taskexp", "distillation_tasks")],
    "ex11": [("taskexp_lib.features", "one_drop_away")],       # and ex6's select_goal, with modes
}


def source_file(module, root=REPOSITORY):
    """The file of a library module named with dots (taskexp_lib.nn) in the folder `root`."""
    return os.path.join(root, *module.split(".")) + ".py"


def find_function(tree, qualname):
    """The FunctionDef of `name` or `Class.name` at the top level of a module's syntax tree."""
    body = tree.body
    *classes, name = qualname.split(".")
    for cls in classes:
        body = next(n for n in body if isinstance(n, ast.ClassDef) and n.name == cls).body
    return next(n for n in body if isinstance(n, ast.FunctionDef) and n.name == name)


def body_lines(source, qualname):
    """(first, last) line numbers (1-based) of a function's body after its docstring."""
    fn = find_function(ast.parse(source), qualname)
    doc = fn.body[0]
    if not (isinstance(doc, ast.Expr) and isinstance(doc.value, ast.Constant)
            and isinstance(doc.value.value, str)) or len(fn.body) < 2:
        raise ValueError(f"{qualname}: an exercised function needs a docstring and a body")
    return doc.end_lineno + 1, fn.end_lineno


def stub(source, module):
    """The module's source with the body of each exercised function replaced by a raise."""
    lines = source.splitlines(keepends=True)
    spans = []
    for ex, names in EXERCISED.items():
        for mod, qualname in names:
            if mod == module:
                first, last = body_lines(source, qualname)
                indent = lines[first - 1][:len(lines[first - 1]) - len(lines[first - 1].lstrip())]
                why = (f'"{module}.{qualname} is a stub in the student kit: "\n{indent}    '
                       f'"the reference solution of exercise {ex[2:]} ({NOTEBOOKS[ex]})"')
                spans.append((first, last, f"{indent}raise NotImplementedError(\n{indent}    "
                                           f"{why})\n"))
    for first, last, text in sorted(spans, reverse=True):       # bottom up: numbers stay valid
        lines[first - 1:last] = [text]
    return "".join(lines)


def normalised(text):
    """Lines without comments and whitespace: what a copy of code keeps."""
    return [re.sub(r"\s+", "", re.sub(r"#.*", "", line)) for line in text.splitlines()]


def reference_code():
    """Every body line of a reference solution, normalised: the library's exercised functions
    (after their docstrings) and the instructor notebooks' solution blocks -> [(where, lines)]."""
    bodies = []
    for names in EXERCISED.values():
        for module, qualname in names:
            with open(source_file(module)) as f:
                source = f.read()
            first, last = body_lines(source, qualname)
            bodies.append((f"{module}.{qualname}", source.splitlines()[first - 1:last]))
    for name in NOTEBOOKS.values():
        with open(os.path.join(NOTEBOOK_DIR, name)) as f:
            for cell in json.load(f)["cells"]:
                for block in re.findall(r"### BEGIN SOLUTION\n(.*?)### END SOLUTION",
                                        "".join(cell["source"]), re.S):
                    bodies.append((name, block.splitlines()))
    return [(where, [n for n in normalised("\n".join(lines)) if n]) for where, lines in bodies]


def _texts(folder):
    """{path: normalised lines} of every file in a folder (notebooks: their cells' sources)."""
    texts = {}
    for dirpath, _, files in os.walk(folder):
        for name in files:
            path = os.path.join(dirpath, name)
            if name.endswith(".npz"):                     # weights: numbers, no code
                continue
            with open(path) as f:
                text = f.read()
            if name.endswith(".ipynb"):
                text = "\n".join("".join(c["source"]) for c in json.loads(text)["cells"])
            texts[path] = [n for n in normalised(text) if n]
    return texts


def answers_in(folder):
    """Where a folder holds a reference solution -> [(path, whose, a line)]: any line of one of
    30 characters or more (without spaces), or any three consecutive lines. Shorter single lines,
    such as `B = len(actions)`, are also plain code elsewhere in the library."""
    found, reference = [], reference_code()
    for path, lines in _texts(folder).items():
        have, triples = set(lines), set(zip(lines, lines[1:], lines[2:]))
        for where, body in reference:
            long = [n for n in body if len(n) >= 30 and n in have]
            runs = [t for t in zip(body, body[1:], body[2:]) if t in triples]
            if long or runs:
                found.append((path, where, (long or [runs[0]])[0]))
    return found


def record_vectors():
    """Every case of the checks with recorded cases (all but the behavioural ex7 and ex12), made
    on the full library -> {key: encoded case}."""
    if vectors.in_kit():
        raise ValueError("this is a student kit, which has no reference solutions: "
                         "make kits from the repository")

    def not_mine(*args, **kwargs):
        raise NotImplementedError()
    with vectors.recording() as cases, contextlib.redirect_stdout(io.StringIO()):
        for ex, check in CHECKS.items():
            if ex in FUNCTIONS:                       # ex7 and ex12 have no cases: they train
                with contextlib.suppress(AssertionError):  # each case is made before it is run
                    check(*[not_mine] * len(FUNCTIONS[ex]))
    return cases


def _target(out):
    """Refuse to write a kit over the repository, the instructor notebooks, or a folder that
    is neither empty nor an earlier kit."""
    real = os.path.realpath(out)
    if real in (os.path.realpath(REPOSITORY), os.path.realpath(NOTEBOOK_DIR)) or \
            os.path.realpath(REPOSITORY).startswith(real + os.sep):
        raise ValueError(f"a kit in {out} would overwrite the repository's library or notebooks")
    if os.path.isdir(out) and os.listdir(out) and not os.path.exists(
            os.path.join(out, "course", "vectors.json")):
        raise ValueError(f"{out} is not empty and holds no earlier kit: choose a new folder")


def write_kit(out, student=True):
    """The kit in `out`: notebooks (student=True: blanked; False: the instructor's, for nbgrader's
    source folder), the library with stubs, the exercises package with its test vectors,
    requirements.txt and README.md.  -> out"""
    _target(out)
    cases = record_vectors()
    kit_course = os.path.join(out, "course")
    os.makedirs(kit_course, exist_ok=True)
    write_notebooks(out, student)
    for module in LIBRARY:
        with open(source_file(module)) as f:
            source = f.read()
        os.makedirs(os.path.dirname(source_file(module, out)), exist_ok=True)   # taskexp_lib/...
        with open(source_file(module, out), "w") as f:
            f.write(stub(source, module))
    for path in glob.glob(os.path.join(COURSE, "*.py")):
        shutil.copyfile(path, os.path.join(kit_course, os.path.basename(path)))
    shutil.copytree(os.path.join(COURSE, "data"), os.path.join(kit_course, "data"),
                    dirs_exist_ok=True)                 # the round-0 agent of exercises 11 and 12
    with open(os.path.join(kit_course, "vectors.json"), "w") as f:
        json.dump(dict(about="the checks' cases: inputs and expected outputs, recorded from the "
                             "reference solutions by python -m course release",
                       numpy=np.__version__, cases=cases), f)
    shutil.copyfile(os.path.join(REPOSITORY, "requirements.txt"),
                    os.path.join(out, "requirements.txt"))
    with open(os.path.join(out, "README.md"), "w") as f:
        f.write(README)
    leaks = answers_in(out) if student else []
    if leaks:                      # the library changed so that the stubs miss a solution
        raise RuntimeError(f"the kit in {out} holds reference code, e.g. {leaks[0]}")
    return out


def paste_solutions(folder, src_dir=NOTEBOOK_DIR):
    """Put the instructor's solution cells into the student notebooks in `folder` (matched by
    their nbgrader grade_id): what a student who finds every reference solution hands in. For
    instructors and tests, to see a kit give full marks.  -> the notebooks changed"""
    changed = []
    for name in NOTEBOOKS.values():
        with open(os.path.join(src_dir, name)) as f:
            solutions = {c["metadata"]["nbgrader"]["grade_id"]: c["source"]
                         for c in json.load(f)["cells"] if c["metadata"]["nbgrader"]["solution"]}
        path = os.path.join(folder, name)
        with open(path) as f:
            nb = json.load(f)
        for cell in nb["cells"]:
            cell["source"] = solutions.get(cell["metadata"]["nbgrader"]["grade_id"],
                                           cell["source"])
        with open(path, "w") as f:
            json.dump(nb, f, indent=1, ensure_ascii=False)
        changed.append(path)
    return changed


def release(out):
    """The student kit in `out` -> out."""
    return write_kit(out, student=True)


def course(root):
    """An nbgrader course in `root`: root/nbgrader_config.py and root/source/taskexp/ (the
    instructor notebooks with the kit's library and checks). `nbgrader generate_assignment
    taskexp` in root then writes the student kit into root/release/taskexp/.  -> root"""
    write_kit(os.path.join(root, "source", ASSIGNMENT), student=False)
    shutil.copyfile(os.path.join(NOTEBOOK_DIR, "nbgrader_config.py"),
                    os.path.join(root, "nbgrader_config.py"))
    return root


WHAT = {"ex1": "the MLP backward pass", "ex2": "log-probability and entropy of the policy, "
        "and their gradients", "ex3": "generalised advantage estimation (GAE)",
        "ex4": "PPO's clipped loss and its gradient", "ex5": "one-alteration task sampling "
        "(sec 4.2)", "ex6": "goal selection by equation (1), hindsight relabelling",
        "ex7": "nothing new: your ex1-ex4 train the base policy (15 s to a minute)",
        "ex8": "the backward pass of a self-attention layer (the paper's network, sec 3)",
        "ex9": "the expansion step: candidates, equation (1), the run from s_T, join or relabel "
        "(sec 4.2)", "ex10": "the data of self-distillation: BC's buffer, PPO's new and old "
        "tasks (sec 4.3)", "ex11": "equation (1) against its ablations, with a real round-0 "
        "critic: predict, measure, explain (Table 3)", "ex12": "the capstone, nothing new: your "
        "ex1-ex6 and ex8-ex10 run two rounds of the method; the tasks must grow and zero-shot "
        "success rise (about a minute)"}

README = """# Task expansion from the inside: the student kit

Twelve exercises on the method of "Self-Generating Data for Goal-Conditioned Compositional
Problems" (Yuan, Li, Wu), in numpy. In each notebook you write one piece of the method; its check
says PASS, or which case fails, what it expected, what you returned, and a hint. The last one,
the capstone, runs two rounds of task expansion with every piece you wrote.

## Set up, once

    python -m venv .venv
    . .venv/bin/activate                   # Windows: .venv\\Scripts\\activate
    pip install -r requirements.txt
    pip install notebook                   # to open the notebooks (or jupyterlab)
    jupyter notebook                       # in this folder

## The exercises

| notebook | you write | points |
|---|---|---|
""" + "".join(f"| `{NOTEBOOKS[ex]}` | {WHAT[ex]} | {POINTS[ex]}"
             + (f" + {MANUAL[ex]} written, graded by hand" if ex in MANUAL else "") + " |\n"
             for ex in NOTEBOOKS) + """
Work in order: exercise 4 uses your exercise 2 (its `ActionDist` runs your
`ex02_logprob_entropy.ipynb`), exercise 7 trains a policy with your exercises 1 to 4, and
exercise 12 runs two rounds of the method with your exercises 1 to 6, 8, 9 and 10.

## Check yourself

Run a notebook's last cell: it prints PASS, or stops with an AssertionError that says what
failed. Or, in a terminal in this folder:

    python -m course ex3 ex03_gae.ipynb   # one exercise
    python -m course ex7 .               # exercise 7: trains with your ex1-ex4
    python -m course ex12 .              # exercise 12: two rounds with your pieces
    python -m course all .               # every exercise, then your total

## What is in this folder

- `ex01_mlp_backward.ipynb` ... `ex12_capstone.ipynb`: the exercises; hand these in.
- `taskexp.py` (the method), `env2d.py` (the world), `agent.py` (the agent), `taskexp_lib/`
  (what they are built from) and `taskexp_cli/` (the command line): the taskexp library that the
  notebooks import. The functions you write are stubs here (they raise NotImplementedError);
  where the library needs them, exercises 7 and 12 run it on yours.
- `course/`: the checks, a file per exercise. `course/vectors.json`
  holds their cases, inputs and expected outputs, recorded from the reference solutions, and
  `course/data/round0.npz` the agent of a default run after round 0 (exercises 11 and 12).
"""
