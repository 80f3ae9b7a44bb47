"""What the lag identification costs the control thread (perchd/flight/lagid.py).

An approach refit runs every 0.25 s of the approach and once at the trigger, on the tick: its
cost is that tick's. This records a full window (8 s at 100 Hz) of a vehicle answering
through a delay and a first-order lag, then times the fit from the positions alone, from
the attitude (the default when the mocap measures it) and the attitude's own fit.

    python benchmarks/lagfit.py [--repeat 50] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time

from perchd.flight.config import LagIdGains
from perchd.flight.lagid import WINDOW_S, LagIdentifier

DT, G = 0.01, 9.81


def recorded(
    cfg: LagIdGains, delay_s: float = 0.11, tc_s: float = 0.24, drag: float = 0.25
) -> LagIdentifier:
    """An 8 s window: a hold, a run-up and a brake, answered delay_s late through tc_s."""
    ident = LagIdentifier(cfg)
    x, v, lean, sent = -6.0, 0.0, 0.0, []
    step = DT / 10  # the vehicle integrated in 1 ms steps, each command held for its tick
    keep = math.exp(-step / tc_s) if tc_s > 0.0 else 0.0
    for k in range(int(WINDOW_S / DT)):
        t = k * DT
        sent.append(0.0 if t < 2.0 else (0.06 if t < 6.0 else -0.08))
        ident.record(t, G * sent[-1], x, v)
        ident.record_lean(t, sent[-1], t, lean)
        for n in range(10):
            late = sent[max(math.floor((t + n * step - delay_s) / DT + 1e-9), 0)]
            lean = keep * lean + (1.0 - keep) * late
            v += (G * lean - drag * v) * step
            x += v * step
    return ident


def median_ms(call, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return 1000.0 * statistics.median(times)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=50, help="timed calls per figure (50)")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args()
    positions = recorded(LagIdGains(from_attitude=False))
    attitude = recorded(LagIdGains())
    figures = {
        "ticks": len(positions._rows),
        "fit_positions_ms": median_ms(positions.fit, args.repeat),
        "fit_attitude_ms": median_ms(attitude.fit, args.repeat),
        "lean_response_ms": median_ms(attitude.lean_response, args.repeat),
        "lag_found_s": attitude.fit().model.lag_s,
    }
    if args.json:
        print(json.dumps(figures))
    else:
        for key, value in figures.items():
            print(f"{key:20s} {value:.3f}" if isinstance(value, float) else f"{key:20s} {value}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
