"""Parameter estimation: output-error estimation of any subset of named parameters (paper luo-et-al,
Section VIII and Appendix B), with ready re-simulators for any NonlinearModel and for the ABS.
"""

from .output_error import (
    ABS_ESTIMATED,
    ABS_TABLE_VI_PAPER,
    ABS_TABLE_VI_TRUE,
    ABSSimulator,
    ModelSimulator,
    OutputErrorResult,
    abs_table_vi,
    output_error,
    output_error_covariance,
)

__all__ = ["ABS_ESTIMATED", "ABS_TABLE_VI_PAPER", "ABS_TABLE_VI_TRUE", "ABSSimulator", "ModelSimulator",
           "OutputErrorResult", "abs_table_vi", "output_error", "output_error_covariance"]
