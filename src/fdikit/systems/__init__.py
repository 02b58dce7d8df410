"""The papers' systems, each a package built end to end on the public core (plant -> residuals ->
tests -> isolation -> monitor -> campaign):

* :mod:`fdikit.systems.abs` -- the ABS integrated diagnosis (luo-et-al);
* :mod:`fdikit.systems.car` -- the passenger-car health monitor and the real RAV4 (ng-chen-speyer);
* :mod:`fdikit.systems.aircraft` -- robust actuator fault reconstruction (ng-tan-edwards-kuang);
* :mod:`fdikit.systems.two_mass` -- a small linear example.

The core never imports a system, and no system imports another (import-linter contracts in
``pyproject.toml``).
"""

__all__ = ["abs", "aircraft", "car", "two_mass"]
