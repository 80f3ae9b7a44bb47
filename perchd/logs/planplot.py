"""Draw a plan like the paper's figure 4: distance, velocity, acceleration and tau vs time."""

from __future__ import annotations

import numpy as np

from perchd.core.extras import require
from perchd.logs.figsave import save_figure
from perchd.tau.plan import Plan


def plot_plan(plan: Plan, path: str, force: bool = False) -> None:
    require("matplotlib", "plot").use("Agg")
    import matplotlib.pyplot as plt

    t = np.linspace(0.0, plan.duration, 1001)
    fig, axes = plt.subplots(4, 1, figsize=(6, 9), sharex=True)
    rows = (
        (plan.x(t), "X [m]"),
        (plan.v(t), "Xdot [m/s]"),
        (plan.a(t), "Xddot [m/s^2]"),
        (plan.tau_ref(t), "tau [s]"),
    )
    for ax, (y, label) in zip(axes, rows):
        ax.plot(t, y)
        ax.axvline(plan.t_switch, color="grey", lw=0.8, ls="--")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    lim = plan.limits
    if lim.a_max is not None:
        for sign in (-1, 1):
            axes[2].axhline(sign * lim.a_max, color="red", lw=0.8, ls=":")
    if lim.v_max is not None:
        axes[1].axhline(lim.v_max, color="red", lw=0.8, ls=":")
    axes[-1].set_xlabel("time since trigger [s]")
    axes[0].set_title(f"{plan.strategy}: {plan.duration:.4f} s, contact {plan.v_contact:.3f} m/s")
    fig.tight_layout()
    try:
        save_figure(fig, path, 100, "--plot", force)
    finally:
        plt.close(fig)
