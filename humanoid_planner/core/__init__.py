"""ROS-free planning core: robots, kinematics, scene and collision, planners, grasp quality, timing.

Nothing in this package may import rclpy or any ROS message module.
"""
