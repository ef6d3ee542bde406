"""battery_predictor: runtime and route-feasibility prediction for battery-powered robots.

The core (everything except :mod:`battery_predictor.nodes`) never imports rclpy.
"""

__version__ = "0.1.0"
