"""The paper's case plans as perchd flies them, from plans/."""

from __future__ import annotations

from pathlib import Path

from perchd.tau import load_plan
from perchd.tau.plan import Plan

PLANS = Path(__file__).resolve().parents[2] / "plans"


def case1(strategy: str) -> Plan:
    """The paper's case-1 plan: plans/case1-ctdts.json or plans/case1-ipts-n3.json."""
    return load_plan(PLANS / {"ctdts": "case1-ctdts.json", "ipts": "case1-ipts-n3.json"}[strategy])


def case1_ipts() -> Plan:
    return case1("ipts")
