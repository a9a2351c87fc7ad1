"""Are two runs the same? Compares what `python taskexp.py` wrote in two run directories.

    python lab/bench/compare_runs.py runs/before runs/after

Same means: results.json equal apart from the wall-clock figures (settings that only one of the two
records, such as a Config field added later, are listed, not compared), and every array of every
round{k}.npz of the first run bit-identical in the second (header keys added later are listed).
Prints SAME or DIFFERENT with what differs; exits 1 when different.
"""
import argparse
import glob
import json
import os
import sys

import numpy as np


def compare(old, new):
    """-> list of differences (empty: the same) and a list of notes."""
    diffs, notes = [], []
    results = []
    for d in (old, new):
        with open(os.path.join(d, "results.json")) as f:
            results.append(json.load(f))
    (ro, rn), (co, cn) = results, (results[0].pop("config"), results[1].pop("config"))
    for r in results:
        r.pop("wallclock", None)
    only = sorted(set(co) ^ set(cn))
    if only:
        notes.append(f"settings recorded by one run only: {only}")
    diffs += [f"config {k}: {co[k]!r} vs {cn[k]!r}" for k in sorted(set(co) & set(cn))
              if co[k] != cn[k]]
    if ro != rn:
        diffs.append("results.json differs")
    checkpoints = sorted(glob.glob(os.path.join(old, "round*.npz")))
    for path in checkpoints:
        other = os.path.join(new, os.path.basename(path))
        if not os.path.exists(other):
            diffs.append(f"{os.path.basename(path)} missing in {new}")
            continue
        with np.load(path) as a, np.load(other) as b:
            added = sorted(set(b.files) - set(a.files))
            if added:
                notes.append(f"{os.path.basename(path)}: keys only in the second: {added}")
            for k in a.files:
                same = k in b.files and a[k].dtype == b[k].dtype and a[k].shape == b[k].shape \
                    and a[k].tobytes() == b[k].tobytes()
                if not same and k != "format_version":
                    diffs.append(f"{os.path.basename(path)}: {k}")
    notes.append(f"{len(checkpoints)} checkpoints compared")
    return diffs, notes


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("first")
    p.add_argument("second")
    a = p.parse_args()
    diffs, notes = compare(a.first, a.second)
    print(("DIFFERENT" if diffs else "SAME") + f": {a.first} vs {a.second}")
    for line in diffs[:20] + notes:
        print("  " + line)
    sys.exit(1 if diffs else 0)


if __name__ == "__main__":
    main()
