"""Bag-replay integration tests as a product (docs/testing.md): the estimator's results in a
test's terms, in process or from the live node.

* :func:`replay_bag` - a bag through the same pipeline as ``rls-uncertainty replay``, in this
  process, no file written: a :class:`ReplayResult`.
* :class:`ReplayResult` - :meth:`~ReplayResult.final` (a parameter's last estimate and both
  standard errors), :meth:`~ReplayResult.series` (its time history as numpy arrays),
  :meth:`~ReplayResult.counters` (message and sample accounting), :attr:`~ReplayResult.parameters`.
* :class:`EstimatorProcess` and :func:`play_to_node` - the estimator node in its own process
  on a private ROS domain (killed with the process that started it), a bag played to it with
  acknowledgements, its outputs collected as a :class:`ReplayResult` (ROS needed; rclpy is
  imported only then).
* :func:`claim_domain` - a ROS domain no other test session holds and no other node uses,
  held until released (:mod:`.domain`).
* pytest fixtures over them: ``-p rls_uncertainty.testing.plugin``, or
  ``pytest_plugins = ["rls_uncertainty.testing.plugin"]`` in a ``conftest.py``
  (:mod:`.plugin`).

Importing this module imports neither rclpy nor pytest.
"""

from ..offline.results import Final, ReplayResult, Series
from ..ros.player import bundled_bag
from .domain import DomainClaim, claim_domain
from .live import REPLAY_PARAMETERS, EstimatorProcess, LiveTimeout, play_to_node
from .offline import parameters, replay_bag

__all__ = [
    "replay_bag",
    "parameters",
    "ReplayResult",
    "Final",
    "Series",
    "EstimatorProcess",
    "play_to_node",
    "LiveTimeout",
    "REPLAY_PARAMETERS",
    "claim_domain",
    "DomainClaim",
    "bundled_bag",
]
