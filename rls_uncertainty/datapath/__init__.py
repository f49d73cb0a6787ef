"""The one data path from stamped messages to published arrays (numpy only, no ROS import).

Inputs defined once (:mod:`.inputs`), each message judged (:mod:`.intake`, :mod:`.limits`),
sampled on the estimator grid (:mod:`.sampling`, :mod:`.streams`, :mod:`.timelines`), run through
the estimators by :class:`.pipeline.Pipeline`, judged (:mod:`.convergence`,
:mod:`.identifiability`), counted (:mod:`.bookkeeping`, :mod:`.alerts`) and encoded for the wire
(:mod:`.outputs`, :mod:`.cdr`). The node and every offline tool drive this wing the same way.

May import the numerical core and :mod:`..settings`; never rclpy, a bag or a web library.
"""
