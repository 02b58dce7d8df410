"""Parameter estimation: output-error estimation of any subset of named parameters (luo-et-al,
Section VIII and Appendix B), with a ready re-simulator for any NonlinearModel; and model
identification from nominal logs (:func:`identify`: N4SID subspace identification or ARX least
squares pooled over many records, the innovation model with its Kalman gain and noise covariances,
order selection and the held-out fit per output).
"""

from .identify import (
           Identification,
           fit_percent,
           identify,
           kalman_gain,
           ljung_box,
           predict_one_step,
           simulate_free,
)
from .output_error import ModelSimulator, OutputErrorResult, output_error, output_error_covariance

__all__ = ["Identification", "ModelSimulator", "OutputErrorResult", "fit_percent", "identify", "kalman_gain",
           "ljung_box", "output_error", "output_error_covariance", "predict_one_step", "simulate_free"]
