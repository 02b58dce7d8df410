"""7th-order lateral aircraft model of ng-tan-edwards-kuang, Section IV (Ng, Tan, Edwards & Kuang, CCA 2007).

The model (taken by ng-tan-edwards-kuang from Heck, Yallapragada & Fan, Automatica 1995) has states, in the
paper's order, bank angle, yaw rate, roll rate, sideslip angle, washout filter state, rudder
deflection and aileron deflection; inputs rudder and aileron commands; outputs the first three
states (``C = [I3 0]``). The fault is on the first (rudder) actuator, ``M = [0 0 0 0 0 20 0]^T``.

Uncertainty
-----------
Ng, Tan, Edwards & Kuang prints the true matrix ``A + dA`` and a factorisation ``dA x = Q~ xi~`` with
``Q~ = [0; I3; 0]`` and ``xi~ = Xi x``, and the two disagree. Compared with the nominal ``A`` the
printed ``A + dA`` changes ``A[1,2]`` 1.5 -> 1.7, ``A[2,2]`` -2.1 -> -2.2, ``A[3,5]`` 0.3 -> 0.4,
``A[3,6]`` -1.1 -> -1.2 and prints ``A[3,2] = 0`` where the nominal value is -5.2; the printed
``Xi`` instead perturbs columns 4 and 7 by +-0.1.

**Reading used here (one consistent choice):** ``A + dA`` as printed, except ``A[3,2]`` which is
read as the nominal -5.2 (a 100 % change of the dominant roll-to-sideslip coupling is implausible
next to the other 0.1-0.2 perturbations, and a zero there looks like a dropped entry). Then
``dA = Q~ Xi`` holds exactly with the printed ``Q~ = [0; I3; 0]`` (uncertainty in rows 2-4 only,
as the text says) and ``Xi = dA[1:4]`` (:data:`XI`). The observer design depends on ``Q~`` only,
so this choice affects the simulated uncertainty, not the design or its L2 bound.

Indices above are 0-based (row 3 = the sideslip equation, the paper's "row 4").

The other two readings are available for comparison through :func:`true_A` (``"printed_xi"``:
``A + Q~ Xi_printed``; ``"literal"``: the printed ``A + dA`` with its 0). Measured with the default
design of :func:`fdikit.residuals.smo.design_reconstructor` (15 s, :func:`fault_signal`, t >= 1 s):
RMS(f^ - f)/RMS(f) = 0.031 (this reading), 0.30 (printed Xi), 0.78 (literal) -- the paper's
Fig. 1 cannot tell which one it used.
"""

from __future__ import annotations

import numpy as np

from ...model.linear import LinearFaultModel

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
    "fault_signal",
    "model",
    "true_A",
]

#: States of the lateral aircraft model of ng-tan-edwards-kuang, Section IV.
STATES = ["bank_angle", "yaw_rate", "roll_rate", "sideslip", "washout", "rudder", "aileron"]
#: Actuator commands.
INPUTS = ["rudder_cmd", "aileron_cmd"]
#: Measured outputs (bank angle, yaw rate, roll rate).
OUTPUTS = ["bank_angle_meas", "yaw_rate_meas", "roll_rate_meas"]

