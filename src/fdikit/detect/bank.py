"""Banks of residual tests: each a chain residual -> GLRT (or directional GLRT) -> hold rule
[-> time gate], designed together from nominal records and run together on records.

A :class:`TestSpec` names one test (residual channel, GLRT window ``W``, hold ``Z``, optional gate
time, optional parameter signature for a directional test); a :class:`TestBank` holds the designed
calibration (``mu0``, ``sigma^2`` per residual) and thresholds and returns every test's outcome
and first alarm time on a set of records (luo-et-al, Section V-C, eqs. (24), (34), (35)).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import DataError
from ..signals import Signals
from .directional import DirectionalGLRT
from .glrt import GLRT, TimeGated
from .threshold import Hold

__all__ = ["TestBank", "TestSpec"]


@dataclass(frozen=True)
class TestSpec:
    """One GLRT test: residual channel, window ``W``, hold ``Z`` and optional gate time ``T`` (s).

    With ``signature`` (a plant parameter, e.g. ``"I_w"``) the test is the directional GLRT
    (:class:`fdikit.detect.DirectionalGLRT`) of the residual along its signature channel
    ``"sig:<residual>:<signature>"`` (as :class:`fdikit.residuals.ParameterSensitivity` names them);
    ``residual`` may then name several channels joined by ``"+"`` (``"r3+r4"``). ``W = None``
    anchors it at the start of the record (the parametric fault present throughout),
    ``min_information`` keeps it silent until the information about the amplitude reaches that
    value (1/eta^2: 2500 means a standard deviation of 2 % for the relative change), and
    ``nuisance`` names parameters whose signatures it is decoupled from.
    """

    __test__ = False  # not a pytest class
    name: str
    residual: str
    W: int | None
    Z: int
    gate: float | None = None
    signature: str | None = None
    min_information: float = 0.0
    nuisance: tuple[str, ...] = ()

    def __post_init__(self):
        if self.W is None and self.signature is None:
            raise DataError(f"test {self.name}: W = None (anchored) is only for directional tests "
                            "(signature=)")
        if self.W is not None and (int(self.W) != self.W or self.W < 1):
            raise DataError(f"test {self.name}: GLRT window W must be an integer >= 1, got {self.W}")
        if int(self.Z) != self.Z or self.Z < 1:
            raise DataError(f"test {self.name}: hold Z must be an integer >= 1, got {self.Z}")
        if self.signature is None and ("+" in self.residual or self.nuisance):
            raise DataError(f"test {self.name}: several residuals and nuisance signatures are only for "
                            "directional tests (signature=)")
        if self.signature is not None and self.signature in self.nuisance:
            raise DataError(f"test {self.name}: the tested signature {self.signature!r} is also a nuisance")
        object.__setattr__(self, "nuisance", tuple(str(n) for n in self.nuisance))

    @property
    def residuals(self) -> list[str]:
        """The residual channels (``"r3+r4"`` -> ``["r3", "r4"]``)."""
        return self.residual.split("+")

    @property
    def signature_channels(self) -> list[str]:
        """``"sig:<residual>:<signature>"`` per residual channel of a directional test, else []."""
        return [] if self.signature is None else [f"sig:{r}:{self.signature}" for r in self.residuals]

    @property
    def nuisance_channels(self) -> list[list[str]]:
        """Per nuisance parameter, its signature channel for each residual channel."""
        return [[f"sig:{r}:{q}" for r in self.residuals] for q in self.nuisance]

    @property
    def parameters(self) -> list[str]:
        """Parameters whose signatures the test reads (tested first)."""
        return [] if self.signature is None else [self.signature, *self.nuisance]

    @property
    def statistic_channel(self) -> str:
        """The statistic the hold rule reads: ``"<residual>:glrt"`` or ``"<name>:dglrt"``."""
        return f"{self.residual}:glrt" if self.signature is None else f"{self.name}:dglrt"


@dataclass
class TestBank:
    """Designed tests: residual calibration (mu0, sigma^2) and thresholds; runs them on records.

    Attributes
    ----------
    specs : list of TestSpec
    mu0, sigma2 : dict residual -> float
    thresholds : dict test -> float
    design : dict test -> dict (achieved_pfa on the design runs, runs, Z, pfa)
    """

    __test__ = False  # not a pytest class

    specs: list[TestSpec]
    mu0: dict[str, float]
    sigma2: dict[str, float]
    thresholds: dict[str, float]
    design: dict[str, dict] = field(default_factory=dict)

    @property
    def names(self) -> list[str]:
        return [s.name for s in self.specs]

    def processor(self, spec: TestSpec):
        """The statistic's processor: :class:`GLRT`, or :class:`DirectionalGLRT` for a directional test."""
        if spec.signature is None:
            return GLRT([spec.residual], self.mu0[spec.residual], self.sigma2[spec.residual], spec.W)
        m = [self.mu0[r] for r in spec.residuals]
        v = [self.sigma2[r] for r in spec.residuals]
        return DirectionalGLRT(spec.residuals, spec.signature_channels, m, v, spec.W, name=spec.name,
                               min_information=spec.min_information, nuisance=spec.nuisance_channels)

    def statistic(self, res: Signals, spec: TestSpec) -> Signals:
        """Statistic of ``spec`` on residual signals (the one channel :attr:`TestSpec.statistic_channel`)."""
        out = self.processor(spec).run(res)
        return out.select([spec.statistic_channel]) if spec.signature is not None else out

    def alarms(self, res: Signals) -> tuple[np.ndarray, np.ndarray]:
        """Outcome and first alarm time of every test.

        Returns
        -------
        fired : ndarray of bool (runs, n_tests)
            Alarm anywhere in the record.
        first : ndarray (runs, n_tests)
            Time of the first alarm (s from the start of the record), NaN if none.
        """
        fired = np.zeros((res.runs, len(self.specs)), bool)
        first = np.full((res.runs, len(self.specs)), np.nan)
        cache: dict[tuple, Signals] = {}
        for j, s in enumerate(self.specs):
            key = (s.residual, s.W, s.Z, s.signature, s.nuisance, self.thresholds[s.name])
            if key not in cache:
                st = self.statistic(res, s)
                cache[key] = Hold(st.names, self.thresholds[s.name], s.Z, absolute=False).run(st)
            al = cache[key]
            if s.gate is not None:
                al = TimeGated(al.names, 0.5, s.gate).run(al)
            a = al.values[:, :, 0] > 0.5
            fired[:, j] = a.any(axis=1)
            idx = a.argmax(axis=1)
            first[:, j] = np.where(fired[:, j], res.t[idx] - res.t[0], np.nan)
        return fired, first

    def to_dict(self) -> dict:
        return {"tests": [s.__dict__ for s in self.specs], "mu0": self.mu0, "sigma2": self.sigma2,
                "thresholds": self.thresholds,
                "design": {k: {kk: vv for kk, vv in v.items() if kk != "critical_values"}
                           for k, v in self.design.items()}}
