"""course/notebooks.py -- the notebooks: load a student's functions from theirs (and
the ActionDist of their exercise 2), and write the student or instructor versions of ours. The
notebooks follow nbgrader's conventions (cell metadata, solution markers)."""
import glob
import json
import linecache
import os
import re

from .dist import student_action_dist
from .problems import ARGUMENTS, BEHAVIOURAL, FUNCTIONS, NOTEBOOKS

COURSE = os.path.dirname(os.path.abspath(__file__))                      # this package
REPOSITORY = os.path.dirname(COURSE)
PACKAGES = [os.path.join(REPOSITORY, p) for p in ("taskexp_lib", "taskexp_cli")]  # the product's
NOTEBOOK_DIR = os.path.join(COURSE, "notebooks")                         # the instructor notebooks

_loading = []         # the folders of the notebooks being loaded: action_dist() looks there


def load(notebook):
    """Exec a notebook's code cells except the graded checks (nbgrader "grade" and not "solution")
    -> the namespace dict holding the student's functions."""
    with open(notebook) as f:
        nb = json.load(f)
    ns = {"__name__": "__exercise__"}
    _loading.append(os.path.dirname(os.path.abspath(notebook)))
    try:
        for i, cell in enumerate(nb["cells"]):
            meta = cell.get("metadata", {}).get("nbgrader", {})
            if cell["cell_type"] == "code" and not (meta.get("grade") and not meta.get("solution")):
                # no IPython magics
                src = re.sub(r"^([ \t]*)([%!])", r"\1# \2", "".join(cell["source"]), flags=re.M)
                name = f"{notebook} (cell {i})"
                # tracebacks show the line
                linecache.cache[name] = (len(src), None, src.splitlines(True), name)
                exec(compile(src, name, "exec"), ns)
    finally:
        _loading.pop()
    return ns


def _notebook(folder, exercise, needed_by):
    path = os.path.join(folder, NOTEBOOKS[exercise])
    if not os.path.exists(path):
        raise FileNotFoundError(f"{needed_by} needs your {exercise}, and there is no "
                                f"{NOTEBOOKS[exercise]} in {os.path.abspath(folder)}")
    return path


def functions(exercise, notebook):
    """The student's functions for an exercise, from their notebook. A behavioural exercise (ex7,
    ex12) takes them from the notebooks of the exercises it needs, in the folder `notebook` (or
    the folder of that notebook): the functions ARGUMENTS names, then the ActionDist of the
    student's exercise 2, the arguments of check_ex7 and check_ex12."""
    if exercise in BEHAVIOURAL:
        folder = notebook if os.path.isdir(notebook) else os.path.dirname(notebook) or "."
        ns = {}
        for ex in BEHAVIOURAL[exercise]:
            if ex != "ex2":                          # ex2 comes in as its ActionDist
                ns.update(load(_notebook(folder, ex, f"exercise {exercise[2:]}")))
        missing = [f for f in ARGUMENTS[exercise] if f not in ns]
        if missing:
            raise NameError(f"your notebooks define no {', '.join(missing)}")
        return [ns[f] for f in ARGUMENTS[exercise]] + [action_dist(folder)]
    ns = load(notebook)
    missing = [f for f in FUNCTIONS[exercise] if f not in ns]
    if missing:
        raise NameError(f"the notebook defines no {', '.join(missing)}")
    return [ns[f] for f in FUNCTIONS[exercise]]


def action_dist(folder=None):
    """The policy distribution of the student's exercise 2: agent.ActionDist's interface, run on
    the functions of ex02_logprob_entropy.ipynb in `folder` (default: the folder of the notebook
    being loaded, else the working directory, which in Jupyter is the notebook's)."""
    folder = folder or (_loading[-1] if _loading else os.getcwd())
    return student_action_dist(*functions("ex2", _notebook(folder, "ex2", "ActionDist")),
                               where=f"exercise 2 ({NOTEBOOKS['ex2']})")


def blank(source, text=False):
    """nbgrader's rule: each ### BEGIN SOLUTION ... ### END SOLUTION block (markers included)
    becomes "# YOUR CODE HERE / raise NotImplementedError()" at the marker's indentation, or in
    a markdown answer (text=True) "YOUR ANSWER HERE"."""
    stub = (lambda i: f"{i}YOUR ANSWER HERE") if text else (
        lambda i: f"{i}# YOUR CODE HERE\n{i}raise NotImplementedError()")
    return re.sub(r"^([ \t]*)### BEGIN SOLUTION[^\n]*\n.*?^[ \t]*### END SOLUTION[^\n]*(\n|$)",
                  lambda m: stub(m.group(1)) + m.group(2), source, flags=re.M | re.S)


def write_notebooks(out_dir, student=True, src_dir=NOTEBOOK_DIR):
    """Write every exercise notebook into out_dir, outputs cleared; student=True: each solution
    blanked (the student version), False: as they are (the instructor version)."""
    os.makedirs(out_dir, exist_ok=True)
    written = []
    for path in sorted(glob.glob(os.path.join(src_dir, "ex*.ipynb"))):
        with open(path) as f:
            nb = json.load(f)
        for cell in nb["cells"]:
            code = cell["cell_type"] == "code"
            if student and (code or cell["metadata"].get("nbgrader", {}).get("solution")):
                cell["source"] = blank("".join(cell["source"]), text=not code).splitlines(
                    keepends=True)
            if code:
                cell["outputs"], cell["execution_count"] = [], None
        written.append(os.path.join(out_dir, os.path.basename(path)))
        with open(written[-1], "w") as f:
            json.dump(nb, f, indent=1, ensure_ascii=False)
            f.write("\n")
    return written
