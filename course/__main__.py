"""course/__main__.py -- the command line: check a notebook or a folder, write the
kit.

    python -m course ex3 NOTEBOOK   # exec the notebook's solution cells, check_ex3
    python -m course all FOLDER     # every exercise, the total; exit 1 if one fails
    python -m course release OUT    # the student kit
    python -m course course DIR     # an nbgrader course that makes the same kit
"""
import os
import sys

from taskexp_lib import one_blas_thread

from .checks import CHECKS
from .grader import passes
from .kit import course, release
from .notebooks import functions
from .problems import BEHAVIOURAL, MANUAL, NOTEBOOKS, POINTS
from .vectors import in_kit

STUDENT_USAGE = """usage: python -m course COMMAND
  ex1 .. ex6, ex8 .. ex11 NOTEBOOK
                        check one exercise in your notebook, e.g. ex3 ex03_gae.ipynb
  ex7 FOLDER            exercise 7: trains with the ex1-ex4 notebooks in FOLDER (e.g. .)
  ex12 FOLDER           exercise 12: two rounds with the ex01-ex06, ex08-ex10 notebooks
  all FOLDER            check every notebook in FOLDER, then the total"""
INSTRUCTOR_USAGE = """
  release OUT           (instructors) write the student kit into OUT
  course DIR            (instructors) write an nbgrader course into DIR"""


def usage():
    """The commands one can run here: a student kit has no reference solutions to make a kit
    from, so its students read only their own commands; the repository lists all."""
    return STUDENT_USAGE + ("" if in_kit() else INSTRUCTOR_USAGE)


def check(exercise, notebook):
    """Run one exercise's check on a notebook (ex7, ex12: a folder) -> passed (True/False); prints
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


def check_all(folder):
    """Every exercise on the notebooks in `folder`, then the total -> all passed."""
    passed = {ex: check(ex, folder if ex in BEHAVIOURAL else os.path.join(folder, NOTEBOOKS[ex]))
              for ex in NOTEBOOKS}
    points = sum(POINTS[ex] for ex, ok in passed.items() if ok)
    print(f"written answers, graded by hand: {', '.join(f'{ex} {p}' for ex, p in MANUAL.items())}"
          " points, not counted below")
    print(f"total: {points}/{sum(POINTS.values())} points; {sum(passed.values())} of "
          f"{len(passed)} exercises pass" + ("" if all(passed.values()) else
          f" (fail: {', '.join(ex for ex, ok in passed.items() if not ok)})"))
    return all(passed.values())


def main(argv=None):
    cmd, *rest = (sys.argv[1:] if argv is None else argv) or [None]
    if cmd in ("release", "course") and len(rest) == 1:
        try:
            print(f"wrote {(release if cmd == 'release' else course)(rest[0])}")
        except ValueError as e:
            print(e, file=sys.stderr)
            return 2
        return 0
    if cmd in [*NOTEBOOKS, "all"] and not rest:
        folder = cmd == "all" or cmd in BEHAVIOURAL
        what = ("the folder of your notebooks" if folder else
                f"your notebook, e.g. {NOTEBOOKS[cmd]}")
        print(f"which {'folder' if folder else 'notebook'}? "
              f"python -m course {cmd} PATH, with PATH {what} ('.' in the "
              "student kit's folder)", file=sys.stderr)
        return 2
    if cmd not in [*NOTEBOOKS, "all"] or len(rest) != 1:
        print(usage(), file=sys.stderr)
        return 2
    if cmd == "all":
        return 0 if check_all(rest[0]) else 1
    return 0 if check(cmd, rest[0]) else 1


if __name__ == "__main__":
    with one_blas_thread():          # the checks and the recorded cases, as in a run
        sys.exit(main())
