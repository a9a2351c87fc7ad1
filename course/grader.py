"""course/grader.py -- what every check is made of: a report of its cases, the calls
of a student's functions, the comparisons, and the stand-in world of exercises 5 and 6.

A check (exN.py) runs the student's functions on fixed cases of varied shapes plus edge cases
and compares them with the reference solution. It prints one PASS line and returns None, or
raises an AssertionError whose message gives the first failing case, expected vs got, and a
hint. Every case has its own seed, so a check is deterministic.

A case's inputs and expected outputs come from its make() function, run on the library
(reference.py) in the repository; a student kit, whose library has stubs, reads them from
recorded test vectors (vectors.py). The comparisons and hints are the same code in both.
"""
import contextlib
import copy
import functools
import sys
import traceback
import warnings
from types import SimpleNamespace

import numpy as np

from taskexp_lib.geometry import TABLE_X, THRESHOLD, X_BINS, layer_y


def tiny_env(n_blocks):
    """What ex5/ex6 may use of a BlockWorld: n_blocks, x_bins (37,), y_bins (n_blocks,), table_x,
    threshold; all from taskexp_lib/geometry.py."""
    return SimpleNamespace(n_blocks=n_blocks, x_bins=X_BINS.copy(),
                           y_bins=layer_y(np.arange(n_blocks)),
                           table_x=TABLE_X, threshold=THRESHOLD)


class Report:
    """Collects failing cases; done() prints PASS, or raises AssertionError with the first
    failure in detail."""

    def __init__(self, name):
        self.name, self.failures, self.cases = name, [], 0

    def case(self, name, detail, problem, hint):
        """One case: its name, its inputs (shapes, seed), what went wrong (None: ok), a hint."""
        self.cases += 1
        if problem:
            self.failures.append((name, detail, problem, hint))

    def done(self, extra=""):
        if not self.failures:
            print(f"{self.name} PASS: {self.cases} case{'s' * (self.cases != 1)}{extra}")
            return
        name, detail, problem, hint = self.failures[0]
        lines = [f"{self.name} FAIL: case {name!r} ({detail})", f"  {problem}"]
        if hint and "NotImplementedError" not in problem:
            lines.append(f"  hint: {hint}")
        if len(self.failures) > 1:
            others = list(dict.fromkeys(f[0] for f in self.failures[1:]))
            lines.append(f"  ({len(self.failures)} of {self.cases} cases failed; "
                         f"also: {'; '.join(others[:5])})")
        raise AssertionError("\n".join(lines))


def graded(check):
    """What a graded notebook cell runs. nbgrader gives no points to a graded cell that writes to
    stderr, even when the check passes, so the check's warnings (numpy's, on a student's overflow)
    and anything written to sys.stderr go to stdout; a warning is reported once, as a note."""
    @functools.wraps(check)
    def run(*args, **kwargs):
        with warnings.catch_warnings(record=True) as caught, \
                contextlib.redirect_stderr(sys.stdout):
            warnings.simplefilter("always")
            try:
                check(*args, **kwargs)
            except AssertionError as failed:    # raised again here: a traceback of two frames,
                raise AssertionError(str(failed)) from None     # the cell's and this line
            finally:
                seen = list(dict.fromkeys(f"{w.category.__name__}: {w.message}" for w in caught))
                if seen:
                    print(f"  note: {len(caught)} warning{'s' * (len(caught) > 1)} while checking"
                          f", e.g. {seen[0]}")
    return run


def passes(check, *args, **kwargs):
    """check(*args) -> True if it passes, False if it fails (its message printed)."""
    try:
        check(*args, **kwargs)
        return True
    except AssertionError as e:
        print(e)
        return False


NOT_DONE = ("raised NotImplementedError: not done yet "
            "(replace `raise NotImplementedError()` by your code)")


def call(fn, *args, **kw):
    """fn(*args) -> (result, None), or (None, what it raised) -- a student's code may raise."""
    try:
        return fn(*copy.deepcopy(args), **kw), None    # copies: the student cannot spoil our inputs
    except NotImplementedError as e:                   # with a message: the exercise it needs
        return None, f"raised NotImplementedError: {e}" if str(e) else NOT_DONE
    except Exception as e:                          # point at the student's line, not at numpy's
        frames = [f for f in traceback.extract_tb(e.__traceback__)[1:]
                  if "site-packages" not in f.filename]
        at = f" at {frames[-1].filename}, line {frames[-1].lineno}" if frames else ""
        code = f": {frames[-1].line}" if frames and frames[-1].line else ""
        return None, f"raised {type(e).__name__}: {e}{at}{code}"


def diff(name, got, want, rtol=1e-6, atol=1e-8):
    """None when got matches want (shape and values), else one line: where, got vs expected."""
    want = np.asarray(want, dtype=np.float64)
    try:
        got = np.asarray(got, dtype=np.float64)
    except (TypeError, ValueError):
        return (f"{name}: got {type(got).__name__} {str(got)[:60]}, "
                f"expected an array of shape {want.shape}")
    if got.shape != want.shape:
        return f"{name}: shape {got.shape}, expected {want.shape}"
    bad = ~np.isclose(got, want, rtol=rtol, atol=atol)
    if not bad.any():
        return None
    i = tuple(int(k) for k in np.argwhere(bad)[0])
    sign = ("  (got = -expected: a sign error?)"
            if np.allclose(got, -want, rtol, atol) and want.any() else "")
    return (f"{name}: {bad.sum()} of {bad.size} entries differ; first at {i}: "
            f"got {got[i]:.6g}, expected {want[i]:.6g}{sign}")


def call_backward(fn, *args, keys):
    """Call a student's backward pass -> ((grads, dx), None), or (None, what is wrong): it raised,
    it did not return a tuple (grads dict, dx), or grads lacks one of `keys` (the first named)."""
    res, err = call(fn, *args)
    if err is None and not (isinstance(res, tuple) and len(res) == 2 and isinstance(res[0], dict)):
        err = f"returned {type(res).__name__}, expected a tuple (grads dict, dx)"
    missing = [] if err else [k for k in keys if k not in res[0]]
    if missing:
        err = f"grads has no key {missing[0]!r}"
    return (None, err) if err else (res, None)


def first(*problems):
    """The first problem that is not None (the one a failing case reports)."""
    return next((p for p in problems if p), None)


def numerical_grad(f, x, eps=1e-6):
    """Central differences of the scalar f() w.r.t. every entry of the array x (changed in
    place)."""
    g = np.zeros_like(x)
    for i in np.ndindex(x.shape):
        old = x[i]
        x[i] = old + eps
        fp = f()
        x[i] = old - eps
        g[i] = (fp - f()) / (2 * eps)
        x[i] = old
    return g


class Wrong(Exception):
    """A failing case, raised by a step of a check: what went wrong and the hint."""

    def __init__(self, problem, hint):
        super().__init__(problem)
        self.problem, self.hint = problem, hint
