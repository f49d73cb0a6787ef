"""Real-time equation-error estimation in the frequency domain, with a corrected covariance.

The other real-time method of flight-test practice beside recursive least squares: every
sample advances a finite Fourier transform of each signal on a fixed frequency grid, and the
model ``Z(w) = X(w) theta`` is fitted by complex least squares on those transforms (Morelli,
"Real-Time Parameter Estimation in the Frequency Domain", JGCD 23(5), 2000; Klein & Morelli,
*Aircraft System Identification*, chapters 7-8). The published covariance
``s^2 Re(X^H X)^-1`` treats the grid's frequencies as independent; this package adds the
covariance of the same estimate for an equation error that is colored in time, derived in
``docs/frequency.md`` after the paper's truncated sandwich (Eqs. 17-22). Equation numbers
``F1``-``F12`` refer to that document. numpy only.

* :mod:`.options`: :class:`FrequencyOptions` (grid, lags, evaluation interval), validated once.
* :mod:`.transform`: the finite Fourier transform, batch (F1) and recursive (F2).
* :mod:`.lags`: lag-product sums giving the residual autocovariance of any estimate (F9).
* :mod:`.covariance`: the corrected covariance in closed form (F7-F8) and the fit correction (F10).
* :mod:`.instrumental`: the instrumental-variable fit's extra pieces (F11-F12).
* :mod:`.bank`: :class:`FrequencyBank`, ``M`` models sample by sample, least squares or
  instrumental variables.
* :mod:`.state`: a bank's record as plain data and back (the state file), bit for bit.
* :mod:`.reference`: :func:`frequency_reference`, the same quantities for one model written
  out over the samples; the oracle of the tests and the batch estimate of a record.
"""

from .bank import FrequencyBank
from .options import FrequencyOptions
from .reference import FrequencyFit, frequency_reference
from .transform import RecursiveFourierTransform, finite_fourier_transform, phasors

__all__ = [
    "FrequencyOptions",
    "FrequencyBank",
    "FrequencyFit",
    "frequency_reference",
    "RecursiveFourierTransform",
    "finite_fourier_transform",
    "phasors",
]
