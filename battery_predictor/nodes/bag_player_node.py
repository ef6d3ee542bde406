"""``bag_player``: publishes a bag's serialised messages and ``/clock`` (the replay's input side)."""

from __future__ import annotations

import importlib
import threading

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from battery_predictor.errors import BagError
from battery_predictor.nodes.messages import ns_to_stamp
from battery_predictor.replay import BagMessage

#: QoS of the played topics: reliable (matches best-effort sensor-data subscribers too), deep.
PLAYER_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
#: QoS of /clock (rclpy's TimeSource subscribes best effort, depth 1).
CLOCK_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


def message_class(msgtype: str):
    """The rclpy message class of ``pkg/msg/Name``."""
    try:
        pkg, kind, name = msgtype.split("/")
        return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    except (ValueError, ImportError, AttributeError):
        raise BagError(f"message type {msgtype} is not available to rclpy") from None


class BagPlayerNode(Node):
    """Publisher side of a replay.

    Parameters
    ----------
    topics : dict
        ``{topic: msgtype}`` to publish.
    node_name : str
        Node name.
    publish_clock : bool
        Create a ``/clock`` publisher (nodes with ``use_sim_time`` follow it).
    **kwargs
        Passed to :class:`rclpy.node.Node`.
    """

    def __init__(self, topics: dict[str, str], *, node_name: str = "bag_player", publish_clock: bool = True,
                 **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        self._topic_pubs = {topic: self.create_publisher(message_class(msgtype), topic, PLAYER_QOS)
                            for topic, msgtype in topics.items()}
        self.clock_pub = self.create_publisher(Clock, "/clock", CLOCK_QOS) if publish_clock else None
        self._lock = threading.Lock()
        #: Messages published per topic.
        self.sent: dict[str, int] = {}

    def publish_clock(self, time_ns: int) -> None:
        """Publish ``/clock`` = ``time_ns``."""
        if self.clock_pub is not None:
            self.clock_pub.publish(Clock(clock=ns_to_stamp(time_ns)))

    def publish(self, msg: BagMessage) -> None:
        """Publish one bag message unchanged (its CDR bytes)."""
        self._topic_pubs[msg.topic].publish(msg.data)
        with self._lock:
            self.sent[msg.topic] = self.sent.get(msg.topic, 0) + 1

    def matched(self) -> bool:
        """True when every publisher (and /clock) has at least one subscriber."""
        pubs = list(self._topic_pubs.values()) + ([self.clock_pub] if self.clock_pub is not None else [])
        return all(p.get_subscription_count() > 0 for p in pubs)
