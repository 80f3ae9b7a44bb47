"""The paper's Table 1 cases and the plan files in plans/ made from them.

`python -m perchd.tau.cases plans/` regenerates every file; tests compare against it.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

from perchd.tau.ctds import plan_ctds
from perchd.tau.ctdts import plan_ctdts
from perchd.tau.ipts import plan_ipts
from perchd.tau.limits import Limits
from perchd.tau.plan import Plan
from perchd.tau.planfile import save_plan


@dataclass(frozen=True)
class Case:
    """Trigger x0 [m], v0 [m/s]; tau_s [s]; V_c range [m/s]; v_max [m/s]; a_max [m/s^2];
    ctdts_v_c: the single contact speed the paper gives CTDTS in this case."""

    name: str
    x0: float
    v0: float
    tau_s: float
    v_contact: tuple[float, float]
    v_max: float
    a_max: float
    ctdts_v_c: float


CASES = (
    Case("case1", -3.0, 1.5, -0.5, (0.7, 1.0), 2.5, 1.4, 1.0),
    Case("case2", -3.0, 1.5, -0.5, (0.7, 1.0), 2.0, 1.0, 0.94),
)
FILES = ("ctds", "ctdts", "ipts-n3", "ipts-n5", "ipts-n8")


def make(case: Case, kind: str) -> Plan:

    if kind == "ctds":
        return plan_ctds(case.x0, case.v0, 0.5, Limits((0.0, 0.0), case.v_max, case.a_max))
    if kind == "ctdts":
        return plan_ctdts(
            case.x0, case.v0, case.tau_s, case.ctdts_v_c, case.a_max, case.v_max, case.v_contact
        )
    order = int(kind.split("-n")[1])
    return plan_ipts(case.x0, case.v0, case.tau_s, case.v_contact, case.v_max, case.a_max, order)


def write_all(folder: Path) -> list[Path]:

    written = []
    for case in CASES:
        for kind in FILES:
            path = folder / f"{case.name}-{kind}.json"
            save_plan(make(case, kind), path)
            written.append(path)
    return written


if __name__ == "__main__":
    for p in write_all(Path(sys.argv[1] if len(sys.argv) > 1 else "plans")):
        print(p)
