"""The paper's simulation study, Section IV (numerical core: numpy and scipy, matplotlib lazily).

- :mod:`.t2`: the T-2 short-period simulation (Eq. 25), its sensor streams and noise.
- :mod:`.turbulence`: Dryden gusts (MIL-F-8785C) as sampled sequences.
- :mod:`.multisine`: Eq. 24 multisines, the Table 2 designs.
- :mod:`.montecarlo`: the Table 3 Monte Carlo, convergence timing, Figs. 5-7.

May import the numerical core (:mod:`..estimator`, :mod:`..frequency`, :mod:`..aero`), the data
path's judgement of estimates and :mod:`..executors`; never ROS, a bag or a web library.
"""
