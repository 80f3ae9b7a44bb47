"""The paper's case-1 IPTS plan for the driver tests that fly."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PLAN_FILE = ROOT / "plans" / "case1-ipts-n3.json"


def case1_ipts():
    """The paper's case-1 IPTS plan: from perchd.tau's plan file once it exists, else the
    closed-loop tests' closed-form reference."""
    try:
        from perchd.tau import load_plan
        if PLAN_FILE.exists():
            return load_plan(PLAN_FILE)
    except ImportError:
        pass
    spec = importlib.util.spec_from_file_location("refplans_for_hil", ROOT / "tests/closedloop/refplans.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module.ipts()
