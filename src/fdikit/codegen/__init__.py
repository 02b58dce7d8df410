"""Portable C99 from a designed monitor (issue 29): a fixed-size state struct, ``init``, ``reset``,
``step``, ``checkpoint`` / ``restore``, events into a caller's buffer; no dynamic memory, no
recursion, no globals with state, only ``<math.h>`` and ``<stdint.h>``; double and float32.

* :func:`generate` (a config's artifacts) and :func:`generate_monitor` (a built Monitor) write
  the code (:mod:`.generate`, :mod:`.emit`, the stages in :mod:`.stages`, the tabulated
  MHSSPT in :mod:`.stages_mhsspt_tab`, the plausibility rules in :mod:`.plausibility`; system
  stages register their emitters with :func:`register_emitter`, :mod:`.registry`);
* :class:`CMonitor` and :func:`compile_shared` are the equivalence harness (:mod:`.harness`).

A stage the generator does not know is refused by name (``stage X cannot be generated yet``).
"""

from .emit import GeneratedSource, emit_monitor, stage_digest
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
from .registry import register_emitter, registered
from .stages import EMITTERS
from .stages_dglrt import DirectionalGLRTEmitter
from .stages_dmatrix import DMatrixDecisionEmitter
from .stages_mhsspt_tab import TabulatedMHSSPTEmitter
from .stages_sensitivity import ParameterSensitivityEmitter

__all__ = [
    "CFLAGS",
    "EMITTERS",
    "CMonitor",
    "DMatrixDecisionEmitter",
    "DirectionalGLRTEmitter",
    "GeneratedSource",
    "ParameterSensitivityEmitter",
    "TabulatedMHSSPTEmitter",
    "c_to_py_state",
    "compile_shared",
    "config_digest",
    "driver_source",
    "emit_monitor",
    "find_compiler",
    "generate",
    "generate_monitor",
    "py_to_c_state",
    "register_emitter",
    "registered",
    "run_driver",
    "signals_input",
    "stage_digest",
]
