"""Monitor config recipe of the aircraft (``examples/aircraft-smo/monitor.toml``): the cascaded
sliding-mode reconstructor designed for the nominal model."""

from __future__ import annotations

__all__ = ["design"]


def design(params: dict | None = None) -> dict:
    """Design recipe for a config-driven monitor (``fdikit design``): ``{"smo": reconstructor}``.

    ``params``: ``dt`` (the observers' fixed step and the log's sample time, default 1e-4 s; with
    the implicit switching step the reconstruction error at 1e-4 is about 1e-4 of the fault),
    ``rho``, ``delta`` (switching gain and boundary layer, defaults 100 and 1e-5).
    """
    from ...residuals.smo import design_reconstructor
    from .plant import model

    p = {"dt": 1e-4, "rho": 100.0, "delta": 1e-5, **(params or {})}
    rec = design_reconstructor(model(), dt=float(p["dt"]), rho=float(p["rho"]), delta=float(p["delta"]),
                               rho2=float(p["rho"]), delta2=float(p["delta"]))
    return {"smo": rec}
