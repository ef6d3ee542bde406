"""ROS-free parts of ``battery-predictor replay``: the bag as a time-ordered message stream, the
output bag writer, the ground truth of a bag and the predicted-vs-true runtime comparison and plot.

* :mod:`.stream`: :class:`ReplayStream` (``read_replay_stream``, ``stream_from_messages``);
* :mod:`.truth`: :class:`RuntimeTruth`, :class:`RuntimePoint`, :class:`Checkpoint`, the comparison;
* :mod:`.plot`: :func:`plot_runtime`;
* :mod:`.output_bag`: :class:`OutputBag`.

Playing a stream into the nodes is :func:`battery_predictor.nodes.replay_run.replay_into_nodes`.

The ROS side (publishing ``/clock`` and the messages, running the nodes,
recording their outputs) is :mod:`battery_predictor.nodes.replay_session`.

Time
----
A replay publishes ``/clock`` with each message's bag (log) time before the
message itself, and the nodes run with ``use_sim_time``: the monitor's
``BatteryState`` stamps, the relay's reception times and the staleness
checks are then all on the bag's time base, whatever the replay rate.
Results are reported on the recording's own time axis (``time_s`` of
:func:`battery_predictor.io.bags.read_recording_bag`, which starts at 0 for
the bundled bags); :meth:`ReplayStream.recording_time_s` maps a ROS time to it.
"""

from battery_predictor.replay.output_bag import CUSTOM_TYPES, OutputBag, output_typestore
from battery_predictor.replay.plot import plot_runtime
from battery_predictor.replay.stream import (
    INPUT_TYPES,
    BagMessage,
    ReplayStream,
    read_replay_stream,
    stream_from_messages,
)
from battery_predictor.replay.truth import (
    DEFAULT_CHECKPOINTS_MIN,
    Checkpoint,
    RuntimePoint,
    RuntimeTruth,
    compare_at_checkpoints,
    error_summary,
    runtime_truth,
)

__all__ = [
    "CUSTOM_TYPES",
    "DEFAULT_CHECKPOINTS_MIN",
    "INPUT_TYPES",
    "BagMessage",
    "Checkpoint",
    "OutputBag",
    "ReplayStream",
    "RuntimePoint",
    "RuntimeTruth",
    "compare_at_checkpoints",
    "error_summary",
    "output_typestore",
    "plot_runtime",
    "read_replay_stream",
    "runtime_truth",
    "stream_from_messages",
]
