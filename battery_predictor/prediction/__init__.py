"""Predictions the robots use (ROS-free): SOC calibration, remaining runtime, route acceptance."""
