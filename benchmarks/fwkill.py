"""SIGKILL of `perchd fly` mid-approach on the vehicles' own firmware: how far each vehicle
goes on toward the wall, and what its autopilot does after.

    python benchmarks/fwkill.py [--kills N] [--speed V] [--only NAME ...] [--json]

The target for PX4: no further than 0.5 m toward the wall, then holding in place or
landed, never returning home (docs/safety.md, "The brake"). Each of N kills (default 3) per
firmware: the harness and `perchd fly` as benchmarks/firmware.py starts them (the same
environment variables name the binaries), the agent SIGKILLed once its flight log shows the
approach at V m/s (default 0.5) toward the wall, then AFTER_S of the mocap. Printed per
firmware: how far the vehicle went on toward the wall (median, max) from the mocap, the
speed at the kill, the height it ended at against the height it was killed at, and what
took over: the modes the autopilot went through after the offboard mode (MAVLink; the
sentinel's own account beside it), or when the Crazyflie's motors stopped. perchd's own
simulator has no row: it flies inside the agent and dies with it.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from firmware import (
    ENV,
    Firmware,
    add_selection,
    fly_argv,
    selected,
    start_harness,
    stop_harness,
)

AFTER_S = 8.0
"""[s] watched after the kill: PX4's COM_OF_LOSS_T, the sentinel's brake and LAND, a descent."""
NOISE_M = 0.001
TARGET_M = 0.5
"""[m] the target: no further toward the wall than this after the kill."""
OFFBOARD_MODES = ("OFFBOARD", "GUIDED_NOGPS")


def modes_after(sim: dict) -> list[str]:
    """The autopilot's modes after the last offboard one (PX4 names them, ArduCopter's
    harness keeps them with their times)."""
    names = [m["mode"] if isinstance(m, dict) else m for m in sim.get("modes", [])]
    last = max((i for i, m in enumerate(names) if m in OFFBOARD_MODES), default=-1)
    return names[last + 1 :]


def motors_off_after(sim: dict, killed: float) -> float | None:
    """[s] after the kill, the Crazyflie's motors last turning (the harness's truth track:
    [time.monotonic() s, z m, motors on]); None without a track."""
    on = [t for t, _, running in sim.get("track", []) if running and t > killed]
    return (on[-1] - killed) if on else (0.0 if "track" in sim else None)


def kill_once(fw: Firmware, binary: str, speed: float, tmp: Path) -> dict:
    from fwharness import YawWatch, after_kill, kill_at_speed, surface_normal

    proc, mocap, driver, surface = start_harness(fw, binary, NOISE_M, tmp)
    watch = YawWatch(mocap)
    try:
        with open(tmp / "fly.err", "w") as err:
            fly = subprocess.Popen(
                fly_argv(fw, tmp, mocap, driver, surface),
                env=ENV,
                stdout=subprocess.DEVNULL,
                stderr=err,
            )
            killed = kill_at_speed(fly, tmp / "flight.jsonl", speed, 90.0)
            if killed is not None:
                time.sleep(AFTER_S)
    finally:
        watch.close()
        sim = stop_harness(proc)
    said = (tmp / "fly.err").read_text()
    if killed is None:
        return {"killed": False, "said": said[-300:]}
    return {
        "killed": True,
        **after_kill(watch.positions, killed, surface_normal(surface)),
        "modes_after": modes_after(sim),
        "motors_off_s": motors_off_after(sim, killed),
        "sentinel": [ln.strip() for ln in said.splitlines() if "mavsentinel" in ln],
    }


def summary(kills: list[dict]) -> dict:
    done = [k for k in kills if k["killed"]]
    further = [k["further_toward_wall_m"] for k in done]
    return {
        "kills": len(kills),
        "killed": len(done),
        "within_target": sum(f <= TARGET_M for f in further),
        "further_median_m": statistics.median(further) if further else None,
        "further_max_m": max(further, default=None),
        "speed_mps": [round(k["speed_at_kill_mps"], 2) for k in done],
        "height_change_m": [round(k["final_height_m"] - k["height_at_kill_m"], 2) for k in done],
        "ends": sorted({" > ".join(k["modes_after"]) or "-" for k in done}),
        "motors_off_s": [
            round(k["motors_off_s"], 2) for k in done if k["motors_off_s"] is not None
        ],
    }


def fmt(v: float | None) -> str:
    return "-" if v is None else f"{v:.3f}"


def print_row(name: str, s: dict) -> None:
    print(
        f"{name}: killed {s['killed']}/{s['kills']} at {s['speed_mps']} m/s; further toward "
        f"the wall {fmt(s['further_median_m'])} m median, {fmt(s['further_max_m'])} max "
        f"({s['within_target']} within {TARGET_M} m); height change {s['height_change_m']} m"
    )
    if s["motors_off_s"]:
        print(f"    motors off {s['motors_off_s']} s after the kill")
    else:
        print(f"    then: {'; '.join(s['ends'])}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=3, help="kills per firmware (3)")
    ap.add_argument(
        "--speed",
        type=float,
        default=0.5,
        help="[m/s] kill once the approach flies this fast toward the wall (0.5)",
    )
    add_selection(ap, "kill")
    args = ap.parse_args()
    if args.kills < 1 or not 0.1 <= args.speed <= 1.5:
        print(
            "benchmarks/fwkill.py: --kills must be >= 1 and --speed 0.1..1.5 m/s", file=sys.stderr
        )
        return 2
    root = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="perchd-fwkill-"))
    out: dict = {"speed_mps": args.speed, "firmwares": {}}
    for fw, binary in selected(args.only):
        kills = []
        for i in range(args.kills):
            tmp = root / fw.name / str(i)
            tmp.mkdir(parents=True, exist_ok=True)
            kills.append(kill_once(fw, binary, args.speed, tmp))
        out["firmwares"][fw.name] = {
            "load_avg": os.getloadavg(),
            "summary": summary(kills),
            "kills": kills,
        }
        if not args.json:
            print_row(f"{fw.name} (load average {os.getloadavg()[0]:.2f})", summary(kills))
    if args.json:
        print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
