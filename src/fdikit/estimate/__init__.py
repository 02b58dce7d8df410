"""Parameter estimation: output-error estimation of any subset of named parameters (luo-et-al,
Section VIII and Appendix B), with a ready re-simulator for any NonlinearModel; and model
identification from nominal logs (:func:`identify`: N4SID subspace identification or ARX least
squares, order selection and the validation fit per output).
"""

from .identify import Identification, fit_percent, identify, simulate_free
from .output_error import ModelSimulator, OutputErrorResult, output_error, output_error_covariance

__all__ = ["Identification", "ModelSimulator", "OutputErrorResult", "fit_percent", "identify", "output_error",
           "output_error_covariance", "simulate_free"]
