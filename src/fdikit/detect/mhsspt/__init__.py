"""Multiple-hypothesis Shiryayev sequential probability test (MHSSPT), in the log domain.

Ng, Chen & Speyer, Section IV-E, after Malladi & Speyer (IEEE TAC 44(8), 1999); the recursion
and densities are written out in shared/notes/residual-processing.md. Hypothesis 0 is "no
fault"; hypotheses 1..M are faults. At every sample a change from H0 occurs with probability
``p``, to H_j with probability ``pi_j``; an optional return probability ``q`` lets a fault
hypothesis fall back to H0 (intermittent faults). With the posterior ``F`` of the previous
sample::

    phi_0 = F_0 (1 - p) + q sum_{j>=1} F_j
    phi_j = F_j (1 - q) + F_0 p pi_j
    F_j  <- phi_j f_j(x_k) / sum_i phi_i f_i(x_k)

computed with log-sum-exp so that likelihoods of 1e-300 neither underflow nor give 0/0. Terms
more than :data:`NEGLIGIBLE_NATS` below the largest are left out of the sums (they are below its
rounding). The densities are evaluated exactly or, with ``tabulate``, by interpolation in tables
(:func:`tabulate_umg`); many independent streams (runs) are advanced in one compiled call, in
parallel threads when the call has enough work.

The code lives in one module per concept: :mod:`.densities` (the hypotheses' densities),
:mod:`.kernels` (compiled exact log densities), :mod:`.recursion` (the compiled recursion and its
outputs), :mod:`.tables` (tabulated densities and their fused kernels), :mod:`.core` (the test),
:mod:`.warmup`, :mod:`.calibrate` (densities from simulated features), :mod:`.design` (the test
from real, labelled data), :mod:`.tempering` (a temperature fitted on held-out data, the
reliability of posteriors) and :mod:`.diagnosis` (decisions from the posteriors); every name of the
former single module is importable from here.
"""

# every name of the old module, private ones too; the constants are read where they are used
# (set ``core.PARALLEL_MIN_WORK``, not the re-export here, to change the threading threshold)
from .calibrate import MHSSPTCalibration, calibrate_densities, extend_ranges, floor_std  # noqa: F401
from .core import (  # noqa: F401
    MHSSPT,
    PARALLEL_MIN_OUTPUTS,
    PARALLEL_MIN_WORK,
    _first_nonfinite,
    _first_nonfinite_run,
    _first_nonfinite_serial,
    table_direct,
)
from .densities import _LOG_SQRT_2PI, LineMeanGaussian, UniformMeanGaussian, _log_diff_ndtr  # noqa: F401
from .design import WhitenedMHSSPT, _segment_list, calibrate_segments, design_mhsspt, shrunk_covariance  # noqa: F401
from .diagnosis import _fault_outputs, detection_time, final_diagnosis  # noqa: F401
from .kernels import (  # noqa: F401
    _INV_SQRT2,
    _log_ndtr_nb,
    _loglik_umg,
    _loglik_umg_parallel,
    _loglik_umg_shared,
    _loglik_umg_shared_parallel,
    _loglik_umg_shared_stream,
    _loglik_umg_stream,
    _shared_components,
    umg_component_logpdf,
)
from .recursion import (  # noqa: F401
    NEGLIGIBLE_NATS,
    _emit,
    _logaddexp,
    _mhsspt_recursion,
    _mhsspt_recursion_parallel,
    _mhsspt_recursion_stream,
    _probabilities,
    _probabilities_parallel,
    _probabilities_row,
    mhsspt_update,
)
from .tables import (  # noqa: F401
    _component_logpdf,
    _exact_values,
    _loglik_table,
    _mhsspt_cubic_run,
    _mhsspt_cubic_run_parallel,
    _mhsspt_cubic_stream,
    _mhsspt_table_run,
    _mhsspt_table_run_parallel,
    _mhsspt_table_stream,
    _umg_exact_points,
    _umg_value_slope,
    tabulate_umg,
    tabulate_umg_cubic,
    umg_table_add,
)
from .tempering import (
    decision_outputs,
    design_calibrated_mhsspt,
    fit_temperature,
    reliability,
)
from .warmup import WarmupMHSSPT  # noqa: F401

__all__ = [
    "MHSSPT",
    "NEGLIGIBLE_NATS",
    "LineMeanGaussian",
    "MHSSPTCalibration",
    "UniformMeanGaussian",
    "WhitenedMHSSPT",
    "calibrate_densities",
    "calibrate_segments",
    "decision_outputs",
    "design_calibrated_mhsspt",
    "design_mhsspt",
    "detection_time",
    "final_diagnosis",
    "fit_temperature",
    "mhsspt_update",
    "reliability",
    "shrunk_covariance",
    "tabulate_umg",
    "tabulate_umg_cubic",
    "umg_component_logpdf",
]
