"""Figures draw off-screen, and BLAS has one thread for every test, as in a run."""
import matplotlib

from taskexp_lib import one_blas_thread

matplotlib.use("Agg")
one_blas_thread()
