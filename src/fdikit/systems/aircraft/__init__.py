"""The aircraft of ng-tan-edwards-kuang, Section IV: the 7th-order lateral model with its
rudder actuator fault and uncertainty (:mod:`.plant`), the reconstruction experiment of Fig. 1
(:mod:`.reconstruction`) and the monitor config recipe (:mod:`.recipe`)."""

from .plant import (
    A_NOMINAL,
    A_TRUE,
    DELTA_A,
    INPUTS,
    OUTPUTS,
    Q_TILDE,
    STATES,
    XI,
    XI_PRINTED,
    B,
    C,
    M,
    fault_signal,
    model,
    true_A,
)
from .recipe import design

__all__ = [
    "A_NOMINAL",
    "A_TRUE",
    "DELTA_A",
    "INPUTS",
    "OUTPUTS",
    "Q_TILDE",
    "STATES",
    "XI",
    "XI_PRINTED",
    "B",
    "C",
    "M",
    "design",
    "fault_signal",
    "model",
    "true_A",
]
