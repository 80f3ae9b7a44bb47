"""A stop signal caught while the main thread holds the lock its callback takes
(perchd/core/interrupts.py): the command must still stop, not deadlock."""

from __future__ import annotations

import subprocess
import sys
import textwrap

# The main thread holds the Event's lock, as it does inside Event.wait, when SIGTERM
# arrives: a handler that set the Event itself would wait for that lock forever.
SCRIPT = textwrap.dedent("""
    import os, signal, threading
    from perchd.core.interrupts import catching
    done = threading.Event()
    with catching(done.set) as caught:
        with done._cond:
            os.kill(os.getpid(), signal.SIGTERM)
        assert done.wait(5.0)
    print(caught.name)
""")


def test_a_signal_caught_while_the_main_thread_holds_the_events_lock_still_stops():
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=20, check=False
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "SIGTERM"
