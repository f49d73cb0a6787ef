"""Per-sample cost of ConvergenceMonitor.update: 6 models x 6 parameters, 50 Hz stamps,
converging estimates (flags up most of the time), default configuration. CPU time of the
calling thread (time.thread_time), best of several batches, beside the cost of one small
numpy call (np.add of two 6x6 arrays into a third) measured the same way, as a yardstick
for a loaded machine.

    PYTHONPATH=$PWD python validation/convergence/bench.py
"""
import os
import time

import numpy as np

from rls_uncertainty.convergence import ConvergenceConfig, ConvergenceMonitor

M, N_PAR, BATCH, REPEATS = 6, 6, 200, 300
rng = np.random.default_rng(0)
k = np.arange(BATCH * 2)
se = 0.1 / np.sqrt(k + 50.0)[:, None, None] * np.ones((1, M, N_PAR))
theta = 1.0 + 0.3 * se * rng.normal(size=se.shape)
ready = np.ones(M, bool)
mon = ConvergenceMonitor([N_PAR] * M, ConvergenceConfig())
a, b, c = np.ones((6, 6)), np.ones((6, 6)), np.ones((6, 6))

best, ref, flagged = [], [], 0
step = 0
for _rep in range(REPEATS):
    t0 = time.thread_time()
    for _ in range(BATCH):
        j = step % (2 * BATCH)
        f, mf = mon.update(step * 20_000_000, theta[j], se[j], ready)
        step += 1
    best.append((time.thread_time() - t0) / BATCH)
    flagged += int(f.sum())
    t0 = time.thread_time()
    for _ in range(BATCH):
        np.add(a, b, out=c)
    ref.append((time.thread_time() - t0) / BATCH)
best, ref = np.array(best) * 1e6, np.array(ref) * 1e6
print(f"update: best {best.min():.2f} us, median {np.median(best):.2f} us per sample "
      f"({M} models x {N_PAR} parameters); one np.add(6x6): best {ref.min():.3f} us, median {np.median(ref):.3f} us; "
      f"update = {np.median(best / ref):.1f} np.add; load average {os.getloadavg()[0]:.2f}; flags at end {flagged}")
