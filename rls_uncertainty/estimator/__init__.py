"""Recursive least squares with a colored-residual parameter covariance.

Grauer & Morelli, "Parameter Uncertainty for Aircraft Aerodynamic Modeling using Recursive
Least Squares" (AIAA SciTech 2016), Eqs. 6-22. Every module of this package imports numpy
only.

* :mod:`.reference`: the equations as the paper writes them, and the definition of every
  option (forgetting, residual kinds, exact initialization, lag window); the test oracle.
* :mod:`.bank`: :class:`EstimatorBank`, the fast per-sample path for ``M`` models at once;
  :mod:`.recursive`: :class:`RecursiveEstimator`, a bank of one.
* :mod:`.lag_storage` (history and lag-indexed sums), :mod:`.initialization` (exact
  initialization), :mod:`.covariance` (Eqs. 13, 20, 22 from one computation),
  :mod:`.state` (``state()`` / ``from_state()``), :mod:`.batch` (Eqs. 6-14),
  :mod:`.lag_window` (Eq. 22 and the Bartlett window), :mod:`.options` (the choices).

Forgetting and the noise model (issue 12 item 7)
------------------------------------------------
With forgetting ``f < 1`` the estimate is the weighted fit ``D_k = (sum f^(k-j) x_j x_j')^-1``
and its covariance the sandwich ``D_k [sum_i c_i R(i) Lambda_k(i)] D_k``, with
``Lambda_k(i) = f^2 Lambda_(k-1)(i) + f^i (x_k x_(k-i)' + x_(k-i) x_k')`` (exact for
``D X'W Sigma W X D``). ``R(i)`` must then be the autocovariance of the *noise*, and the
estimator's own residuals cannot give it: a fit with memory ``1/(1-f)`` absorbs the noise
within about ``1 - f`` rad/sample of every regressor frequency, exactly where the sandwich
looks (for an intercept and white noise the expected corrected variance is
``2f (1 + f^(2L+1)) / (1+f)^2`` of the truth: 0.565 at ``f = 0.98``, ``L = 50``; 0.5 with all
lags), and ``1/(1-f)`` samples cannot estimate ``2L+1`` lags (25-50 % spread of the SE).
Measured with ``f = 0.95-0.999`` on AR(1) and band-limited noise within 50 lags: corrected
SE / true std 0.31-1.00, 2-SE coverage 41-96 % (0.52-0.64 for the bias at ``f = 0.98``).

So under forgetting ``R_k(i)`` comes from a **noise model**: the same regression fitted by
RLS with the slower forgetting ``f_R`` (``noise_forgetting``, default
``max(f, 1 - 1/(40 (n_lags + 1)))`` = 0.99951 for 50 lags, a memory of 2040 samples), whose
residuals ``u_k`` (standardized: ``(z_k - x_k' theta^N_(k-1)) sqrt(f_R / d^N_k)``) give
``R_k(i) = S_k(i) / n^N_k``, ``S_k(i) = f_R S_(k-1)(i) + u_k u_(k-i)``,
``n^N_k = f_R n^N_(k-1) + 1``. ``D_k`` and ``Lambda_k(i)`` stay the estimator's; the
conventional covariance is ``R_k(0) D_k Lambda_k(0) D_k``. ``f = 1`` gives ``f_R = 1``: no
noise model, exactly the paper (bit for bit as before). ``noise_forgetting = f`` gives the
estimator's own residuals (the formulas before the fix, bit for bit). It costs one more RLS
update per sample (no per-lag work) and one more residual history. With the noise model the
same study gives SE / true std 0.92-1.02 and coverage 93-97 % (validation/forgetting/REPORT.md;
test/test_estimator_forgetting.py). :meth:`.EstimatorBank.autocorrelation` and
``residual_variance`` then return the noise model's ``R_k(i)``; :meth:`.EstimatorBank.residuals`
the estimator's own residuals, :meth:`.EstimatorBank.noise_residuals` those behind ``R_k(i)``.

Where the corrected SE under forgetting is still not honest (validation/forgetting/REPORT.md,
section 6; ``f = 0.98``, 50 lags unless said):

1. **Noise correlated beyond the lags** (as in the paper, also at ``f = 1``): the SE equals the
   one of the truncated true autocovariance, low or high. AR(1) with correlation time 50
   samples: bias SE/true 0.91 (``f = 0.98``), 0.85 (0.99), 0.79 (0.999); band-limited 0.5 Hz
   noise (negative lobes): 0.81-0.82 for the multisine parameters at 0.98, 1.03-1.10 at
   0.999. Watch ``R_k(L)/R_k(0)``; raise ``n_lags`` (or use ``n_lags="auto"``, which reports
   when it reaches its cap).
2. **Noise level changing faster than** ``1/(1-f_R)`` **samples** (2040 for 50 lags): after the
   noise std doubles the SE is low (SE/true 0.53-0.64) for about 500 samples and needs about
   3000 to reach 0.9 (no worse than the estimator's own residuals during that time).
3. **Parameter steps** (what forgetting is for): for about ``1/(1-f)`` samples after a step the
   error is the tracking lag, which no noise covariance describes (RMS error 1.8-2.4 true SE,
   coverage 44-67 % for every variant); afterwards the slow noise model sees the step as
   residual and the SE is conservative (bias 1.3-1.9x, slopes 1.1-1.2x, still 1.2x / 1.05x
   after 6000 samples, about ``3/(1-f_R)``).
4. **Equation-error components slower than the noise memory** (drifting sensor biases,
   unmodelled slow dynamics): the fast fit takes them for parameter variation and the noise
   model absorbs them; nothing with finite memory can tell them from a parameter change, and
   they are not in the SE.
5. Early samples (``k < ~1/(1-f_R)``): ``R_k(i)`` from fewer samples, unbiased but with more
   spread. With all lags (``n_lags=None``) the default is ``f_R = f`` (no noise model: the
   notch above remains); pass ``noise_forgetting`` explicitly there.

Automatic lags (issue 14)
-------------------------
``n_lags="auto"`` (``max_lags=50``, ``min_lags=0``) keeps ``R_k(i)`` and ``Lambda_k(i)`` up to
``max_lags`` (the memory and update cost of ``n_lags=max_lags``) and, at the first covariance
evaluation of each sample, chooses every model's ``L`` by Politis' flat-top rule
(:mod:`.lag_selection`: ``L = 2 m``, ``m`` the lag before the first run of 5 autocorrelations
``|R_k(i)/R_k(0)| < 2 sqrt(log10 k / k)``; ``max_lags`` when no such run fits), then evaluates
Eq. 22 with the truncated window up to each model's ``L``. :attr:`.EstimatorBank.lags_used`
gives the choice. ``window="bartlett"`` is refused with it (the rule picks a truncation point;
the taper cannot let the anti-correlated lags of differentiated noise cancel). A long
correlation that first becomes significant can step a standard error (up to +30 % at one
sample on the Twin Otter data, onto the value 50 lags had). Under forgetting the rule's sample
count is Kish's effective size of the weights of ``R_k(i)``; that combination is not validated.

Residual burn-in
----------------
``residual_burn_in=B`` leaves the residuals of the first ``B`` samples after each model's
initialization at ``k0`` (and the initialization's own, samples ``1..k0``) out of ``R_k(i)``:
until ``k0 + B`` it is the paper's, afterwards Eq. 17 on the samples after ``k0 + B`` (both
``v_k`` and ``v_(k-i)``), divided by their count (weight total under forgetting), and the lag
rule's ``n`` is that count (:mod:`.reference` defines it). ``None`` (default) is 50 with
``n_lags="auto"`` and 0, the paper's Eq. 17 bit for bit, with fixed or all lags. Why: right
after initialization the estimate is poor and its residuals large and correlated; Eq. 17
keeps them for ever, and where the noise is small (Table 3 at 0 %) they inflate ``R_k(i)``
and the corrected SE, the more so the more lags are kept. Table 3 Monte Carlo (250 runs x 5 levels,
validation/integration/RESULTS.md): auto without burn-in 0.83-1.27, 24 of 25 cells in
[0.8, 1.25] (the miss: C_m_alpha at 0 %, 1.27); auto with the default burn-in 0.83-1.20, all
25; 50 lags 0.93-1.44 without (22 of 25) and 0.94-1.21 with a burn-in of 50 (all 25); all
lags 0.94-1.53 (21 of 25). With ``residual="a_posteriori"`` auto meets all 25 cells without a
burn-in (0.81-1.14). On the Twin Otter recordings the burn-in raises every auto SE by 3 %
(the normalisation: the early residuals are small). Right after ``k0 + B`` ``R_k`` rests on a
few samples and the covariance is as unsettled as right after initialization; a burn-in
longer than a short record leaves ``R_k`` the paper's for most of it.
"""

from ..errors import EstimatorNotReady, NonFiniteInput
from .bank import EstimatorBank
from .batch import batch_estimate
from .covariance import nearest_psd
from .lag_window import lag_weights
from .options import COVARIANCE_KINDS, RESIDUALS, WINDOWS, CovarianceKind, EstimatorOptions, Lags, Residual, Window
from .recursive import RecursiveEstimator

__all__ = [
    "EstimatorBank",
    "EstimatorOptions",
    "Lags",
    "RecursiveEstimator",
    "EstimatorNotReady",
    "NonFiniteInput",
    "batch_estimate",
    "lag_weights",
    "nearest_psd",
    "WINDOWS",
    "Window",
    "Residual",
    "CovarianceKind",
    "RESIDUALS",
    "COVARIANCE_KINDS",
]
