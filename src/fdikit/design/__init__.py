"""Designs shared by the residual generators: the LMIs of the sliding mode observers
(ng-tan-edwards-kuang, after Tan & Edwards 2001 and 2003), solved with cvxpy + Clarabel."""

from .smo_lmi import PrimaryGains, SecondaryGains, primary_smo_lmi, secondary_smo_lmi

__all__ = ["PrimaryGains", "SecondaryGains", "primary_smo_lmi", "secondary_smo_lmi"]
