"""A campaign's figures from its table's rows (perchd.campaign.flights.FlightRow): contact
speed against the contact window, perch-time error, outcome counts, and the worst flights'
parameters. matplotlib is imported here, lazily, through perchd.core.extras (extra "plot")."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from perchd.core.extras import require
from perchd.logs.figsave import save_figure

DPI = 110
WORST_COLUMNS = (
    ("index", "d"),
    ("outcome", "s"),
    ("x0_aim", ".3f"),
    ("v0_aim", ".3f"),
    ("gust_dvx", "+.2f"),
    ("gust_dvy", "+.2f"),
    ("gust_dvz", "+.2f"),
    ("contact_speed", ".3f"),
    ("perch_error_s", "+.4f"),
)


def worst(rows: Sequence[Any], n: int) -> list[Any]:
    """The n worst flights: those outside their window first, then by contact-speed error."""

    def badness(r: Any) -> tuple[bool, float]:
        return r.in_window, -abs(r.speed_error_mps or 0.0)

    return sorted(rows, key=badness)[:n]


def plot_campaign(rows: Sequence[Any], out_dir: Path, force: bool, n_worst: int = 10) -> list[Path]:
    """The four figures as PNGs in the existing directory out_dir; their paths."""
    require("matplotlib", "plot").use("Agg")
    plt = require("matplotlib.pyplot", "plot")
    figures: dict[str, Callable[[Any], None]] = {
        "contact-speed.png": lambda ax: _speeds(ax, rows),
        "perch-error.png": lambda ax: _perch_errors(ax, rows),
        "outcomes.png": lambda ax: _outcomes(ax, rows),
        "worst.png": lambda ax: _worst(ax, worst(rows, n_worst)),
    }
    saved = []
    for name, draw in figures.items():
        fig, ax = plt.subplots(figsize=(9.0 if name == "worst.png" else 6.0, 4.0))
        try:
            draw(ax)
            fig.tight_layout()
            saved.append(save_figure(fig, out_dir / name, DPI, "--plots", force))
        finally:
            plt.close(fig)
    return saved


def _speeds(ax: Any, rows: Sequence[Any]) -> None:
    speeds = [r.contact_speed for r in rows if r.contact_speed is not None]
    ax.hist(speeds, bins=30, color="tab:blue")
    for edge in sorted({r.v_lo for r in rows} | {r.v_hi for r in rows}):
        ax.axvline(edge, color="tab:red", linestyle="--")
    ax.set(
        xlabel="contact speed [m/s] (dashed: the plan's window)",
        ylabel="flights",
        title=f"{len(speeds)} contacts of {len(rows)} flights",
    )


def _perch_errors(ax: Any, rows: Sequence[Any]) -> None:
    errors = [r.perch_error_s * 1e3 for r in rows if r.perch_error_s is not None]
    ax.hist(errors, bins=30, color="tab:green")
    ax.set(xlabel="perch time - plan [ms]", ylabel="flights", title="perch-time error")


def _outcomes(ax: Any, rows: Sequence[Any]) -> None:
    counts = Counter(r.outcome for r in rows).most_common()
    ax.bar([k for k, _ in counts], [v for _, v in counts], color="tab:gray")
    ax.set(ylabel="flights", title="outcomes")
    ax.tick_params(axis="x", rotation=20)


def _worst(ax: Any, rows: Sequence[Any]) -> None:
    ax.axis("off")
    ax.set_title(f"the {len(rows)} worst flights")
    if not rows:
        return
    cells = [[text(getattr(r, c), f) for c, f in WORST_COLUMNS] for r in rows]
    table = ax.table(cellText=cells, colLabels=[c for c, _ in WORST_COLUMNS], loc="center")
    table.auto_set_font_size(False)
    table.set_fontsize(7)


def text(value: Any, spec: str) -> str:
    """A table cell: value in spec's format, None as '--'."""
    return "--" if value is None else format(value, spec)
