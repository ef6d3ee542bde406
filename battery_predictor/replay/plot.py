"""The figure of a replay: predicted (and true) remaining runtime over the recording time."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

from battery_predictor.replay.truth import Checkpoint, RuntimePoint, RuntimeTruth


def plot_runtime(points: Sequence[RuntimePoint], truth: RuntimeTruth | None, path: str | os.PathLike[str], *,
                 title: str = "", checkpoints: Sequence[Checkpoint] = ()) -> Path:
    """PNG of predicted (and, when known, true) remaining runtime over the recording time."""
    from matplotlib.figure import Figure

    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig = Figure(figsize=(8.0, 4.8))
    ax = fig.subplots()
    valid = [p for p in points if p.valid and math.isfinite(p.remaining_s)]
    invalid = [p for p in points if not p.valid]
    if valid:
        ax.plot([p.time_s / 60 for p in valid], [p.remaining_s / 60 for p in valid], ".", ms=3,
                label="predicted (/remaining_runtime)")
    if invalid:
        ax.plot([p.time_s / 60 for p in invalid], [0.0] * len(invalid), "x", color="tab:red", ms=4,
                label="invalid prediction")
    if truth is not None:
        t_end = truth.runtime_s / 60
        ax.plot([0.0, t_end], [t_end, 0.0], "-", color="k", lw=1.2,
                label=f"true (until {truth.stop_voltage_v:.2f} V at {t_end:.0f} min)")
    if checkpoints:
        ax.plot([c.time_s / 60 for c in checkpoints], [c.predicted_min for c in checkpoints], "o", mfc="none",
                color="tab:orange", label="checkpoints")
    ax.set_xlabel("time since start of the recording (min)")
    ax.set_ylabel("remaining runtime (min)")
    ax.set_ylim(bottom=0)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    return out
