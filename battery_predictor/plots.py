"""Figures a user looks at: measured vs simulated voltage (the seed paper's Fig. 4/7 kind)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


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
    fig, axes = plt.subplots(n, 1, figsize=(9, 3.2 * n), squeeze=False)
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
    plt.close(fig)
    return path
