"""Every setting, defined once: the aircraft and model domain, the node's parameters and where
they come from (``--ros-args``, parameter files), read without rclpy.

Imports the numerical core's options classes and the standard library, numpy and yaml.
"""
