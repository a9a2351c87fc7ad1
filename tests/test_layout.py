"""The code's layout: one job per file, no import cycle, no module loaded twice.

The library is the three modules of the design (taskexp.py, env2d.py, agent.py) and the package
taskexp_lib/; the import graph is read from the syntax trees, so the test needs nothing run.
"""
import ast
import os
import subprocess
import sys
import textwrap

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MAX_LINES = 500


def library_files():
    """{module name: path} of every library module."""
    files = {m: os.path.join(ROOT, f"{m}.py") for m in ("taskexp", "env2d", "agent")}
    for folder, _, names in os.walk(os.path.join(ROOT, "taskexp_lib")):
        for name in names:
            if name.endswith(".py"):
                path = os.path.join(folder, name)
                parts = os.path.relpath(path, ROOT)[:-3].split(os.sep)
                files[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return files


def imports(module, path, known):
    """The library modules that `module` imports, anywhere but under `if __name__ == "__main__"`
    (which runs only when the file is the program)."""
    tree = ast.parse(open(path).read())
    package = module if path.endswith("__init__.py") else module.rpartition(".")[0]
    main_guards = [n for n in tree.body
                   if isinstance(n, ast.If) and "__main__" in ast.unparse(n.test)]
    skip = {id(n) for guard in main_guards for n in ast.walk(guard)}
    found = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
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
        found |= {n for n in names if n in known and n != module}
    # a package is loaded before its modules anyway: a module naming its own package (from .
    # import x) is no cycle
    return {n for n in found if not module.startswith(n + ".")}


def test_no_library_file_is_longer_than_500_lines():
    long = {m: n for m, p in library_files().items() if (n := len(open(p).readlines())) > MAX_LINES}
    assert not long, f"over {MAX_LINES} lines: {long}"


def test_the_library_has_no_import_cycle():
    files = library_files()
    graph = {m: imports(m, p, files) for m, p in files.items()}
    assert graph["taskexp_lib.nn"] == set(), "the layers import numpy only"
    done, path = set(), []

    def visit(m):                                  # depth first; a module met on its own path
        if m in path:                              # closes a cycle
            raise AssertionError("import cycle: " + " -> ".join(path[path.index(m):] + [m]))
        if m not in done:
            path.append(m)
            for n in sorted(graph[m]):
                visit(n)
            path.pop()
            done.add(m)
    for m in sorted(graph):
        visit(m)


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
