"""Plot a load profile as a step curve coloured by label.

Uses matplotlib's object API with the Agg canvas directly, so it neither
needs a display nor changes the global pyplot backend.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from battery_predictor.profiles.load_profile import LoadProfile

#: (upper limit of the total duration in s, unit label, divisor) for the time axis.
_TIME_UNITS = ((600.0, "s", 1.0), (3 * 3600.0, "min", 60.0), (float("inf"), "h", 3600.0))


def _time_unit(total_s: float) -> tuple[str, float]:
    for limit, unit, divisor in _TIME_UNITS:
        if total_s <= limit:
            return unit, divisor
    return "h", 3600.0  # pragma: no cover


def plot_profile(profile: LoadProfile, path: str | Path, *, title: str | None = None, dpi: int = 120) -> Path:
    """Draw current vs time as steps, one colour per label, and save it.

    Parameters
    ----------
    profile : LoadProfile
        Profile to draw.
    path : str or Path
        Output image (format from the suffix, e.g. ``.png``, ``.pdf``).
    title : str, optional
        Plot title; by default built from the metadata (robot, route).
    dpi : int
        Resolution of raster images.

    Returns
    -------
    pathlib.Path
        The path written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    unit, divisor = _time_unit(profile.total_duration_s)
    starts = profile.times_s() / divisor
    ends = profile.end_times_s() / divisor
    edges = np.concatenate(([0.0], ends))

    figure = Figure(figsize=(10, 4.5), layout="constrained")
    FigureCanvasAgg(figure)
    ax = figure.add_subplot()
    # Each point is drawn as the edge leading into it plus its flat top, in
    # its label's colour, so that even short points (Temi navigation) show.
    current = profile.current_a
    previous = np.concatenate((current[:1], current[:-1]))
    polylines = np.stack(
        (np.column_stack((starts, previous)), np.column_stack((starts, current)), np.column_stack((ends, current))),
        axis=1,
    )
    labels = list(dict.fromkeys(profile.point_labels))
    colours = _colours(len(labels))
    label_array = np.array(profile.labels, dtype=object)
    for label, colour in zip(labels, colours):
        mask = label_array == label
        collection = LineCollection(polylines[mask], colors=[colour], linewidths=1.6, label=label or "(no label)")
        ax.add_collection(collection)
    ax.set_xlabel(f"Time in {unit}")
    ax.set_ylabel("Current in A (discharge > 0)")
    ax.set_xlim(0.0, edges[-1])
    top = float(np.max(profile.current_a))
    bottom = float(np.min(profile.current_a))
    ax.set_ylim(min(0.0, bottom * 1.1), top * 1.1 if top > 0 else 1.0)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", title="Label", frameon=False,
              ncol=1 if len(labels) <= 18 else 2)
    ax.set_title(title if title is not None else _default_title(profile), fontsize="medium")
    figure.savefig(path, dpi=dpi)
    return path


def _colours(n: int) -> list:
    from matplotlib import colormaps

    cmap = colormaps["tab10" if n <= 10 else "tab20"]
    return [cmap(i % cmap.N) for i in range(n)]


def _default_title(profile: LoadProfile) -> str:
    meta = profile.metadata
    parts = [str(meta.get("robot", "load profile"))]
    for key in ("route", "kind", "generator", "mode"):
        if meta.get(key):
            parts.append(str(meta[key]))
    if meta.get("seed") is not None:
        parts.append(f"seed {meta['seed']}")
    summary = (
        f"{profile.n_points} points, {profile.total_duration_s / 60.0:.2f} min, "
        f"{profile.charge_ah:.3f} Ah, mean {profile.mean_current_a:.2f} A"
    )
    return " | ".join(parts) + "\n" + summary
