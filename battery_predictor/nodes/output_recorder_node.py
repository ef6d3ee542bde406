"""``output_recorder``: subscribes to the nodes' outputs, keeps them, and writes them to an MCAP bag."""

from __future__ import annotations

import threading

from battery_predictor_msgs.msg import PackState, RemainingRuntime
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message

from battery_predictor.replay import OutputBag

#: Deep reliable QoS so that a fast replay loses nothing.
RECORDER_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
#: Message classes of the recordable outputs and their type names.
OUTPUT_TYPES = {
    "battery_predictor_msgs/msg/PackState": PackState,
    "battery_predictor_msgs/msg/RemainingRuntime": RemainingRuntime,
    "diagnostic_msgs/msg/DiagnosticArray": DiagnosticArray,
}


class OutputRecorderNode(Node):
    """Records topics; the log time is the message's header stamp (the bag's time base in a replay).

    The recorded outputs all carry a header stamped on the node clock (``use_sim_time``
    in a replay), so the recorder needs no ``/clock`` of its own; a message with a zero
    stamp is logged at the recorder's clock.

    Parameters
    ----------
    topics : dict
        ``{topic: msgtype}``, msgtype one of :data:`OUTPUT_TYPES`.
    bag : OutputBag, optional
        Where to write them too.
    node_name : str
        Node name.
    **kwargs
        Passed to :class:`rclpy.node.Node`.
    """

    def __init__(self, topics: dict[str, str], *, bag: OutputBag | None = None, node_name: str = "output_recorder",
                 **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        self.bag = bag
        self._lock = threading.Lock()
        #: Received messages per topic, in arrival order.
        self.messages: dict[str, list] = {topic: [] for topic in topics}
        #: Messages per topic handed out by :meth:`drain` (still counted by :meth:`count`).
        self._drained: dict[str, int] = {topic: 0 for topic in topics}
        group = MutuallyExclusiveCallbackGroup()
        for topic, msgtype in topics.items():
            self.create_subscription(OUTPUT_TYPES[msgtype], topic, self._callback(topic, msgtype), RECORDER_QOS,
                                     callback_group=group)

    def _callback(self, topic: str, msgtype: str):
        def on_message(msg) -> None:
            stamp = msg.header.stamp
            now_ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
            if now_ns == 0:
                now_ns = self.get_clock().now().nanoseconds
            if self.bag is not None:
                self.bag.write(topic, msgtype, now_ns, serialize_message(msg))
            with self._lock:
                self.messages[topic].append(msg)

        return on_message

    def count(self, topic: str) -> int:
        """Messages received on ``topic`` (drained ones included)."""
        with self._lock:
            return len(self.messages.get(topic, [])) + self._drained.get(topic, 0)

    def drain(self) -> dict[str, list]:
        """The messages kept so far per topic, forgotten here (a long replay's memory stays flat).

        :meth:`count` still counts them; :meth:`snapshot` returns only what came after.
        """
        with self._lock:
            out = {topic: list(msgs) for topic, msgs in self.messages.items()}
            for topic, msgs in self.messages.items():
                self._drained[topic] += len(msgs)
                msgs.clear()
        return out

    def snapshot(self, topic: str) -> list:
        """A copy of the messages received on ``topic``."""
        with self._lock:
            return list(self.messages.get(topic, []))
