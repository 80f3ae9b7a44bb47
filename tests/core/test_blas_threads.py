"""Every perchd process runs its BLAS/OpenMP libraries on one thread, as threadpoolctl sees
them, however numpy came to be loaded; a user who sets the variables gets what they set."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from perchd import BLAS_THREAD_VARS

ROOT = Path(__file__).resolve().parents[2]
REPORT = (
    "import json, threadpoolctl; "
    "print(json.dumps([p['num_threads'] for p in threadpoolctl.threadpool_info()]))"
)


def pools(code: str, **env: str) -> list[int]:
    """Thread counts of every pool threadpoolctl finds in a fresh interpreter running `code`."""
    environ = {k: v for k, v in os.environ.items() if k not in BLAS_THREAD_VARS}
    environ.update(env, PYTHONPATH=str(ROOT))
    out = subprocess.run(
        [sys.executable, "-c", f"{code}; {REPORT}"],
        env=environ,
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    return json.loads(out.stdout.splitlines()[-1])


def test_a_perchd_process_has_one_blas_thread_in_every_pool():
    found = pools("import perchd.tau, numpy, scipy.linalg")
    assert found and set(found) == {1}


def test_numpy_imported_before_perchd_is_limited_too():
    """An embedding program loaded numpy (and its pool) before perchd set the variables."""
    before = pools("import numpy")
    found = pools("import numpy, perchd")
    assert found and set(found) == {1}
    if os.cpu_count() and os.cpu_count() > 1:
        assert max(before) > 1  # the case reproduced: without perchd numpy starts a pool


@pytest.mark.parametrize("var", ["OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"])
def test_a_user_who_sets_the_threads_gets_them(var):
    """Offline work (`plan library`, a campaign's workers) may want a bigger pool."""
    found = pools("import perchd, numpy", **{var: "2"})
    assert 2 in found
