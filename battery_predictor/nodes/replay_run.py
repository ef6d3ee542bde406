"""One replay run, as ``battery-predictor replay`` and ``demo`` do it: play, record, compare, plot.

:func:`replay_into_nodes` plays a :class:`~battery_predictor.replay.ReplayStream` into the real nodes
(:class:`~.replay_session.ReplaySession`), records their outputs into a new MCAP bag, compares the
published remaining runtime with the bag's truth at the checkpoints and plots it. The caller owns
the rclpy context, the output directory and what is printed.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from battery_predictor.io.paths import portable_paths
from battery_predictor.nodes.replay_session import PlayStats, ReplaySession
from battery_predictor.replay import (
    Checkpoint,
    OutputBag,
    ReplayStream,
    RuntimePoint,
    RuntimeTruth,
    compare_at_checkpoints,
    plot_runtime,
    runtime_truth,
)

#: ``progress(end_ns)``: a context manager yielding the ``on_step(t_ns)`` of :meth:`ReplaySession.play_until`.
Progress = Callable[[int | None], AbstractContextManager[Callable[[int], None] | None]]


@dataclass(frozen=True)
class ReplayResult:
    """What one :func:`replay_into_nodes` run gave.

    Attributes
    ----------
    stats : PlayStats
        Steps, messages, bag seconds and wall seconds played.
    points : list of RuntimePoint
        Every ``/remaining_runtime`` message, on the recording's time axis (s).
    truth : RuntimeTruth or None
        The bag's true runtime, when its metadata carries it or ``truth_from_points`` finds it.
    checkpoints : list of Checkpoint
        Predicted vs true remaining runtime at the checkpoints (empty without truth).
    plot : pathlib.Path
        The PNG written.
    pack_states : int
        ``PackState`` messages the monitor published.
    diagnostic_levels : list of int
        The level of every ``/diagnostics`` status.
    rejected : dict
        Samples the monitor rejected, per input and reason.
    rejected_total : int
        All samples the monitor rejected.
    during : object
        What ``while_open(session)`` returned (None without it).
    """

    stats: PlayStats
    points: list[RuntimePoint]
    truth: RuntimeTruth | None
    checkpoints: list[Checkpoint]
    plot: Path
    pack_states: int
    diagnostic_levels: list[int]
    rejected: dict[str, dict[str, int]] = field(default_factory=dict)
    rejected_total: int = 0
    during: Any = None


@contextlib.contextmanager
def _no_progress(_end_ns: int | None) -> Iterator[None]:
    yield None


def replay_into_nodes(stream: ReplayStream, *, context, params_file: str | Path, out_bag: Path,
                      bag_metadata: dict[str, Any], plot: Path, plot_title: str, rate: float,
                      overrides: dict[str, Any] | None = None, end_ns: int | None = None,
                      progress: Progress | None = None,
                      while_open: Callable[[ReplaySession], Any] | None = None,
                      truth_from_points: Callable[[list[RuntimePoint]], RuntimeTruth | None] | None = None,
                      ) -> ReplayResult:
    """Play ``stream`` into the nodes up to ``end_ns`` (ROS time, ns; None: the whole bag) and compare.

    Parameters
    ----------
    stream : ReplayStream
        The bag to play.
    context : rclpy.context.Context or None
        An initialised rclpy context (None: the global one, initialised by the caller).
    params_file : str or Path
        Node parameters (``node_name: ros__parameters:``).
    out_bag : Path
        Output bag directory to create (must not exist).
    bag_metadata : dict
        Stored in the output bag (paths made portable).
    plot, plot_title : Path, str
        The remaining-runtime PNG to write and its title.
    rate : float
        Replay rate (times faster than recorded; 0 = as fast as the nodes take it).
    overrides : dict, optional
        Predictor parameter overrides.
    end_ns : int, optional
        Stop at this ROS time (ns).
    progress : callable, optional
        ``progress(end_ns)``, see :data:`Progress`.
    while_open : callable, optional
        Called with the session after the play, before it closes (e.g. to call a service).
    truth_from_points : callable, optional
        The truth of a bag whose metadata has none (e.g. found in a measured recording at the
        cut-off the predictor published), given the published runtime points.
    """
    output = OutputBag(out_bag, metadata=portable_paths(bag_metadata))
    try:
        with ReplaySession(stream, context=context, params_file=str(params_file),
                           predictor_overrides=overrides or {}, rate=rate, out_bag=output) as session:
            with (progress or _no_progress)(end_ns) as on_step:
                stats = session.play_until(end_ns, on_step=on_step)
            session.flush()
            points = session.runtime_points()
            pack_states = len(session.pack_states())
            levels = [s.level[0] if isinstance(s.level, bytes) else int(s.level)
                      for d in session.diagnostics() for s in d.status]
            rejected = dict(session.monitor.monitor.rejected)
            rejected_total = session.monitor.monitor.rejected_total
            during = while_open(session) if while_open is not None else None
    finally:
        output.close()
    truth = runtime_truth(stream.metadata)
    if truth is None and truth_from_points is not None:
        truth = truth_from_points(points)
    checkpoints = compare_at_checkpoints(points, truth) if truth else []
    plot_runtime(points, truth, plot, title=plot_title, checkpoints=checkpoints)
    return ReplayResult(stats=stats, points=points, truth=truth, checkpoints=checkpoints, plot=Path(plot),
                        pack_states=pack_states, diagnostic_levels=levels, rejected=rejected,
                        rejected_total=rejected_total, during=during)
