"""exercises/notebooks.py -- load a student's notebook, release the student versions, and the CLI.
~120 lines.  The notebooks follow nbgrader's conventions (cell metadata, solution markers) without
needing nbgrader.
"""
import glob
import json
import linecache
import os
import re
import sys

from .behaviour import check_ex7
from .checks import check_ex1, check_ex2, check_ex3, check_ex4, check_ex5, check_ex6

NOTEBOOK_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                            "notebooks", "exercises")
NOTEBOOKS = {"ex1": "ex1_mlp_backward.ipynb", "ex2": "ex2_logprob_entropy.ipynb",
             "ex3": "ex3_gae.ipynb", "ex4": "ex4_ppo_loss.ipynb", "ex5": "ex5_alter.ipynb",
             "ex6": "ex6_select_relabel.ipynb", "ex7": "ex7_base_policy.ipynb"}
FUNCTIONS = {"ex1": ["mlp_backward"], "ex2": ["logp_entropy", "logp_entropy_backward"],
             "ex3": ["gae"], "ex4": ["ppo_loss"], "ex5": ["alter"],
             "ex6": ["select_goal", "relabel"], "ex7": ["mlp_backward", "gae", "ppo_loss"]}

CHECKS = dict(ex1=check_ex1, ex2=check_ex2, ex3=check_ex3, ex4=check_ex4, ex5=check_ex5,
              ex6=check_ex6, ex7=check_ex7)


def load(notebook):
    """Exec a notebook's code cells except the graded checks (nbgrader "grade" and not "solution")
    -> the namespace dict holding the student's functions."""
    with open(notebook) as f:
        nb = json.load(f)
    ns = {"__name__": "__exercise__"}
    for i, cell in enumerate(nb["cells"]):
        meta = cell.get("metadata", {}).get("nbgrader", {})
        if cell["cell_type"] == "code" and not (meta.get("grade") and not meta.get("solution")):
            # no IPython magics
            src = re.sub(r"^([ \t]*)([%!])", r"\1# \2", "".join(cell["source"]), flags=re.M)
            name = f"{notebook} (cell {i})"
            # tracebacks show the line
            linecache.cache[name] = (len(src), None, src.splitlines(True), name)
            exec(compile(src, name, "exec"), ns)
    return ns


def functions(exercise, notebook=None):
    """The student's functions for an exercise, from its notebook (ex7: from ex1, ex3, ex4's)."""
    if exercise == "ex7":                          # notebook: ex7's notebook, or their folder
        folder = notebook or NOTEBOOK_DIR
        folder = folder if os.path.isdir(folder) else os.path.dirname(folder)
        ns = {k: v for ex in ("ex1", "ex3", "ex4")
              for k, v in load(os.path.join(folder, NOTEBOOKS[ex])).items()}
    else:
        ns = load(notebook or os.path.join(NOTEBOOK_DIR, NOTEBOOKS[exercise]))
    missing = [f for f in FUNCTIONS[exercise] if f not in ns]
    if missing:
        raise NameError(f"the notebook defines no {', '.join(missing)}")
    return [ns[f] for f in FUNCTIONS[exercise]]


def blank(source):
    """nbgrader's rule: each ### BEGIN SOLUTION ... ### END SOLUTION block (markers included)
    becomes "# YOUR CODE HERE / raise NotImplementedError()" at the marker's indentation."""
    return re.sub(r"^([ \t]*)### BEGIN SOLUTION[^\n]*\n.*?^[ \t]*### END SOLUTION[^\n]*(\n|$)",
                  lambda m: (f"{m.group(1)}# YOUR CODE HERE\n"
                             f"{m.group(1)}raise NotImplementedError(){m.group(2)}"),
                  source, flags=re.M | re.S)


def release(out_dir, src_dir=NOTEBOOK_DIR):
    """Write the student version of every exercise notebook: solutions blanked, outputs cleared."""
    if os.path.realpath(out_dir) == os.path.realpath(src_dir):
        raise ValueError(f"release would overwrite the instructor notebooks in {src_dir}")
    os.makedirs(out_dir, exist_ok=True)
    written = []
    for path in sorted(glob.glob(os.path.join(src_dir, "ex*.ipynb"))):
        with open(path) as f:
            nb = json.load(f)
        for cell in nb["cells"]:
            if cell["cell_type"] == "code":
                cell["source"] = blank("".join(cell["source"])).splitlines(keepends=True)
                cell["outputs"], cell["execution_count"] = [], None
        written.append(os.path.join(out_dir, os.path.basename(path)))
        with open(written[-1], "w") as f:
            json.dump(nb, f, indent=1, ensure_ascii=False)
            f.write("\n")
    return written


def main(argv=None):
    cmd, *rest = (sys.argv[1:] if argv is None else argv) or [None]
    lo, hi = (1, 2) if cmd == "release" else (0, 1)          # how many arguments follow the command
    if cmd not in [*NOTEBOOKS, "all", "release"] or not lo <= len(rest) <= hi:
        print("usage: python -m exercises "
              "{ex1..ex7 [NOTEBOOK] | all [DIR] | release OUT_DIR [SRC_DIR]}", file=sys.stderr)
        return 2
    if cmd == "release":
        try:
            for path in release(*rest):
                print("wrote", path)
        except ValueError as e:
            print(e, file=sys.stderr)
            return 2
        return 0
    if cmd == "all":
        todo = [(ex, os.path.join(rest[0] if rest else NOTEBOOK_DIR, NOTEBOOKS[ex]))
                for ex in NOTEBOOKS]
    else:
        todo = [(cmd, rest[0] if rest else None)]
    ok = []
    for ex, nb in todo:
        try:
            fns = functions(ex, nb)
        except Exception as e:  # a broken notebook fails its exercise, not the run
            print(f"{ex} FAIL: could not run the notebook's cells: {type(e).__name__}: {e}")
            ok.append(False)
            continue
        try:
            ok.append(CHECKS[ex](*fns))
        except Exception as e:  # a check the student's answer crashed still says FAIL
            print(f"{ex} FAIL: the check stopped: {type(e).__name__}: {e}")
            ok.append(False)
    return 0 if all(ok) else 1

