"""No model? Identify one: linear state-space innovation models from nominal logs.

:func:`identify` fits a discrete :class:`~fdikit.model.LinearFaultModel` and its innovation form
(Kalman gain ``K``, noise covariances ``Q``, ``R``, ``S``) to one record or many records of named
inputs and outputs, so that the model-based designs (fault detection filters, residual banks, the
Kalman residual) apply to a system known only from data:

* ``method="n4sid"``: subspace identification (N4SID / PO-MOESP of Verhaegen & Verdult, with the
  arithmetic of the maintained ``nfoursid`` package), pooled over the records
  (:mod:`.n4sid`); the singular values of the projected Hankel matrix are kept for order selection;
  with few samples for many outputs, fewer block rows or the principal components of the outputs;
* ``method="arx"``: an ARX model ``y[k] = sum_i A_i y[k-i] + sum_i B_i u[k-i] + e[k]`` fitted by
  linear least squares (optionally ridge-regularised) pooled over the records (:mod:`.arx`),
  realised in state space with the past outputs and inputs as states.

Every record is split in time: its first part estimates, its held-out last part validates (or whole
held-out records validate). The fit of each output is

    fit % = 100 (1 - ||y - y_hat|| / ||y - mean(y)||)

of the one-step-ahead prediction by the Kalman predictor (``fit``, per output and per record) and of
the free-run simulation from the inputs alone (``fit_free_run``, the figure of MATLAB's
``compare``); the order is selected by BIC (default) or AIC of the innovations, or by either fit
(:mod:`.core`). Poles on the unit circle the data show (integrators) are kept and named in
``info``. The data are taken as deviations from the means of the estimation data (the operating
point); the offsets are in ``info`` and must be removed from signals fed to a design made on the
identified model.
"""

from .core import CRITERIA, Identification, identify
from .fit import fit_percent, simulate_free
from .innovation import kalman_gain, ljung_box, predict_one_step

__all__ = ["CRITERIA", "Identification", "fit_percent", "identify", "kalman_gain", "ljung_box",
           "predict_one_step", "simulate_free"]
