"""The README's times, from one place: lab/results/times.json, measured on one named machine with
the code they describe.

    python lab/bench/times.py --measure smoke default tests   # alone on the machine: ~25 min
    python lab/bench/times.py --readme README.md             # write them into the README

--measure times each command the README gives, one after the other, each alone: the smoke test,
the default run (both in a temporary folder), and the tests as CI runs them (.ci/run, on a clean
clone of this checkout's HEAD: a fresh virtual environment, installed as the README says). It
records the wall time, the machine, the date and the commit in times.json, keeping what it did not
measure. The README shows them between its markers, with how much slower a slower machine here
was (SLOWER: the same code's tests on two machines), and tests/test_bench.py checks that it does.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from headline import write_readme  # noqa: E402
from reproduce import machine  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
TIMES = os.path.join(ROOT, "lab", "results", "times.json")
BEGIN = "<!-- times: written by `python lab/bench/times.py --readme README.md` -->"
END = "<!-- end of the times -->"
# The README's commands, as a newcomer types them (run from the checkout, in its venv)
COMMANDS = {"smoke": ["python", "taskexp.py", "--rounds", "1", "--scale", "0.05"],
            "default": ["python", "taskexp.py", "--rounds", "3"],
            "tests": [".ci/run"]}
# The same code's tests on two machines of this workplace, both alone (lab/notes.md, 2026-12-06):
# how much slower a slower machine was
SLOWER = {"what": "the tests of main 1f5545a", "fast_s": 448, "slow_s": 1048}


def measure(what):
    """Wall seconds of the README's command `what`, run alone: a run in a temporary folder, the
    tests on a clean clone of HEAD."""
    with tempfile.TemporaryDirectory() as tmp:
        if what == "tests":
            subprocess.run(["git", "clone", "-q", ROOT, tmp], check=True)
            cwd, cmd = tmp, COMMANDS[what]
        else:
            cwd, cmd = ROOT, [sys.executable, *COMMANDS[what][1:], "--out",
                              os.path.join(tmp, "run")]
        t0 = time.perf_counter()
        subprocess.run(cmd, cwd=cwd, check=True, stdout=subprocess.DEVNULL)
        return time.perf_counter() - t0


def load():
    with open(TIMES) as f:
        return json.load(f)


def minutes(seconds):
    return f"{seconds / 60:.0f} minutes" if seconds >= 120 else f"{seconds:.0f} s"


def readme_lines(times):
    """The README's block: the two commands (and the smoke test) with their times, and where and
    when they were measured."""
    t = {what: minutes(times[what]["seconds"]) for what in COMMANDS}
    made = {(times[w]["commit"], times[w]["machine"].split(",")[0], times[w]["date"])
            for w in COMMANDS}
    if len(made) != 1:
        raise SystemExit(f"{TIMES}: measured with other code or machines {sorted(made)}: "
                         "measure all three again")
    (commit, where, date), = made
    slower = SLOWER["slow_s"] / SLOWER["fast_s"]
    return ["    python3 -m venv .venv && . .venv/bin/activate && pip install -e .",
            "    python taskexp.py --rounds 1 --scale 0.05     # the smoke test: about "
            f"{t['smoke']}",
            f"    python taskexp.py --rounds 3                  # the default run: about "
            f"{t['default']} on 2 cores",
            "    pip install -r requirements-dev.txt && python -m pytest -q     # the tests: about "
            f"{t['tests']}",
            "",
            f"The times were measured with the code they describe (main {commit}), each alone, "
            f"on {where} ({date}).",
            f"Machines here differ: {SLOWER['what']} took {slower:.1f}x as long on a slower one "
            f"({SLOWER['slow_s']} s against {SLOWER['fast_s']} s)."]


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--measure", nargs="+", choices=tuple(COMMANDS), default=[])
    p.add_argument("--readme", help="write the times into this README, between its markers")
    a = p.parse_args()
    times = load() if os.path.exists(TIMES) else {}
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, check=True,
                            capture_output=True, text=True).stdout.strip()
    if a.measure and subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                                    cwd=ROOT, capture_output=True, text=True).stdout:
        raise SystemExit("commit first: the times name the commit they were measured with")
    for what in a.measure:
        seconds = measure(what)
        times[what] = dict(seconds=round(seconds), command=" ".join(COMMANDS[what]),
                           machine=machine(), date=time.strftime("%Y-%m-%d"), commit=commit)
        print(f"{what}: {seconds:.0f} s")
        with open(TIMES, "w") as f:
            json.dump(times, f, indent=1)
    if a.readme:
        write_readme(a.readme, readme_lines(load()), BEGIN, END)
        print("wrote the times into", a.readme)


if __name__ == "__main__":
    main()
