"""The code's layout: the method in the paper's order, three floors, one job per file, no import
cycle, no module loaded twice.

    ground floor   taskexp_lib/   layers, networks, features, geometry, config, checkpoints,
                                  episodes, drawing: imports none of the floors above
    the method     taskexp.py, env2d.py, agent.py
    above it       taskexp_cli/   the command line and the reports

The wheel installs these three floors; the course (course/) and the lab (lab/bench/) use them,
and they use neither. The import graph is read from the syntax trees, so the test needs nothing
run. A file run as a program (`python taskexp.py`, `python -m course`) is a module of its own,
`__main__`: its `if __name__ == "__main__"` block is part of that module, not of the one that
other files import.
"""
import ast
import glob
import os
import subprocess
import sys
import textwrap

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# taskexp.py defines the paper's functions in the paper's order: sec 4.1, 4.2 (its three steps,
# then the round), 4.3, 5, and last the loop that calls them, whose body fits on one screen
PAPER_ORDER = ("base_demos", "base_skills", "alter", "select_goal", "relabel", "task_expansion",
               "self_distill", "evaluate", "train")
LOOP_LINES = 30
METHOD = ("taskexp", "env2d", "agent")
FLOORS = {"taskexp_lib": 0, **{m: 1 for m in METHOD}, "taskexp_cli": 2}


def module_files(folders=("taskexp_lib", "taskexp_cli", "course")):
    """{module name: path} of the three modules and every module of the packages `folders`."""
    files = {m: os.path.join(ROOT, f"{m}.py") for m in METHOD}
    for folder in folders:
        for path in glob.glob(os.path.join(ROOT, folder, "*.py")):
            parts = os.path.relpath(path, ROOT)[:-3].split(os.sep)
            files[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return files


def lab_scripts():
    """{"lab:name": path} of the lab's scripts, run as programs from lab/bench/."""
    return {f"lab:{os.path.basename(p)[:-3]}": p
            for p in glob.glob(os.path.join(ROOT, "lab", "bench", "*.py"))}


def imports(module, path, known):
    """(the known modules `module` imports when imported, and those its `if __name__ ==
    "__main__"` block imports when the file runs as the program)."""
    tree = ast.parse(open(path).read())
    package = module if path.endswith("__init__.py") else module.rpartition(".")[0]
    guards = [n for n in tree.body if isinstance(n, ast.If) and "__main__" in ast.unparse(n.test)]
    in_guard = {id(n) for guard in guards for n in ast.walk(guard)}
    found, found_main = set(), set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parent + ([base] if base else []))
            names = [base] + [f"{base}.{a.name}" for a in node.names]
        else:
            continue
        (found_main if id(node) in in_guard else found).update(n for n in names if n in known)
    # a package is loaded before its modules anyway: a module naming its own package (from .
    # import x) is no cycle
    own = lambda names: {n for n in names if n != module and not module.startswith(n + ".")}
    return own(found), own(found_main)


def import_graph():
    """{module: modules it imports}, with a node "__main__:m" for each file m that runs as a
    program: what running it imports (its module's imports and its main block's)."""
    files = {**module_files(), **lab_scripts()}
    known = set(files) | {m.split(":")[1] for m in files if m.startswith("lab:")}
    graph = {}
    for m, p in files.items():
        plain, main = imports(m, p, known)
        graph[m] = plain
        if main or m.startswith("lab:") or m.endswith("__main__"):
            graph[f"__main__:{m}"] = plain | main
    for m in graph:                        # a lab script imports its neighbours by bare name
        graph[m] = {f"lab:{n}" if f"lab:{n}" in files else n for n in graph[m]}
    return graph


def floor(module):
    """0, 1 or 2 for the product's modules, None for the course and the lab."""
    return FLOORS.get(module.split(".")[0])


def out_of_order(source):
    """What keeps a method file's source from reading as the paper: a function of PAPER_ORDER
    missing or defined before the one it follows, or train's body (after its docstring) longer
    than LOOP_LINES lines -> a list of reasons (empty: none)."""
    functions = {n.name: n for n in ast.parse(source).body if isinstance(n, ast.FunctionDef)}
    wrong = [f"{name} is not defined" for name in PAPER_ORDER if name not in functions]
    found = [name for name in PAPER_ORDER if name in functions]
    wrong += [f"{b} comes before {a}" for a, b in zip(found, found[1:])
              if functions[b].lineno < functions[a].lineno]
    if "train" in functions:
        body = functions["train"].body[1:]
        lines = body[-1].end_lineno - body[0].lineno + 1 if body else 0
        if lines > LOOP_LINES:
            wrong.append(f"train's body takes {lines} lines, more than {LOOP_LINES}")
    return wrong


