"""The offline tools: bags and MCAP files (:mod:`.bags`, :mod:`.mcap_io`), the replay through the
node's pipeline (:mod:`.replay`, :mod:`.replay_files`, :mod:`.results`, :mod:`.report`,
:mod:`.compare`) and its figures (:mod:`.figure_data`, :mod:`.figures`).

May import :mod:`..datapath`, :mod:`..settings` and the numerical core; never rclpy.
"""
