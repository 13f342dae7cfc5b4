"""humanoid_planner: reach-to-grasp motion planning (GIRRT, DAGRRT) for humanoid arms.

`humanoid_planner.core` is a plain Python library (no rclpy); `humanoid_planner.ros` is the thin
ROS 2 layer on top of it.
"""
