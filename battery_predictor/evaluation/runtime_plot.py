"""Predicted vs true remaining runtime per recording (matplotlib's ``Figure`` API, no global state)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from matplotlib.figure import Figure

from battery_predictor.evaluation.runtime_eval import RecordingResult


def plot_runtime(results: Sequence[RecordingResult], path: str | Path) -> Path:
    """One panel per recording: true remaining runtime, the predictor's answers and each counter's.

    Parameters
    ----------
    results : sequence of RecordingResult
        Evaluated recordings.
    path : str or Path
        Image file to write.
    """
    n = len(results)
    cols = min(3, n)
    rows = math.ceil(n / cols)
    fig = Figure(figsize=(4.2 * cols, 3.2 * rows))
    for k, res in enumerate(results):
        ax = fig.add_subplot(rows, cols, k + 1)
        elapsed = [c.time_s / 60.0 for c in res.checkpoints]
        ax.plot(elapsed, [c.true_remaining_s / 60.0 for c in res.checkpoints], color="black", lw=1.5, label="true")
        ax.plot([c.time_s / 60.0 for c in res.checkpoints if c.valid],
                [c.predicted_s / 60.0 for c in res.checkpoints if c.valid], "o-", color="tab:red", ms=4,
                label="predictor (P50)")
        banded = [c for c in res.checkpoints if c.valid and math.isfinite(c.p10_s) and math.isfinite(c.p90_s)]
        if banded:
            ax.fill_between([c.time_s / 60.0 for c in banded], [c.p10_s / 60.0 for c in banded],
                            [c.p90_s / 60.0 for c in banded], color="tab:red", alpha=0.15, lw=0, label="P10..P90")
        for name in (res.checkpoints[0].counters_s if res.checkpoints else {}):
            ax.plot(elapsed, [c.counters_s[name] / 60.0 for c in res.checkpoints], "s--", ms=3, lw=0.8,
                    label=f"counter ({name})")
        ax.set_title(f"{Path(res.source).stem} ({res.mean_temperature_c:.0f} degC)", fontsize=9)
        ax.set_xlabel("elapsed [min]")
        ax.set_ylabel("remaining [min]")
        ax.grid(alpha=0.3)
        if k == 0:
            ax.legend(fontsize=7)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    return path