#: Nominal A of ng-tan-edwards-kuang, Section IV (as printed).
A_NOMINAL = np.array([
    [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
    [0.0, -0.2, 1.5, 0.0, 0.0, -0.7, 0.0],
    [0.0, -1.0, -2.1, 0.0, 0.0, 0.0, 0.0],
    [0.0, 0.2, -5.2, -1.0, 0.0, 0.3, -1.1],
    [0.0, 0.5, 0.0, 0.0, -4.0, 0.0, 0.0],
    [0.0, 0.0, 0.0, 0.0, 0.0, -20.0, 0.0],
    [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -25.0],
])

#: True A + dA: ng-tan-edwards-kuang's printed matrix with A[3, 2] read as the nominal -5.2 (printed: 0).
A_TRUE = np.array([
    [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
    [0.0, -0.2, 1.7, 0.0, 0.0, -0.7, 0.0],
    [0.0, -1.0, -2.2, 0.0, 0.0, 0.0, 0.0],
    [0.0, 0.2, -5.2, -1.0, 0.0, 0.4, -1.2],  # printed "0 0.2 0 -1 0 0.4 -1.2"; 0 -> -5.2
    [0.0, 0.5, 0.0, 0.0, -4.0, 0.0, 0.0],
    [0.0, 0.0, 0.0, 0.0, 0.0, -20.0, 0.0],
    [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -25.0],
])

#: The uncertainty: ``A_TRUE - A_NOMINAL``.
DELTA_A = A_TRUE - A_NOMINAL

#: Uncertainty distribution (ng-tan-edwards-kuang: [0_{1x3}; I3; 0_{3x3}]).
Q_TILDE = np.vstack([np.zeros((1, 3)), np.eye(3), np.zeros((3, 3))])

#: xi~ = XI x~ so that DELTA_A = Q_TILDE @ XI exactly (the consistent reading above).
XI = DELTA_A[1:4].copy()

#: The factor printed in ng-tan-edwards-kuang (inconsistent with its printed A + dA; see the module
#: docstring).
XI_PRINTED = np.array([[0.0, 0.0, 0.0, 0.1, 0.0, 0.0, 0.0],
                       [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -0.1],
                       [0.0, 0.0, 0.0, -0.1, 0.0, 0.0, 0.0]])

#: Actuators: first-order lags of 20 and 25 rad/s (the rudder column is ng-tan-edwards-kuang's M).
B = np.array([[0.0, 0.0]] * 5 + [[20.0, 0.0], [0.0, 25.0]])
#: Output matrix: the first three states are measured.
C = np.hstack([np.eye(3), np.zeros((3, 4))])
#: Fault distribution: the rudder actuator (the first column of ``B``).
M = B[:, [0]]


def model(uncertain: bool = False) -> LinearFaultModel:
    """The aircraft as a :class:`LinearFaultModel`.

    Parameters
    ----------
    uncertain : bool
        ``False``: nominal ``A`` (the design model); ``True``: ``A + dA`` (the "true" plant).

    Returns
    -------
    LinearFaultModel
        Continuous; controls ``rudder_cmd``, ``aileron_cmd``; fault ``actuator:rudder_cmd``
        (direction ``M = [0 0 0 0 0 20 0]^T``); disturbances ``xi1..xi3`` with directions
        ``Q~ = [0; I3; 0]`` (rad/s^2 or rad/s per unit of ``xi``); outputs bank angle, yaw rate,
        roll rate (rad, rad/s).

    Examples
    --------
    >>> from fdikit.systems import aircraft
    >>> m = aircraft.model()
    >>> m.fault_names, m.B_of("f").ravel().tolist()
    (['actuator:rudder_cmd'], [0.0, 0.0, 0.0, 0.0, 0.0, 20.0, 0.0])
    """
    A = A_TRUE if uncertain else A_NOMINAL
    return LinearFaultModel(A.copy(), B.copy(), C.copy(), states=STATES, inputs=INPUTS, outputs=OUTPUTS,
                            Bd=Q_TILDE.copy(), disturbances=["xi1", "xi2", "xi3"],
                            faults=["actuator:rudder_cmd"],
                            name="aircraft (uncertain)" if uncertain else "aircraft")


def true_A(reading: str = "consistent") -> np.ndarray:
    """The uncertain system matrix ``A + dA`` under one of the three readings of ng-tan-edwards-kuang.

    Parameters
    ----------
    reading : {"consistent", "printed_xi", "literal"}
        ``"consistent"`` (default, :data:`A_TRUE`), ``A_NOMINAL + Q_TILDE @ XI_PRINTED``, or the
        printed ``A + dA`` with ``A[3, 2] = 0``.

    Returns
    -------
    ndarray (7, 7)

    Examples
    --------
    >>> from fdikit.systems import aircraft
    >>> float(aircraft.true_A("literal")[3, 2]), float(aircraft.true_A()[3, 2])
    (0.0, -5.2)
    """
    if reading == "consistent":
        return A_TRUE.copy()
    if reading == "printed_xi":
        return A_NOMINAL + Q_TILDE @ XI_PRINTED
    if reading == "literal":
        A = A_TRUE.copy()
        A[3, 2] = 0.0
        return A
    raise ValueError(f"unknown reading {reading!r}; use 'consistent', 'printed_xi' or 'literal'")


def fault_signal(t: np.ndarray) -> np.ndarray:
    """Rudder actuator fault used for Fig. 1 (ng-tan-edwards-kuang does not print its formula).

    Zero until 2 s, a ramp to 0.2 at 6 s, then ``0.2 + 0.1 sin(1.5 (t - 6))`` (units of the
    rudder command, rad).

    Parameters
    ----------
    t : array_like (T,)
        Time (s).

    Returns
    -------
    ndarray (T,)

    Examples
    --------
    >>> from fdikit.systems.aircraft import fault_signal
    >>> fault_signal([0.0, 4.0, 6.0]).round(3).tolist()
    [0.0, 0.1, 0.2]
    """
    t = np.asarray(t, float)
    f = np.where(t < 2.0, 0.0, 0.05 * (t - 2.0))
    return np.where(t >= 6.0, 0.2 + 0.1 * np.sin(1.5 * (t - 6.0)), f)
