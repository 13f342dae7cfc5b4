"""Thin ROS 2 layer: the node, message <-> core conversions, QoS profiles."""
