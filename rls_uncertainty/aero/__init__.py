"""From a measured flight state to the aerodynamics (numerical core: numpy only).

- :mod:`.models`: what is flown and what is estimated of it (the aircraft, the Eq. 2 models).
- :mod:`.coefficients`: REP-103 to aircraft body axes (the one conversion), the flight state,
  the Eq. 1 coefficients and the Eq. 2 regressors.
- :mod:`.differentiation`: the fixed-lag local-polynomial differentiator of the angular rates.
- :mod:`.surface_mixing`: Eq. 23, JointState joint names to elevator, aileron and rudder.

Imports the standard library, numpy and :mod:`rls_uncertainty.errors`; nothing else of the package.
"""
