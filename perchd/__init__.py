"""perchd: fly a vehicle onto a surface along a time-to-contact (tau) plan."""

import os
import sys

# One BLAS/OpenMP thread per process unless the user asks for more: the planner's small
# dense solves gain nothing from a pool, and on a busy flight PC the pool's threads fight
# other programs for cores and slow every solve several-fold. Set before numpy loads, and
# inherited by every child (a campaign's workers). docs/architecture.md "Threads and timing".
BLAS_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
if not any(os.environ.get(var) for var in BLAS_THREAD_VARS):  # any one set: the user's choice
    os.environ.update(dict.fromkeys(BLAS_THREAD_VARS, "1"))
    if "numpy" in sys.modules:
        # A program that imported numpy before perchd started its pools already: the
        # variables came too late, so limit the loaded libraries themselves.
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)

__version__ = "0.1.0"
