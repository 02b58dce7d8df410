"""Parameter estimation: output-error estimation of any subset of named parameters (luo-et-al,
Section VIII and Appendix B), with a ready re-simulator for any NonlinearModel.
"""

from .output_error import ModelSimulator, OutputErrorResult, output_error, output_error_covariance

__all__ = ["ModelSimulator", "OutputErrorResult", "output_error", "output_error_covariance"]
