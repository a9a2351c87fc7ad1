"""The real grader: nbgrader (a dev dependency: if it is missing these tests fail, they do not
skip), run as an instructor would, on the course that `python -m course course`
writes.

    nbgrader generate_assignment taskexp     on the instructor notebooks (source/taskexp/)
    nbgrader autograde taskexp               on two submissions, copies of release/taskexp/:
        reference   every solution cell pasted from the instructor notebooks: every point that
                    autograde gives, ex7 and ex12 included; then the instructor grades its two
                    written answers (ex11) by hand, as nbgrader's formgrader would, and it has
                    full marks
        mixed       ex2, ex4, ex9 and ex11 solved; ex1, ex3, ex5, ex8 and ex10 left as released
                    (blank); ex6 with select_goal = argmax V(s_T, g) (end2new, equation 1 without
                    its first term); ex7 and ex12, which first name ex1 as not done, so they do
                    not train: the points of ex2, ex4, ex9 and ex11 and nothing else

nbclient, which tests/test_exercises.py uses, executes notebooks but does not grade: nbgrader
gives 0 points to a graded cell that writes to stderr, stops a cell after its timeout, and grades
in the student's folder. About two minutes on two cores: 24 kernels, ex7 and ex12 train once. (A
blank release scoring 0 is checked without nbgrader too, by tests/test_kit.py.)
"""
import json
import os
import shutil
import subprocess
import sys

import nbgrader  # noqa: F401  (the dev dependency: an ImportError here fails, it does not skip)
import pytest
from nbgrader.api import Gradebook

import course as exercises
import course.kit as kit

POINTS, MANUAL = exercises.POINTS, exercises.MANUAL
EXERCISE = {os.path.splitext(name)[0]: ex for ex, name in exercises.NOTEBOOKS.items()}
WRONG = ("return int(np.argmax(v_T - v_0))", "return int(np.argmax(v_T))")      # in ex6
BLANK = ("ex1", "ex3", "ex5", "ex8", "ex10")           # left as released by the mixed submission
SOLVED = ("ex2", "ex4", "ex9", "ex11")                 # the mixed submission's passing exercises


