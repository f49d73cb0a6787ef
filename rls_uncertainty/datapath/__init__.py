"""The one data path from stamped messages to published arrays (numpy only, no ROS import).

Inputs defined once (:mod:`.inputs`), each message judged (:mod:`.intake`, :mod:`.limits`),
sampled on the estimator grid (:mod:`.sampling`, :mod:`.streams`, :mod:`.timelines`), run through
the estimators by :class:`.pipeline.Pipeline`, judged (:mod:`.convergence`,
:mod:`.identifiability`), counted (:mod:`.bookkeeping`, :mod:`.alerts`) and encoded for the wire
(:mod:`.outputs`, :mod:`.cdr`). The node and every offline tool drive this wing the same way.

Its configuration is :mod:`.config` (:class:`.config.PipelineConfig`). May import the numerical core
and the package's shared modules (errors, files, schema, state_file); never :mod:`..settings`
(which builds this wing's options from the node's parameters), rclpy, a bag or a web library.
"""
