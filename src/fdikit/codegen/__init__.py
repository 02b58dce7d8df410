"""Portable C99 from a designed monitor (issue 29): a fixed-size state struct, ``init``, ``reset``,
``step``, ``checkpoint`` / ``restore``, events into a caller's buffer; no dynamic memory, no
recursion, no globals with state, only ``<math.h>`` and ``<stdint.h>``; double and float32.

* :func:`generate` (a config's artifacts) and :func:`generate_monitor` (a built Monitor) write
  the code (:mod:`.generate`, :mod:`.emit`, the stages in :mod:`.stages`, the MHSSPT's shared
  C and its exact form in :mod:`.mhsspt_c`, the tabulated MHSSPT in :mod:`.stages_mhsspt_tab`,
  the plausibility rules in :mod:`.plausibility`, constant tables as exact C arrays in
  :mod:`.arrays`);
* :class:`CMonitor` and :func:`compile_shared` are the equivalence harness (:mod:`.harness`);
* :func:`register_emitter` adds the emitter of another stage class (:mod:`.registry`: system
  stages register from their own package, found by the plugin convention); the sensor checks
  and the peer CUSUM (:mod:`.sensor`), the scheduled blend (:mod:`.scheduled`), the directional
  GLRT, the D-matrix decision, the parameter sensitivity, the tabulated MHSSPT and the fault-type classifier
  (:mod:`.fault_type`) register there; the episode rule is :mod:`.episodes`;
* :func:`subset_monitor` cuts a monitor after a processor (``generate(..., stop_after=...)``).

A stage the generator does not know is refused by name (``stage X cannot be generated yet``).
"""

from .emit import GeneratedSource, emit_monitor, stage_digest
from .fault_type import FaultTypeEmitter
from .generate import config_digest, generate, generate_monitor
from .harness import (
    CFLAGS,
    CMonitor,
    c_to_py_state,
    compile_shared,
    driver_source,
    find_compiler,
    py_to_c_state,
    run_driver,
    signals_input,
)
from .registry import (
    class_path,
    emitter_for,
    register_emitter,
    registered,
    registered_emitter,
    registered_names,
)
from .scheduled import ScheduledFilterEmitter
from .sensor import PeerCheckEmitter, PeerCUSUMEmitter, StuckEmitter
from .stages import EMITTERS
from .stages_dglrt import DirectionalGLRTEmitter
from .stages_dmatrix import DMatrixDecisionEmitter
from .stages_mhsspt_tab import TabulatedMHSSPTEmitter
from .stages_sensitivity import ParameterSensitivityEmitter
from .subset import subset_monitor

__all__ = ["CFLAGS", "EMITTERS", "CMonitor", "DMatrixDecisionEmitter", "DirectionalGLRTEmitter",
           "FaultTypeEmitter",
           "GeneratedSource", "ParameterSensitivityEmitter", "PeerCUSUMEmitter", "PeerCheckEmitter",
           "ScheduledFilterEmitter",
           "StuckEmitter",
           "TabulatedMHSSPTEmitter", "c_to_py_state", "class_path", "compile_shared", "config_digest",
           "driver_source", "emit_monitor", "emitter_for", "find_compiler", "generate", "generate_monitor",
           "py_to_c_state", "register_emitter", "registered", "registered_emitter", "registered_names",
           "run_driver", "signals_input", "stage_digest", "subset_monitor"]
