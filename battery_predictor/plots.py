"""Figures a user looks at: measured vs simulated voltage (the seed paper's Fig. 4/7 kind)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure


def plot_voltage_fit(recordings: Sequence, results: Sequence, path: str | Path, *, title: str,
                     labels: Sequence[str] | None = None) -> Path:
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
    """
    n = len(recordings)
    fig = Figure(figsize=(9, 3.2 * n))
    axes = fig.subplots(n, 1, squeeze=False)
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
