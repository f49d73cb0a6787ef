"""The ROS adapter: the rclpy node (:mod:`.node`), its ``/diagnostics`` statuses computed without
ROS (:mod:`.diagnostics`), DDS playback and the live demo (:mod:`.player`), and the operator
commands (:mod:`.operate`).

The only wing that imports rclpy; it adapts :mod:`..datapath` and adds no numerical policy.
"""
