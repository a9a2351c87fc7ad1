"""exercises/notebooks.py -- load a student's notebook, their exercise 2's ActionDist, and the CLI.
~190 lines.  The notebooks follow nbgrader's conventions (cell metadata, solution markers).
"""
import glob
import json
import linecache
import os
import re
import sys

from .attention import check_ex8
from .behaviour import check_ex7
from .checks import check_ex1, check_ex2, check_ex3, check_ex4, check_ex5, check_ex6, passes
from .dist import student_action_dist
from .problems import FUNCTIONS, NOTEBOOKS, POINTS

NOTEBOOK_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                            "notebooks", "exercises")       # the instructor notebooks
CHECKS = dict(ex1=check_ex1, ex2=check_ex2, ex3=check_ex3, ex4=check_ex4, ex5=check_ex5,
              ex6=check_ex6, ex7=check_ex7, ex8=check_ex8)

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
    """The student's functions for an exercise, from their notebook. ex7: from the ex1-ex4
    notebooks in the folder `notebook` (or the folder of that notebook): [mlp_backward, gae,
    ppo_loss, ActionDist], the arguments of check_ex7."""
    if exercise == "ex7":
        folder = notebook if os.path.isdir(notebook) else os.path.dirname(notebook) or "."
        ns = {}
        for ex in ("ex1", "ex3", "ex4"):
            ns.update(load(_notebook(folder, ex, "exercise 7")))
        return [ns["mlp_backward"], ns["gae"], ns["ppo_loss"], action_dist(folder)]
    ns = load(notebook)
    missing = [f for f in FUNCTIONS[exercise] if f not in ns]
    if missing:
        raise NameError(f"the notebook defines no {', '.join(missing)}")
    return [ns[f] for f in FUNCTIONS[exercise]]


def action_dist(folder=None):
    """The policy distribution of the student's exercise 2: agent.ActionDist's interface, run on
    the functions of ex2_logprob_entropy.ipynb in `folder` (default: the folder of the notebook
    being loaded, else the working directory, which in Jupyter is the notebook's)."""
    folder = folder or (_loading[-1] if _loading else os.getcwd())
    return student_action_dist(*functions("ex2", _notebook(folder, "ex2", "ActionDist")),
                               where=f"exercise 2 ({NOTEBOOKS['ex2']})")


def blank(source):
    """nbgrader's rule: each ### BEGIN SOLUTION ... ### END SOLUTION block (markers included)
    becomes "# YOUR CODE HERE / raise NotImplementedError()" at the marker's indentation."""
    return re.sub(r"^([ \t]*)### BEGIN SOLUTION[^\n]*\n.*?^[ \t]*### END SOLUTION[^\n]*(\n|$)",
                  lambda m: (f"{m.group(1)}# YOUR CODE HERE\n"
                             f"{m.group(1)}raise NotImplementedError(){m.group(2)}"),
                  source, flags=re.M | re.S)


def write_notebooks(out_dir, student=True, src_dir=NOTEBOOK_DIR):
    """Write every exercise notebook into out_dir, outputs cleared; student=True: each solution
    blanked (the student version), False: as they are (the instructor version)."""
    os.makedirs(out_dir, exist_ok=True)
    written = []
    for path in sorted(glob.glob(os.path.join(src_dir, "ex*.ipynb"))):
        with open(path) as f:
            nb = json.load(f)
        for cell in nb["cells"]:
            if cell["cell_type"] == "code":
                if student:
                    cell["source"] = blank("".join(cell["source"])).splitlines(keepends=True)
                cell["outputs"], cell["execution_count"] = [], None
        written.append(os.path.join(out_dir, os.path.basename(path)))
        with open(written[-1], "w") as f:
            json.dump(nb, f, indent=1, ensure_ascii=False)
            f.write("\n")
    return written


USAGE = """usage: python -m exercises COMMAND
  ex1 .. ex6, ex8 NOTEBOOK   check one exercise in your notebook, e.g. ex3 ex3_gae.ipynb
  ex7 FOLDER            exercise 7: trains with the ex1-ex4 notebooks in FOLDER (e.g. .)
  all FOLDER            check all eight notebooks in FOLDER, then the total
  release OUT           (instructors) write the student kit into OUT
  course DIR            (instructors) write an nbgrader course into DIR"""


def check(exercise, notebook):
    """Run one exercise's check on a notebook (ex7: a folder) -> passed (True/False); prints
    PASS, or FAIL and what failed."""
    try:
        fns = functions(exercise, notebook)
    except Exception as e:  # a broken notebook fails its exercise, not the run
        print(f"{exercise} FAIL: could not run the notebook's cells: {type(e).__name__}: {e}")
        return False
    try:
        return passes(CHECKS[exercise], *fns)
    except Exception as e:  # a check the student's answer crashed still says FAIL
        print(f"{exercise} FAIL: the check stopped: {type(e).__name__}: {e}")
        return False


def main(argv=None):
    cmd, *rest = (sys.argv[1:] if argv is None else argv) or [None]
    if cmd in ("release", "course") and len(rest) == 1:
        from .kit import course, release
        try:
            print(f"wrote {(release if cmd == 'release' else course)(rest[0])}")
        except ValueError as e:
            print(e, file=sys.stderr)
            return 2
        return 0
    if cmd in [*NOTEBOOKS, "all"] and not rest:
        what = ("the folder of your notebooks" if cmd in ("all", "ex7") else
                f"your notebook, e.g. {NOTEBOOKS[cmd]}")
        print(f"which {'folder' if cmd in ('all', 'ex7') else 'notebook'}? "
              f"python -m exercises {cmd} PATH, with PATH {what} ('.' in the student kit's "
              "folder)", file=sys.stderr)
        return 2
    if cmd not in [*NOTEBOOKS, "all"] or len(rest) != 1:
        print(USAGE, file=sys.stderr)
        return 2
    if cmd != "all":
        return 0 if check(cmd, rest[0]) else 1
    passed = {ex: check(ex, os.path.join(rest[0], NOTEBOOKS[ex]) if ex != "ex7" else rest[0])
              for ex in NOTEBOOKS}
    points = sum(POINTS[ex] for ex, ok in passed.items() if ok)
    print(f"total: {points}/{sum(POINTS.values())} points; {sum(passed.values())} of "
          f"{len(passed)} exercises pass" + ("" if all(passed.values()) else
          f" (fail: {', '.join(ex for ex, ok in passed.items() if not ok)})"))
    return 0 if all(passed.values()) else 1
