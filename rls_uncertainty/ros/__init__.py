"""The ROS adapter: the rclpy node (:mod:`.node`), DDS playback (:mod:`.player`), the live demo
(:mod:`.demo`) and the operator commands (:mod:`.operate`).

The only wing that imports rclpy; it adapts :mod:`..datapath` (whose
:mod:`..datapath.diagnostics` computes the ``/diagnostics`` statuses without ROS) and adds no
numerical policy.
"""
