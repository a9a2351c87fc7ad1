"""The student kit (`python -m course release OUT`): self-contained, and without
answers.

Its library is the repository's with each exercised function's body replaced by a raise, and
nothing else changed; no line of a reference solution (the library's exercised functions, the
instructor notebooks' solution blocks) is anywhere in it; its checks read recorded cases that
equal the live ones. And from a folder outside the checkout, in a virtual environment that has the
requirements but not the checkout, the blank kit totals 0 and the kit with the reference solutions
pasted in gets full marks (exercise 7 trains once: ~15-60 s).
"""
import ast
import json
import os
import re
import shutil
import site
import subprocess
import sys

import numpy as np
import pytest

import course as exercises
import course.kit as kit
from course import vectors

ROOT = kit.REPOSITORY


@pytest.fixture(scope="module")
def kit_dir(tmp_path_factory):
    return kit.release(str(tmp_path_factory.mktemp("kit") / "kit"))


def cli(*args, cwd=ROOT, python=sys.executable):
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    return subprocess.run([python, "-m", "course", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)


def test_cli_release_writes_the_kit_and_never_over_the_repository(tmp_path):
    out = tmp_path / "kit"
    res = cli("release", str(out))
    assert res.returncode == 0, res.stdout + res.stderr
    top_level = [f"{m}.py" for m in kit.LIBRARY if "." not in m]      # and the packages
    assert sorted(os.listdir(out)) == sorted(
        [*exercises.NOTEBOOKS.values(), *top_level, "taskexp_lib", "taskexp_cli", "course",
         "requirements.txt", "README.md"])
    assert "vectors.json" in os.listdir(out / "course")
    assert cli("release", str(out)).returncode == 0                   # an earlier kit: updated
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("mine")
    for target in (exercises.NOTEBOOK_DIR, ROOT, str(tmp_path / "mine")):
        res = cli("release", target)
        assert res.returncode == 2 and res.stderr, (target, res.stdout)


def test_library_list_is_pyproject_s():
    """The kit's library is what the wheel installs: pyproject's top-level modules, and every
    module of its packages, taskexp_lib and taskexp_cli (the course is copied apart, with its
    vectors)."""
    with open(os.path.join(ROOT, "pyproject.toml")) as f:
        toml = f.read()
    listed = re.search(r"py-modules = \[(.*?)\]", toml).group(1)
    assert sorted(re.findall(r'"(\w+)"', listed)) == sorted(m for m in kit.LIBRARY if "." not in m)
    packages = re.findall(r'"(\w+)"', re.search(r"packages = \[(.*?)\]", toml).group(1))
    assert sorted(map(os.path.basename, kit.PACKAGES)) == sorted(packages)
    modules = sorted(f"{os.path.basename(p)}.{name[:-3]}" for p in kit.PACKAGES
                     for name in os.listdir(p) if name.endswith(".py"))
    assert modules == sorted(m for m in kit.LIBRARY if "." in m)


def functions_of(tree):
    """{qualname: FunctionDef} of a module's top-level functions and methods."""
    out = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            out[node.name] = node
        elif isinstance(node, ast.ClassDef):
            out.update({f"{node.name}.{n.name}": n for n in node.body
                        if isinstance(n, ast.FunctionDef)})
    return out


def test_kit_library_stubs_exactly_the_exercised_functions(kit_dir):
    exercised = {(m, q) for names in kit.EXERCISED.values() for m, q in names}
    for module in kit.LIBRARY:
        with open(kit.source_file(module)) as f:
            ref = ast.parse(f.read())
        with open(kit.source_file(module, kit_dir)) as f:
            mine = ast.parse(f.read())
        ref_fns, kit_fns = functions_of(ref), functions_of(mine)
        assert sorted(ref_fns) == sorted(kit_fns), module
        for name, fn in kit_fns.items():
            if (module, name) in exercised:
                doc, body = fn.body[0], fn.body[1:]
                assert ast.get_docstring(fn) == ast.get_docstring(ref_fns[name]), name
                assert isinstance(doc.value, ast.Constant)
                assert len(body) == 1 and isinstance(body[0], ast.Raise), name
                assert "NotImplementedError" in ast.unparse(body[0]), name
                assert len(ref_fns[name].body) > 1, name          # the library's is not a stub
            else:
                assert ast.dump(fn) == ast.dump(ref_fns[name]), f"{module}.{name} changed"
        # and nothing outside the functions changed
        strip = lambda tree: [ast.dump(n) for n in tree.body
                              if not isinstance(n, (ast.FunctionDef, ast.ClassDef))]
        assert strip(ref) == strip(mine), module


def test_no_reference_solution_anywhere_in_the_kit(kit_dir):
    code, blocks = kit.reference_code(), 0
    for name in exercises.NOTEBOOKS.values():
        with open(os.path.join(exercises.NOTEBOOK_DIR, name)) as f:
            blocks += f.read().count("### BEGIN SOLUTION")
    assert len(code) == sum(map(len, kit.EXERCISED.values())) + blocks
    # each can be found: a line of 30 characters or more, or three lines
    assert all(len(body) >= 3 or max(map(len, body)) >= 30 for _, body in code)
    assert kit.answers_in(kit_dir) == []


def test_the_answer_search_finds_an_answer(kit_dir, tmp_path):
    """The search above can fail: a kit with one reference body pasted back is caught."""
    shutil.copytree(kit_dir, tmp_path / "leaky")
    with open(os.path.join(ROOT, "agent.py")) as f:
        gae = f.read()
    first, last = kit.body_lines(gae, "gae")
    with open(tmp_path / "leaky" / "course" / "helpers.py", "w") as f:
        f.write("\n".join(gae.splitlines()[first - 1:last]))
    assert [where for _, where, _ in kit.answers_in(tmp_path / "leaky")] == ["agent.gae"]


def test_recorded_cases_are_the_live_ones(kit_dir):
    with open(os.path.join(kit_dir, "course", "vectors.json")) as f:
        recorded = json.load(f)["cases"]
    live = json.loads(json.dumps(kit.record_vectors()))
    # ex1 5, ex2 6, ex3 12, ex4 6, ex5 7, ex6 13, ex8 5, ex9 6, ex10 7, ex11 8 (join: no case)
    assert recorded == live and len(live) == 5 + 6 + 12 + 6 + 7 + 13 + 5 + 6 + 7 + 8


def test_vectors_read_back_what_was_written():
    case = {"x": np.arange(6.0).reshape(2, 3) / 7, "n": np.zeros((0, 3), int), "f": 0.1 + 0.2,
            "goals": {2: (0.15, 0.175), 0: (-0.3, 0.525)}, "hs": [np.ones(2), np.eye(2)],
            "none": None, "inf": -np.inf}
    back = vectors.decode(json.loads(json.dumps(vectors.encode(case))))
    assert back.keys() == case.keys() and back["goals"] == case["goals"]
    assert all(np.array_equal(back[k], case[k]) and back[k].dtype == case[k].dtype
               for k in ("x", "n"))
    assert back["f"] == case["f"] and back["none"] is None and back["inf"] == -np.inf
    assert all(np.array_equal(a, b) for a, b in zip(back["hs"], case["hs"]))


@pytest.fixture(scope="module")
def bare_python(tmp_path_factory):
    """A fresh virtual environment with the requirements (this environment's packages, through
    a path line in a .pth; its .pth files, such as the checkout's editable install, stay off)
    and without the checkout."""
    venv = tmp_path_factory.mktemp("venv")
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    python = str(venv / ("Scripts" if os.name == "nt" else "bin") / "python")
    where = "import sysconfig; print(sysconfig.get_paths()['purelib'])"
    purelib = subprocess.run([python, "-c", where], capture_output=True, text=True,
                             check=True).stdout.strip()
    with open(os.path.join(purelib, "outer_deps.pth"), "w") as f:
        f.write("\n".join(site.getsitepackages()) + "\n")
    res = subprocess.run([python, "-c", "import numpy, pymunk, gymnasium; import agent"],
                         cwd=venv, capture_output=True, text=True)
    assert "No module named 'agent'" in res.stderr, res.stderr      # the checkout is not there
    return python


def test_kit_runs_from_a_folder_outside_the_checkout(kit_dir, bare_python, tmp_path):
    kit_copy = shutil.copytree(kit_dir, tmp_path / "anywhere")
    # no module from the checkout (its virtual environment's packages may live inside it)
    where = ("import sys, course, agent, taskexp, env2d; "
             "print(sorted({m.__file__ for m in list(sys.modules.values()) "
             "if getattr(m, '__file__', None) and m.__file__.startswith(%r) "
             "and 'site-packages' not in m.__file__}))" % ROOT)
    res = subprocess.run([bare_python, "-c", where], cwd=kit_copy, capture_output=True, text=True)
    assert res.returncode == 0 and res.stdout.strip() == "[]", res.stdout + res.stderr

    blank = cli("all", ".", cwd=kit_copy, python=bare_python)
    assert blank.returncode == 1 and blank.stderr == "", blank.stderr
    total, count = sum(exercises.POINTS.values()), len(exercises.NOTEBOOKS)
    assert blank.stdout.strip().splitlines()[-1].startswith(
        f"total: 0/{total} points; 0 of {count} exercises pass"), blank.stdout

    kit.paste_solutions(kit_copy)
    full = cli("all", ".", cwd=kit_copy, python=bare_python)
    assert full.returncode == 0, full.stdout + full.stderr
    assert full.stdout.strip().splitlines()[-1] == \
        f"total: {total}/{total} points; {count} of {count} exercises pass"
    assert [line.split()[:2] for line in full.stdout.splitlines() if "PASS" in line] == [
        [ex, "PASS:"] for ex in exercises.NOTEBOOKS]


def test_usage_shows_the_instructor_commands_only_in_the_repository(kit_dir):
    """A student who types `python -m course` in the kit reads the commands they can run; the
    instructor commands (release, course) need the reference solutions, which a kit lacks."""
    repository, student = cli(), cli(cwd=kit_dir)
    for res in (repository, student):
        assert res.returncode == 2 and res.stdout == "", res.stdout
        assert "ex1 .. ex6, ex8 .. ex11 NOTEBOOK" in res.stderr and "all FOLDER" in res.stderr
    assert "release OUT" in repository.stderr and "course DIR" in repository.stderr
    assert "release" not in student.stderr and "course DIR" not in student.stderr, \
        student.stderr


def paths_named(text):
    """The file paths a text names in backticks: words with a folder or a file ending."""
    words = re.findall(r"`([^`\s]+)`", text)
    return {w for w in words if re.fullmatch(r"[\w./-]+\.(py|ipynb|json|txt|md)|[\w.-]+/[\w./-]*",
                                             w)}


def test_a_kit_notebook_names_no_file_the_kit_lacks(kit_dir):
    """What a student reads in a kit names only files the kit has (a path from the kit's root, or
    from the course folder), and the test sees a path that is missing."""
    for name in exercises.NOTEBOOKS.values():
        with open(os.path.join(kit_dir, name)) as f:
            text = "\n".join("".join(c["source"]) for c in json.load(f)["cells"]
                             if c["cell_type"] == "markdown")
        missing = [p for p in paths_named(text) if not any(
            os.path.exists(os.path.join(kit_dir, where, p)) for where in ("", "course"))]
        assert missing == [], (name, missing)
    assert paths_named("run `python x.py`, see `course/notebooks/measure_ex7.py` and "
                       "`tests/`") == {"course/notebooks/measure_ex7.py", "tests/"}
