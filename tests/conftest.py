"""Test-session set-up.

One BLAS thread per test process: the suite runs with ``pytest -n 2`` on two cores, and
multithreaded BLAS in each worker oversubscribes the cores, which makes the many small
least-squares solves of the tests orders of magnitude slower. Set before numpy loads.
"""

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
