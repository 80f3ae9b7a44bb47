"""perchd: fly a vehicle onto a surface along a time-to-contact (tau) plan."""

import os

# One BLAS/OpenMP thread per process unless the user asks for more: the planner's small
# dense solves gain nothing from a pool, and on a busy flight PC the pool's threads fight
# other programs for cores and slow every solve several-fold. Set before numpy loads.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

__version__ = "0.1.0"
