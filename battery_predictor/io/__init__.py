"""File I/O: measurement CSVs and rosbag2 (MCAP) recordings, converted to :class:`Recording`.

ROS-free: nothing here imports rclpy; bags are read and written with ``rosbags``.

* :mod:`battery_predictor.io.csv_io`: ``load_csv``, ``load_csv_groups``, ``save_csv``;
* :mod:`battery_predictor.io.bags`: ``write_recording_bag``, ``read_recording_bag``, ``bag_info``
  (``schema``, ``storage``, ``topics``, ``writer``, ``reader``, ``info``);
* :mod:`battery_predictor.io.validation`: the checks both readers run on the parsed samples;
* :mod:`battery_predictor.io.loader`: ``load_recording``, ``csv_to_bag``, ``bag_to_csv``.
"""

from battery_predictor.io.bags import bag_info, read_recording_bag, write_recording_bag
from battery_predictor.io.csv_io import load_csv, load_csv_groups, save_csv
from battery_predictor.io.loader import bag_to_csv, csv_to_bag, load_recording

__all__ = [
    "bag_info",
    "bag_to_csv",
    "csv_to_bag",
    "load_csv",
    "load_csv_groups",
    "load_recording",
    "read_recording_bag",
    "save_csv",
    "write_recording_bag",
]
