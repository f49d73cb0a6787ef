"""The last guard before anything is published: finite, and a standard error that means something.

Both estimators publish a model only once its fit has the degrees of freedom the corrected
covariance needs (``estimator.publish_lag_windows``), so a published standard error is
neither zero nor rounding. This guard is the final check of that promise, per sample and
model: a ready model any of whose estimates or standard errors (corrected, Eqs. 20/22 or
F7-F8, and conventional, Eq. 13 or F5) is not finite, or any of whose standard errors is not
above :data:`SE_FLOOR` times its estimate's magnitude, is withheld at that sample (the caller
counts it in ``outputs_withheld``). ``1e3 eps |theta|``: the interval ``theta +- 2 SE`` would be
``theta`` itself to 12 digits, more than any least-squares solution is computed to (its
relative error is the condition number times ``eps``).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["SE_FLOOR", "withheld"]

# A published standard error must exceed this multiple of its estimate's magnitude.
SE_FLOOR = 1e3 * float(np.finfo(np.float64).eps)


def withheld(
    ready: npt.NDArray[np.bool_], real: npt.NDArray[np.bool_], theta: npt.NDArray[np.float64],
    se: npt.NDArray[np.float64], se_conventional: npt.NDArray[np.float64],
) -> npt.NDArray[np.bool_]:
    """The ``ready`` models ``(M,)`` to withhold: on a parameter (``real`` ``(M, n)``, not
    padding) an estimate or standard error that is not finite, or a standard error not above
    ``SE_FLOOR |theta|``."""
    # A non-finite estimate makes the floor NaN or infinite, which no standard error exceeds;
    # NaN in either standard error propagates through minimum and maximum (no comparison of
    # NaN or infinity warns).
    floor = SE_FLOOR * np.abs(theta)
    ok = np.minimum(se, se_conventional) > floor
    ok &= np.maximum(se, se_conventional) < np.inf
    bad: npt.NDArray[np.bool_] = ready & np.logical_or.reduce(real > ok, axis=1)  # (real > ok: real and not ok)
    return bad
