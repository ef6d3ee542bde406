"""ROS 2 nodes (thin adapters around the ROS-free cores) and their ``main()`` entry points.

* :mod:`.battery_monitor_node` -- ``battery_monitor``: validates and averages the
  pack's raw samples (:mod:`battery_predictor.monitor.core`), publishes
  ``PackState`` and ``/diagnostics``;
* :mod:`.predictor_node` -- ``predictor``: remaining runtime on a timer and the
  ``can_accept_route`` service (:class:`battery_predictor.prediction.core.PredictorCore`);
* :mod:`.bag_player_node`, :mod:`.output_recorder_node`, :mod:`.replay_session`
  -- ``battery-predictor replay``: a bag played into the nodes (with ``/clock``)
  and their outputs recorded into a new MCAP bag.

Importing this package does not import rclpy; the modules do.
"""
