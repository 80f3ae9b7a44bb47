"""perchd: fly a vehicle onto a surface along a time-to-contact (tau) plan."""

import os
import sys


def _is_the_command() -> bool:
    """This process runs `perchd` itself: its console script, or `python -m perchd` (while
    the package is imported for that, sys.argv[0] is "-m" and sys.orig_argv names it)."""
    argv = sys.argv
    if not argv:
        return False
    if argv[0] == "-m":
        module = sys.orig_argv[-len(argv)] if len(sys.orig_argv) >= len(argv) else ""
        return module == "perchd" or (module.startswith("-") and module.endswith("mperchd"))
    return os.path.basename(argv[0]) == "perchd"


# The command takes SIGINT and SIGTERM from here to its exit (perchd/core/command_signals.py);
# nothing here runs code that looks at signals before the `try`.
_command = None
try:
    _command = _is_the_command()
    if _command:
        from perchd.core import command_signals

        command_signals.take()
except KeyboardInterrupt:  # a Ctrl-C that came before the handler was in place
    # the line is made here, not by command_signals: its import may be what was cut short
    if _command is None:
        _command = _is_the_command()
    if not _command:
        raise
    _name = next((f" {a}" for a in sys.argv[1:] if not a.startswith("-")), "")
    os.write(2, f"perchd{_name}: interrupted\n".encode(errors="backslashreplace"))
    os._exit(130)

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
