"""The project installs like a package, and its code keeps the style the linter enforces.

The install test builds the checkout into a fresh virtual environment outside it (`pip install
--no-deps <checkout>`; the dependencies come from this environment through a .pth file, so the test
needs no download beyond the build backend), then, from a temporary folder, imports the world,
makes it through Gymnasium, checks it with warnings as errors, and runs the console script.
"""
import os
import shutil
import site
import subprocess
import sys
import textwrap
import zipfile

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_ruff_finds_nothing():
    ruff = shutil.which("ruff")
    assert ruff, "ruff is not installed: pip install -r requirements-dev.txt"
    res = subprocess.run([ruff, "check", "."], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr


@pytest.fixture(scope="module")
def fresh(tmp_path_factory):
    """(python, bin folder) of a fresh venv, outside the checkout, with the checkout installed."""
    venv = tmp_path_factory.mktemp("venv")
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    bin_dir = venv / ("Scripts" if os.name == "nt" else "bin")
    python = str(bin_dir / "python")
    where = "import sysconfig; print(sysconfig.get_paths()['purelib'])"
    purelib = subprocess.run([python, "-c", where], capture_output=True, text=True,
                             check=True).stdout.strip()
    # numpy, pymunk, ... from this environment (a path line in a .pth; its own .pth files stay off)
    with open(os.path.join(purelib, "outer_deps.pth"), "w") as f:
        f.write("\n".join(site.getsitepackages()) + "\n")
    res = subprocess.run([python, "-m", "pip", "install", "-q", "--no-deps", ROOT],
                         cwd=venv, capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr
    return python, bin_dir


def test_installed_world_registers_with_gymnasium_and_passes_check_env(fresh, tmp_path):
    python, _ = fresh
    code = textwrap.dedent("""
        import warnings
        import gymnasium, env2d
        from gymnasium.utils.env_checker import check_env
        assert not env2d.__file__.startswith(%r), env2d.__file__       # the installed copy
        env = gymnasium.make("taskexp/BlockWorld-v0", n_blocks=7)
        assert env.unwrapped.n_blocks == 7
        assert env.unwrapped.drop, "the world the method uses drops its blocks"
        assert not gymnasium.make("taskexp/BlockWorld-v0", drop=False).unwrapped.drop
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            for drop in (True, False):
                check_env(gymnasium.make("taskexp/BlockWorld-v0", drop=drop).unwrapped)
        import importlib, pkgutil, taskexp, agent, taskexp_lib, taskexp_cli  # every module imports
        for package in (taskexp_lib, taskexp_cli):
            for m in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
                importlib.import_module(m.name)
        print("ok")
    """ % ROOT)
    res = subprocess.run([python, "-c", code], cwd=tmp_path, capture_output=True, text=True)
    assert res.returncode == 0 and res.stdout.strip() == "ok", res.stdout + res.stderr


def test_installed_console_script_prints_its_help(fresh, tmp_path):
    _, bin_dir = fresh
    res = subprocess.run([str(bin_dir / "taskexp"), "--help"], cwd=tmp_path, capture_output=True,
                         text=True)
    assert res.returncode == 0, res.stderr
    assert "--rounds" in res.stdout and "--ppo-steps" in res.stdout


def test_the_wheel_installs_only_the_three_modules_and_the_project_packages(tmp_path):
    """The three floors (not the course, not the lab), and no generic top-level name (config,
    cli, exercises ...) that another package could shadow."""
    # from a copy: a build/ folder left in the checkout by an earlier build could add stale files
    src = tmp_path / "src"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(
        ".*", "build", "*.egg-info", "runs", "release", "__pycache__", "notebooks", "docs"))
    res = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w",
                          str(tmp_path), str(src)], capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr
    (wheel,) = tmp_path.glob("taskexp-*.whl")
    with zipfile.ZipFile(wheel) as z:
        top = {name.split("/")[0].removesuffix(".py") for name in z.namelist()
               if ".dist-info/" not in name}
    assert top == {"taskexp", "env2d", "agent", "taskexp_lib", "taskexp_cli"}
