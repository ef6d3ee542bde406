"""Figures a user looks at: measured vs simulated voltage (the seed paper's Fig. 4/7 kind)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

#: Relative 95 % half-widths are drawn up to this; wider ones (and infinite ones) end at it, marked.
HALF_WIDTH_AXIS_MAX = 10.0


def plot_voltage_fit(recordings: Sequence, results: Sequence, path: str | Path, *, title: str,
                     labels: Sequence[str] | None = None,
                     identifiability: tuple[Sequence[tuple[str, float, bool]], Sequence[tuple[str, str, float]]]
                     | None = None) -> Path:
    """Measured vs simulated pack voltage over time, one panel per recording.

    Parameters
    ----------
    recordings : sequence of Recording
        Measured data.
    results : sequence of PackSimResult
        Simulations of the same recordings.
    path : str or Path
        PNG to write.
    title : str
        Figure title (carries R2_mod).
    identifiability : tuple, optional
        ``(rows, pairs)`` from the fit's identifiability report: ``rows`` of ``(name,
        relative 95 % half-width, determined)`` and compensating ``pairs`` of ``(name_a, name_b,
        correlation)``; drawn as a last panel.
    """
    n = len(recordings)
    extra = 1 if identifiability is not None else 0
    fig = Figure(figsize=(9, 3.2 * (n + extra)))
    axes = fig.subplots(n + extra, 1, squeeze=False)
    if identifiability is not None:
        _identifiability_panel(axes[n, 0], *identifiability)
    for k, (rec, res) in enumerate(zip(recordings, results)):
        ax = axes[k, 0]
        ax.plot(rec.relative_time_s / 60.0, rec.voltage_v, color="black", lw=1.2, label="measured")
        ax.plot(res.time_s / 60.0, res.pack_voltage_v, color="tab:red", lw=1.0, ls="--", label="simulated")
        ax.set_xlabel("time [min]")
        ax.set_ylabel("pack voltage [V]")
        ax.set_title(labels[k] if labels else Path(str(rec.source)).name, fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def _identifiability_panel(ax: Axes, rows: Sequence[tuple[str, float, bool]], pairs: Sequence[tuple[str, str, float]]) -> None:
    """Bars of each fitted parameter's relative 95 % half-width, coloured by whether the data determine it."""
    names = [r[0] for r in rows]
    widths = [min(r[1], HALF_WIDTH_AXIS_MAX) if np.isfinite(r[1]) else HALF_WIDTH_AXIS_MAX for r in rows]
    colours = ["tab:green" if r[2] else "tab:red" for r in rows]
    y = np.arange(len(rows))
    ax.barh(y, widths, color=colours)
    ax.set_yticks(y, names, fontsize=7)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlim(min([1e-4] + [0.5 * w for w in widths if w > 0]), HALF_WIDTH_AXIS_MAX * 1.5)
    ax.set_xlabel("relative 95 % half-width (green: determined by the data, red: not)")
    for k, r in enumerate(rows):
        if not np.isfinite(r[1]) or r[1] > HALF_WIDTH_AXIS_MAX:
            ax.text(HALF_WIDTH_AXIS_MAX, k, "  unbounded", va="center", fontsize=7)
    text = "; ".join(f"{a} ~ {b} ({c:+.2f})" for a, b, c in pairs) or "none"
    ax.set_title(f"identifiability at the optimum; compensating pairs: {text}", fontsize=8)
    ax.grid(alpha=0.3, axis="x")


def ocv_figure(soc: Sequence[float] | np.ndarray, measured_v: Sequence[float] | np.ndarray,
               model_v: Sequence[float] | np.ndarray, *, title: str) -> Figure:
    """Measured vs model open-circuit voltage against state of charge (a matplotlib ``Figure``).

    Parameters
    ----------
    soc : sequence of float
        State of charge, 0..1.
    measured_v, model_v : sequence of float
        Cell open-circuit voltage in V, measured and from the model's OCPs.
    title : str
        Figure title.
    """
    import numpy as np

    fig = Figure(figsize=(8, 5.5))
    top, bottom = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    top.plot(soc, measured_v, color="black", lw=1.4, label="measured")
    top.plot(soc, model_v, color="tab:red", lw=1.0, ls="--", label="model OCPs")
    top.set_ylabel("open-circuit voltage [V]")
    top.grid(alpha=0.3)
    top.legend(loc="best", fontsize=8)
    bottom.plot(soc, 1000 * (np.asarray(model_v) - np.asarray(measured_v)), color="tab:red", lw=1.0)
    bottom.set_xlabel("state of charge")
    bottom.set_ylabel("model - measured [mV]")
    bottom.grid(alpha=0.3)
    fig.suptitle(title, fontsize=10)
    return fig
