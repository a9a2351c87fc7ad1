"""Pin BLAS to one thread before numpy loads: tiny matmuls are faster and results reproducible."""
import os

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import matplotlib

matplotlib.use("Agg")