def nbgrader_cmd(root, *args):
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    res = subprocess.run([sys.executable, "-m", "nbgrader", *args], cwd=root, env=env,
                         capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, f"nbgrader {' '.join(args)}:\n{res.stdout}\n{res.stderr[-3000:]}"
    return res


@pytest.fixture(scope="module")
def course(tmp_path_factory):
    """The course after generate_assignment and autograde -> (root, {student: {ex: points}})."""
    root = tmp_path_factory.mktemp("course")
    kit.course(str(root))
    nbgrader_cmd(root, "generate_assignment", "taskexp")
    release = root / "release" / "taskexp"
    for student in ("reference", "mixed"):
        shutil.copytree(release, root / "submitted" / student / "taskexp")
        kit.paste_solutions(root / "submitted" / student / "taskexp")
    mixed = root / "submitted" / "mixed" / "taskexp"
    ex6 = mixed / exercises.NOTEBOOKS["ex6"]
    text = ex6.read_text()
    assert text.count(WRONG[0]) == 1
    ex6.write_text(text.replace(WRONG[0], WRONG[1]))
    for ex in BLANK:                                   # ex1 unfinished: ex7 stops without training
        shutil.copy(release / exercises.NOTEBOOKS[ex], mixed / exercises.NOTEBOOKS[ex])
    nbgrader_cmd(root, "autograde", "taskexp")
    scores = {}
    with Gradebook(f"sqlite:///{root / 'gradebook.db'}") as gb:
        for student in ("reference", "mixed"):
            sub = gb.find_submission("taskexp", student)
            assert sub.max_score == sum(POINTS.values()) + sum(MANUAL.values())
            scores[student] = {EXERCISE[nb.name]: nb.score for nb in sub.notebooks}
        # the instructor grades the reference's written answers by hand, full marks each
        graded = {EXERCISE[nb.name]: nb for nb in
                  gb.find_submission("taskexp", "reference").notebooks}
        for ex in MANUAL:
            for grade in graded[ex].grades:
                if grade.cell.cell_type == "markdown":
                    grade.manual_score = grade.max_score
        gb.db.commit()
        scores["reference, graded by hand"] = {
            EXERCISE[nb.name]: nb.score
            for nb in gb.find_submission("taskexp", "reference").notebooks}
    return root, scores


def test_reference_solutions_get_full_marks(course):
    """autograde gives every automatic point and leaves the written answers to the instructor;
    with those graded, full marks."""
    assert course[1]["reference"] == POINTS
    assert course[1]["reference, graded by hand"] == {
        ex: POINTS[ex] + MANUAL.get(ex, 0) for ex in POINTS}


def test_blank_exercises_get_nothing(course):
    left = (*BLANK, "ex7", "ex12")                     # they need ex1, which is left blank
    assert {ex: course[1]["mixed"][ex] for ex in left} == {ex: 0 for ex in left}


def test_a_wrong_answer_loses_exactly_its_exercise(course):
    assert course[1]["mixed"] == {ex: POINTS[ex] if ex in SOLVED else 0 for ex in POINTS}


def graded_outputs(path):
    with open(path) as f:
        return [o for c in json.load(f)["cells"] if c["metadata"].get("nbgrader", {}).get("grade")
                for o in c.get("outputs", [])]


def test_graded_cells_write_nothing_to_stderr_and_fail_with_a_message(course):
    root = course[0]
    for name in exercises.NOTEBOOKS.values():
        outputs = graded_outputs(root / "autograded" / "reference" / "taskexp" / name)
        assert outputs and not [o for o in outputs if o.get("name") == "stderr"
                                or o["output_type"] == "error"], (name, outputs)
    errors = [o for o in graded_outputs(root / "autograded" / "mixed" / "taskexp" /
                                        exercises.NOTEBOOKS["ex6"]) if o["output_type"] == "error"]
    assert errors[0]["ename"] == "AssertionError"
    assert errors[0]["evalue"].startswith("ex6 FAIL: case 'select_goal") and \
        "end2new" in errors[0]["evalue"], errors[0]["evalue"]
    ex7 = graded_outputs(root / "autograded" / "mixed" / "taskexp" / exercises.NOTEBOOKS["ex7"])
    assert "not done yet" in ex7[-1]["evalue"] and "ex1" in ex7[-1]["evalue"], ex7


def test_nbgrader_release_is_the_student_kit(course, tmp_path):
    """generate_assignment writes the same files as `python -m course release`,
    with the same code in every notebook, and no answer."""
    root, mine = course[0] / "release" / "taskexp", kit.release(str(tmp_path / "kit"))
    files = lambda top: sorted(os.path.relpath(os.path.join(d, f), top)
                               for d, _, fs in os.walk(top) for f in fs)
    assert files(root) == files(mine)
    for name in files(mine):
        if name.endswith(".ipynb"):
            code = lambda top: [c["source"] for c in json.load(open(os.path.join(top, name)))
                                ["cells"]]
            assert ["".join(s) for s in code(root)] == ["".join(s) for s in code(mine)], name
        elif name != os.path.join("course", "vectors.json"):
            assert open(os.path.join(root, name), "rb").read() == \
                open(os.path.join(mine, name), "rb").read(), name
    assert kit.answers_in(root) == []


def test_config_stops_nbgrader_when_the_kernel_cannot_import_the_course(tmp_path):
    """Without this, every cell fails on an import and autograde exits 0 with 0 points. Here the
    python3 kernel is a fresh virtual environment without the requirements."""
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(tmp_path / "venv")],
                   check=True)
    python = str(tmp_path / "venv" / ("Scripts" if os.name == "nt" else "bin") / "python")
    spec = tmp_path / "jupyter" / "kernels" / "python3"
    spec.mkdir(parents=True)
    (spec / "kernel.json").write_text(json.dumps(dict(
        argv=[python, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        display_name="Python 3 (no requirements)", language="python")))
    root = tmp_path / "course"
    kit.course(str(root))
    res = subprocess.run([sys.executable, "-m", "nbgrader", "generate_assignment", "taskexp"],
                         cwd=root, env=dict(os.environ, JUPYTER_PATH=str(tmp_path / "jupyter")),
                         capture_output=True, text=True, timeout=300)
    assert res.returncode != 0 and not (root / "release").exists()
    assert f"the grading kernel's Python ({python}) cannot import the course" in res.stderr
    # the first requirement it misses (taskexp_lib imports threadpoolctl, then numpy)
    assert "No module named '" in res.stderr and "pip install -r" in res.stderr, res.stderr
