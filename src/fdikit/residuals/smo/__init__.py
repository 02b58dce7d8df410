"""Robust actuator fault reconstruction with sliding mode observers (ng-tan-edwards-kuang).

Ng, Tan, Edwards & Kuang: K. Y. Ng, C. P. Tan, C. Edwards, Y. C. Kuang, "New result in robust actuator fault
reconstruction with application to an aircraft", IEEE CCA 2007 -- and, for the relative-degree-one
case, C. P. Tan & C. Edwards, IJRNC 13:443-463, 2003.

The system is

    x~' = A~ x~ + B~ u + M~ f + Q~ xi~,   y = C~ x~,   xi~' = A_Omega xi~ + B_Omega xi      (1)-(3)

with ``f`` (q) the actuator faults to reconstruct and ``xi~`` (h) the uncertainty, band-limited by
the filter ``(A_Omega, B_Omega)``. :func:`design_reconstructor` checks the existence conditions
(:func:`check_conditions`), then

* if A1 holds (rank C~M~ = q, relative degree one) designs **one** robust SMO (Tan & Edwards
  2003) on the augmented system (7)-(8);
* otherwise, if B1 and B2 hold, builds the canonical form of Lemmas 1 and 4 (orthogonal / QR /
  SVD steps only), designs the **primary** SMO (15)-(18) by the LMI (42)-(44), forms the
  fictitious relative-degree-one system (25)-(36) from the primary's equivalent output injection
  and designs the **secondary** SMO (37)-(39) by the LMIs (46)-(47), which minimise the L2 gain
  from ``xi`` to the reconstruction ``f^ = W T^-1 Po^-1 nu_eq``.

The runtime :class:`SlidingModeReconstructor` is a :class:`~fdikit.monitor.ResidualGenerator`
whose outputs are the fault reconstructions ``fhat:<fault>``. It integrates the observers with a
fixed step equal to the sample time of the data (see :func:`integrate_observers`): explicit Euler
for the linear part and an implicit (backward) step for the smoothed switching term (24), which
removes the numerical chattering of an explicit switched term; batch :meth:`run` and streaming
:meth:`step` call the same compiled kernel and agree to the last bit.

Modules (each imports only the ones above it):

* :mod:`.validation` - argument checks shared by the others;
* :mod:`.conditions` - the existence conditions A1, A2, B1, B2;
* :mod:`.canonical` - Lemma 1, the augmented system, Lemma 4, the fictitious system;
* :mod:`.gains` - H-infinity norm and peak-to-peak gains;
* :mod:`.kernel` - the compiled observer step, sliding status and integration;
* :mod:`.status` - the sliding status codes and :func:`sliding_episodes`;
* :mod:`.noise_estimate` - the online noise estimate and the switch between a noise-aware
  design's branches (compiled);
* :mod:`.runtime` - :class:`SlidingModeReconstructor` and :func:`integrate_observers`;
* :mod:`.plant` - :func:`simulate_plant` (exact ZOH simulation of the design model);
* :mod:`.noise` - measurement-noise response, noise-driven boundary layers and the switch rule;
* :mod:`.selfcheck` - :func:`self_check`, the design run on its own model;
* :mod:`.design` - :func:`design_reconstructor`.
"""

from .canonical import (
    AugmentedSystem,
    CanonicalForm,
    FictitiousSystem,
    Lemma1Form,
    augment,  # noqa: F401 (re-exported)
    fictitious_system,
    lemma1_form,
    lemma4_form,
)
from .conditions import (
    RANK_ATOL_SCALE,  # noqa: F401 (re-exported)
    SMOConditions,
    check_conditions,
)
from .design import (
    DELTA_LADDER,  # noqa: F401 (re-exported)
    design_reconstructor,
)
from .gains import (
    hinf_norm,
    injection_peak_gains,
    peak_gain,
)
from .noise import (
    noise_response,
)
from .noise_estimate import (
    estimate_noise_std,
)
from .plant import (
    simulate_plant,
)
from .runtime import (
    SlidingModeReconstructor,
    integrate_observers,
)
from .selfcheck import (
    band_frequencies,
    self_check,
)
from .status import (
    NOT_SLIDING,  # noqa: F401 (re-exported)
    SATURATED,  # noqa: F401 (re-exported)
    SLIDING,  # noqa: F401 (re-exported)
    STATUS_LABELS,  # noqa: F401 (re-exported)
    sliding_episodes,
)

__all__ = [
    "AugmentedSystem",
    "CanonicalForm",
    "FictitiousSystem",
    "Lemma1Form",
    "SMOConditions",
    "SlidingModeReconstructor",
    "band_frequencies",
    "check_conditions",
    "design_reconstructor",
    "estimate_noise_std",
    "fictitious_system",
    "hinf_norm",
    "injection_peak_gains",
    "integrate_observers",
    "lemma1_form",
    "lemma4_form",
    "noise_response",
    "peak_gain",
    "self_check",
    "simulate_plant",
    "sliding_episodes",
]
