"""course/vectors.py -- where a check's cases come from: the library, or recorded
test vectors.

A case is data: its inputs and the expected outputs, a dict made by a `make()` function of the
check. In the repository, make() runs on the full library (the reference). A student kit has no
reference code (its exercised functions are stubs), so `python -m course release`
runs every make() once and writes the results into the kit as course/vectors.json:
the kit's checks read numbers, not answer code. A kit is recognised by that file.

JSON keeps the numbers exact (floats are written with repr, which reads back to the same float64)
and readable. Arrays, tuples and dicts with int keys (goals) are tagged so they read back as they
were.
"""
import json
import os
from contextlib import contextmanager

import numpy as np

FILE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "vectors.json")

_stored = None        # the kit's cases, read once
_recording = None     # {key: case} while release() records


def in_kit():
    """True in a student kit (the checks read recorded cases), False in the repository."""
    return os.path.exists(FILE)


def case(key, make):
    """The data of one case: recorded (in a kit) or make() (in the repository)."""
    global _stored
    if in_kit():
        if _stored is None:
            with open(FILE) as f:
                _stored = json.load(f)["cases"]
        if key not in _stored:
            raise KeyError(f"course/vectors.json has no case {key!r}: "
                           "this kit is older than its checks; ask for a new one")
        return decode(_stored[key])
    data = make()
    if _recording is not None:
        _recording[key] = encode(data)
    return data


@contextmanager
def recording():
    """Collect every case that the checks make while inside: -> the dict, filled on exit."""
    global _recording
    _recording = cases = {}
    try:
        yield cases
    finally:
        _recording = None


def encode(x):
    """A case -> plain JSON values."""
    if isinstance(x, np.ndarray):
        return {"array": x.tolist(), "dtype": str(x.dtype), "shape": list(x.shape)}
    if isinstance(x, dict):
        return {"dict": [[encode(k), encode(v)] for k, v in x.items()]}
    if isinstance(x, tuple):
        return {"tuple": [encode(v) for v in x]}
    if isinstance(x, list):
        return [encode(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    if x is None or isinstance(x, (bool, int, float, str)):
        return x
    raise TypeError(f"cannot record a {type(x).__name__} in a test vector")


def decode(x):
    """The inverse of encode."""
    if isinstance(x, list):
        return [decode(v) for v in x]
    if isinstance(x, dict):
        if "array" in x:
            return np.array(x["array"], dtype=x["dtype"]).reshape(x["shape"])
        if "tuple" in x:
            return tuple(decode(v) for v in x["tuple"])
        return {decode(k): decode(v) for k, v in x["dict"]}
    return x