def test_the_method_reads_in_the_papers_order():
    with open(os.path.join(ROOT, "taskexp.py")) as f:
        assert out_of_order(f.read()) == []


def test_the_order_test_sees_a_function_out_of_place_and_a_long_loop():
    defs = {name: f"def {name}():\n    'doc'\n    pass\n" for name in PAPER_ORDER}
    assert out_of_order("".join(defs.values())) == []
    swapped = dict(defs, alter=defs["select_goal"], select_goal=defs["alter"])
    assert out_of_order("".join(swapped.values())) == ["select_goal comes before alter"]
    long = dict(defs, train="def train():\n    'doc'\n" + "    pass\n" * (LOOP_LINES + 1))
    assert out_of_order("".join(long.values())) == [
        f"train's body takes {LOOP_LINES + 1} lines, more than {LOOP_LINES}"]
    assert out_of_order("") == [f"{name} is not defined" for name in PAPER_ORDER]


def cycle(graph):
    """An import cycle of `graph` as a list of modules, or None."""
    done, path = set(), []

    def visit(m):                                  # depth first; a module met on its own path
        if m in path:                              # closes a cycle
            return path[path.index(m):] + [m]
        if m not in done:
            path.append(m)
            for n in sorted(graph.get(m, ())):
                if found := visit(n):
                    return found
            path.pop()
            done.add(m)
    return next((c for m in sorted(graph) if (c := visit(m))), None)


def upward(graph):
    """The imports of `graph` that go up a floor or out of the product. A main block of the
    method may hand over to the command line: that is taskexp.py's program, not its module."""
    wrong = []
    for m, deps in graph.items():
        name = m.split(":")[-1]
        program_of_the_method = m.startswith("__main__:") and name in METHOD
        if floor(name) is None:
            continue
        wrong += [f"{m} imports {d}" for d in sorted(deps) if floor(d) is None
                  or (floor(d) > floor(name) and not program_of_the_method)]
    return wrong


def test_no_import_cycle_main_blocks_included():
    graph = import_graph()
    assert graph["taskexp_lib.nn"] == set(), "the layers import numpy only"
    assert cycle(graph) is None, "import cycle: " + " -> ".join(cycle(graph))


def test_each_floor_imports_only_the_floors_under_it():
    """The product never imports the course or the lab, and no floor imports one above it."""
    assert upward(import_graph()) == []


def test_the_layout_tests_see_a_cycle_in_a_main_block_and_an_upward_import(tmp_path):
    """The two tests above can fail: a cycle closed only by a main block, and a ground-floor
    module importing the method, are both found."""
    cli = tmp_path / "cli.py"
    cli.write_text("import taskexp\nif __name__ == '__main__':\n    import course\n")
    assert imports("taskexp_cli.x", str(cli), {"taskexp", "course"}) == ({"taskexp"}, {"course"})
    graph = {"a": {"b"}, "b": set(), "__main__:b": {"a"}}
    assert cycle(graph) is None
    assert cycle({**graph, "b": {"a"}}) == ["a", "b", "a"]
    graph = {**import_graph(), "taskexp_lib.nn": {"agent"}, "__main__:taskexp_lib.nn": {"course"}}
    assert upward(graph) == ["taskexp_lib.nn imports agent",
                             "__main__:taskexp_lib.nn imports course"]
    assert upward({"__main__:taskexp": {"taskexp_cli"}, "taskexp": {"taskexp_cli"}}) == [
        "taskexp imports taskexp_cli"]


def test_python_taskexp_py_defines_the_method_once():
    """`python taskexp.py` runs the file as __main__, and the CLI imports it as taskexp: the
    method's classes must exist once, not once per copy of the module. (Garbage collection is
    off, so a second copy, had there been one, would still be there to count.)"""
    code = textwrap.dedent("""
        import gc, runpy, sys
        gc.disable()
        sys.argv = ["taskexp.py", "--help"]
        try:
            runpy.run_path("taskexp.py", run_name="__main__")
        except SystemExit as e:
            assert e.code in (0, None), e.code
        print(sum(isinstance(o, type) and o.__name__ == "RunState" for o in gc.get_objects()))
    """)
    res = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "--rounds" in res.stdout and res.stdout.split()[-1] == "1", res.stdout[-500:]
