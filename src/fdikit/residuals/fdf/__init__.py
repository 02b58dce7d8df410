"""Fault detection filters: exact unknown input observer and optimal stochastic fault detection filter.

A fault detection filter watches one *target* fault and blocks *nuisance* faults (other faults,
and the linearisation error of a nonlinear plant modelled as a fault; ng-chen-speyer, Sections II and
IV-A). Two designs are offered, both in discrete time at the sample rate of the monitor:

* :func:`design_uio` - the exact unknown input observer of Chen, Patton & Zhang (1996), for a
  nuisance distribution ``E`` with ``rank(C E) = rank(E)`` and ``(C, A1)`` detectable. The
  nuisance-to-residual transfer is zero (to rounding).
* :func:`design_optimal_fdf` - the optimal stochastic fault detection filter of Chen, Mingori &
  Speyer (Automatica 39 (2003) 377-390), here in its steady-state *discrete-time* form: a
  Kalman-type filter whose process-noise model carries the nuisance directions with the large
  intensity ``Q2 / gamma`` and whose residual is the projected output error ``r = H (y - C x_hat)``,
  ``H`` annihilating the output directions of the nuisance. As ``gamma -> 0`` the nuisance
  subspace becomes unobservable from ``r`` (the UIO's geometric structure) and its eigenvalues go
  to ``z = 0`` (the discrete image of ``-infinity``); short of the limit these fast, weakly
  observable modes are removed by model reduction (ng-chen-speyer, Section IV-C,
  :func:`reduce_filter`).

Every design is a plain-matrix :class:`FilterDesign` (the *implementation form*)

    xi[k+1] = A xi[k] + Bu u[k] + By y[k]
    r[k]    = C xi[k] + Du u[k] + Dy y[k]

run by :class:`FaultDetectionFilter` (batch ``run`` and streaming ``step``, bitwise equal);
its ``internal`` attribute holds the internal form against the design model, and
:func:`internal_form` composes any design with any :class:`~fdikit.model.linear.LinearFaultModel`
into the transfer from every input group (controls, disturbances, faults, noise) to ``r``; the
design's ``info`` records the conditions checked, ranks, ``gamma``, eigenvalues and reduction.

Modules (each imports only the ones above it):

* :mod:`.form` - :class:`FilterDesign`, the model at the filter's ``dt``, :func:`stack_designs`;
* :mod:`.directions` - fault directions and conditioned-invariant subspaces;
* :mod:`.analysis` - :func:`internal_form`, target visibility, frequency response, covariance;
* :mod:`.reduction` - :func:`modal_observability` and :func:`reduce_filter`;
* :mod:`.design` - :func:`design_uio`, :func:`design_optimal_fdf` and their front ends;
* :mod:`.kernels` - the compiled row updates of the runtime;
* :mod:`.runtime` - :class:`FaultDetectionFilter`.
"""

from ...base.stage import ResidualGenerator  # noqa: F401 (re-exported: the old module imported it)
from .analysis import (
    filter_frequency_response,
    internal_form,
    residual_covariance,
)
from .design import (
    design_filter_set,
    design_optimal_fdf,
    design_uio,
    fault_detection_filter,
)
from .directions import (
    _complement_rows,  # noqa: F401 (re-exported)
    _orth,  # noqa: F401 (re-exported)
    conditioned_invariant_subspace,
    fault_direction_split,
    fault_directions,
)
from .form import (
    FilterDesign,
    _discrete,  # noqa: F401 (re-exported)
    stack_designs,
)
from .kernels import (
    CHUNK,  # noqa: F401 (re-exported)
    _row_chunks,  # noqa: F401 (re-exported)
    _run_kernel_chunked,  # noqa: F401 (re-exported)
)
from .reduction import (
    modal_observability,
    reduce_filter,
)
from .runtime import (
    FaultDetectionFilter,
)

__all__ = [
    "FaultDetectionFilter",
    "FilterDesign",
    "conditioned_invariant_subspace",
    "design_filter_set",
    "design_optimal_fdf",
    "design_uio",
    "fault_detection_filter",
    "fault_direction_split",
    "fault_directions",
    "filter_frequency_response",
    "internal_form",
    "modal_observability",
    "reduce_filter",
    "residual_covariance",
    "stack_designs",
]
