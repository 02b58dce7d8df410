"""The RAV4's redundant groups (issue 27): the signals the generic peer checks and fault-type
classifier read (:class:`Rav4PeerSignals`) and their design on the calibration half
(:func:`design_peer_stages`).

Two groups: the four wheel speeds (each against the other three), and the yaw rate as the gyro,
the accelerometer (``a_y / U``), the steering model and the two axles' wheel-speed differences say
it (each against the others; the wheel-derived members only serve as peers, their faults belong to
the wheel group).

The wheel group's reference is the speed squared (``sig:speed_sq``, the four wheels' median): on the
real minute the front wheels read slower than the rear ones the more, the lower the speed (the
residual of a front wheel against its peers, fitted as an affine map of their median on 16-20 m/s,
falls to -0.17 m/s at 8 m/s), which an affine map on the peers' median alone does not follow. The
wheels are fitted on the whole calibration half (8-20 m/s; wheel speeds need no warm-up) and their
thresholds target one false alarm per 10 minutes (the yaw group too, low-passed at 0.1 Hz: its
yaw-rate threshold 0.0095 rad/s, before per hour at 0.2 Hz 0.0188 rad/s = 1.08 deg/s, above the
0.5-1 deg/s biases the MHSSPT announces untyped). The MHSSPT's alarms of the yaw rate, the
accelerometer and the steering also start the fault typing of that sensor (``isolated_by``,
while its peer statistic is >= 0.5), so what the MHSSPT isolates first is typed too. Measured on the minute
(:func:`run_rav4_log`, whole monitor): the nominal wheel statistic peaks at 0.67 of its threshold,
no announcement; a 1 % gain of WHEEL_SPEED_FL from 20 s / 50 s is announced on that wheel after
1.6 s / 2.3 s, of WHEEL_SPEED_RR after 1.0 s / 1.1 s (gain 0.99: FL 1.1 / 1.2 s, RR 1.5 / 2.3 s),
typed a bias first and revised to a gain 5-10 s later. Before (fit on 16-20 m/s only, no
reference, per hour), the nominal peak was 0.85 of the threshold, reached at 11 m/s in the
held-out half, and a 1 % gain of WHEEL_SPEED_FL was not announced. Lower thresholds do not pay:
at one false alarm per minute the 1 % gains take 0.5-0.8 s but the nominal minute peaks at 1.12
(false isolations).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ....errors import DataError
from ....signals import Signals
from ..monitor.peers import PeerSignalsBase
from ..rav4 import RAV4
from .channels import _RAW_U, _RAW_Y, Rav4Preprocessing

__all__ = ["PEER_GROUPS", "PEER_RATES", "PEER_REFERENCES", "PEER_SENSORS", "Rav4PeerSignals",
           "design_peer_stages"]

#: Redundant groups: group -> members (channels of :class:`Rav4PeerSignals`).
PEER_GROUPS = {"wheels": ["sig:wheel_fl", "sig:wheel_fr", "sig:wheel_rl", "sig:wheel_rr"],
               "yaw": ["sig:yaw_rate", "sig:lateral_accelerometer", "sig:steering", "sig:yaw_front",
                       "sig:yaw_rear"]}
#: Group -> reference channels of :class:`Rav4PeerSignals` (affine terms of each member's fit).
PEER_REFERENCES = {"wheels": ["sig:speed_sq"], "yaw": []}
#: Group -> channels whose rate of change is an affine term too (:class:`~fdikit.detect.PeerCheck`'s
#: ``rates``): the wheels' longitudinal slip under braking and traction moves a wheel's speed by about
#: ``a U``, the rate of ``U^2 / 2`` (issue 27: without it a front wheel's residual keeps a slope of
#: 0.014-0.022 per m/s of speed through the held-out half's braking, the size of a 1-2 % gain, so
#: that small wheel gains could not be told from biases; with it 0.002-0.006).
PEER_RATES = {"wheels": ["sig:speed_sq"], "yaw": []}
#: Members that name a sensor -> that sensor (the others are peers only).
PEER_SENSORS = {"sig:wheel_fl": "wheel_fl", "sig:wheel_fr": "wheel_fr", "sig:wheel_rl": "wheel_rl",
                "sig:wheel_rr": "wheel_rr", "sig:yaw_rate": "yaw_rate",
                "sig:lateral_accelerometer": "lateral_accelerometer", "sig:steering": "steering"}
#: Raw channel of each sensor (for the stuck check).
_RAW_OF = {"sig:wheel_fl": "raw:wheel_fl", "sig:wheel_fr": "raw:wheel_fr", "sig:wheel_rl": "raw:wheel_rl",
           "sig:wheel_rr": "raw:wheel_rr", "sig:yaw_rate": "raw:yaw_rate",
           "sig:lateral_accelerometer": "raw:accel_y", "sig:steering": "raw:steer_angle"}


#: The channel of each member's zero offset that the signal conditioning removed, in the member's
#: units (:class:`Rav4PeerSignals` outputs; the wheels have none): a gain of the raw sensor makes the
#: member's residual ``(g - 1) (x + offset)``, the fault-type stage's ``gain_offset``.
GAIN_OFFSETS = {"sig:yaw_rate": "zero:sig:yaw_rate",
                "sig:lateral_accelerometer": "zero:sig:lateral_accelerometer",
                "sig:steering": "zero:sig:steering"}


class Rav4PeerSignals(PeerSignalsBase):
    """The members of the RAV4's redundant groups and the raw sensor values, from the raw CAN channels.

    ``sig:wheel_*`` (m/s); in rad/s: ``sig:yaw_rate`` (the gyro, offset removed),
    ``sig:lateral_accelerometer`` (``a_y / U``), ``sig:steering`` (kinematic steering,
    ``(steer - c_0) U / L``; the peer check fits its gain and sign), ``sig:yaw_front`` /
    ``sig:yaw_rear`` (each axle's wheel-speed difference over ``k_f`` / ``k_r``); ``sig:speed_sq``
    the median of the four wheel speeds squared (m^2/s^2, the wheels' reference); ``raw:*`` the raw
    sensor values.
    Stateless.

    Parameters
    ----------
    pre : Rav4Preprocessing
    steer : sequence of 3 floats
        ``c_1, c_2, c_0`` of the steering model (:class:`Rav4SensorChannels` ``coef["steer"]``).
    k_f, k_r : float
        Wheel-speed difference per yaw rate (m/s per rad/s).
    """

    _state_attrs = ()

    def __init__(self, pre: Rav4Preprocessing, steer, k_f: float, k_r: float):
        self.pre = pre
        self.steer = [float(c) for c in steer]
        self.k_f, self.k_r = float(k_f), float(k_r)
        if len(self.steer) != 3 or not (self.k_f and self.k_r):
            raise DataError(f"steer needs 3 coefficients and k_f, k_r must be non-zero; "
                            f"got {steer}, {k_f}, {k_r}")
        self.u_names, self.y_names = list(_RAW_U), list(_RAW_Y)
        self.output_names = ([m for ms in PEER_GROUPS.values() for m in ms] + ["sig:speed_sq"]
                             + sorted(set(_RAW_OF.values())) + list(GAIN_OFFSETS.values()))
        self.output_units = (["m/s"] * 4 + ["rad/s"] * 5 + ["m^2/s^2"] + ["-"] * len(set(_RAW_OF.values()))
                             + ["rad/s"] * len(GAIN_OFFSETS))

    def __repr__(self) -> str:
        return f"Rav4PeerSignals(steer={self.steer}, k_f={self.k_f:g}, k_r={self.k_r:g})"

    def to_dict(self) -> dict[str, Any]:
        return {"pre": self.pre.to_dict(), "steer": self.steer, "k_f": self.k_f, "k_r": self.k_r}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Rav4PeerSignals:
        return cls(Rav4Preprocessing.from_dict(d["pre"]), d["steer"], d["k_f"], d["k_r"])

    def _columns(self, u: np.ndarray, y: np.ndarray) -> list[np.ndarray]:
        uu, yy = self.pre.apply(u, y)
        U = np.maximum(uu[..., 1], 1.0)
        c0 = self.steer[2]
        raw = {"raw:wheel_fl": y[..., 2], "raw:wheel_fr": y[..., 3], "raw:wheel_rl": y[..., 4],
               "raw:wheel_rr": y[..., 5], "raw:yaw_rate": y[..., 0], "raw:accel_y": y[..., 1],
               "raw:steer_angle": u[..., 0]}
        cols = [y[..., 2], y[..., 3], y[..., 4], y[..., 5], yy[..., 1], yy[..., 0] / U,
                (uu[..., 0] - c0) * U / RAV4["L"], yy[..., 2] / self.k_f, yy[..., 3] / self.k_r,
                np.median(y[..., 2:6], axis=-1) ** 2]
        p = self.pre
        # what the conditioning removed from each member, in its units: a gain of the raw sensor
        # scales the member plus this (the yaw-rate offset; the accelerometer's over U; the steering
        # member's c_0 and the hand-wheel angle's fine part and offset)
        zero = [p.b_r + 0.0 * U, (p.ay_sign * p.b_ay) / U,
                (c0 - (u[..., 1] - p.delta_0) / p.i_s) * U / RAV4["L"]]
        return cols + [raw[n] for n in sorted(raw)] + zero


#: the fault-type stage's isolation with the CUSUM (PeerCUSUM merges the peer check's); its statistic
#: stays the peer check's (the MHSSPT's isolated_by flags need it >= confirm: the merged one, grown by
#: a CUSUM that a faulty peer moves, let the MHSSPT's "steering" type a yaw-rate drift)
_CUSUM_CHANNELS = {"isolated": "cusum:{m}:isolated"}


def design_peer_stages(sig: Signals, dt: float, *, skip: int, warmup: int, band_hz=None,
                       stuck_margin: float = 1.0, window_s: float = 30.0, lookback_s: float = 5.0,
                       clear_after_s: float = 5.0, pfa: float = 1.0, per=None, fit_skip=None,
                       margin: float = 0.0, block_s: float = 0.5, gain_crit: float = 25.0,
                       isolated_by=None, confirm: float = 0.5, gain_margin: float = 1.5,
                       cusum: bool = True, cusum_nu: float = 1.0, cusum_margin: float = 0.5,
                       cusum_groups: tuple[str, ...] = ("yaw",), revise_after_s: float = 1.0,
                       revise_conf: float = 0.6, rates=None, rate_hz: float = 0.5,
                       typing_fit_hz=None, cusum_transfer: bool = True, gain_offset: bool = True):
    """The peer check and the fault-type classifier designed on nominal :class:`Rav4PeerSignals`
    outputs ``sig`` (the calibration half).

    Each group of :data:`PEER_GROUPS` is fitted and thresholded on its own
    (:func:`~fdikit.detect.design_peer_check`, references :data:`PEER_REFERENCES`, rate channels
    ``rates``, default :data:`PEER_RATES`, their filter's cut-off ``rate_hz``): ``band_hz``
    (default 0.2 Hz for the wheels, 0.1 Hz for the yaw group), ``per`` (the false-alarm period of
    ``pfa``; default 10 minutes each) and ``fit_skip`` (samples left out of the fit and the
    thresholds; default 0 for the wheels, ``skip`` for the yaw group, whose members are low-passed)
    are per group; ``skip`` also bounds the classifier's nominal statistics, ``warmup`` the samples
    during which nothing is isolated; ``block_s`` and ``gain_crit`` are the classifier's gain test
    (block length in seconds: 0.5 s averages the 12.5 Hz wheel-hop out; the block-mean noise
    ``sigma_block`` from the nominal residual; per member the level is at least ``gain_margin``
    times the largest gain statistic of the nominal residual over a window); ``isolated_by`` the
    classifier's further isolation flags per member (the MHSSPT's alarms), which count while the
    member's peer statistic is at least ``confirm``. The merged :class:`~fdikit.detect.PeerCheck`
    holds the groups in the order of :data:`PEER_GROUPS`.

    With ``cusum`` a :class:`~fdikit.detect.PeerCUSUM` (drift ``cusum_nu`` nominal standard
    deviations, threshold the nominal maximum times ``1 + cusum_margin``) on the members of
    ``cusum_groups`` (the yaw group: the wheels' residuals follow the speed, and a CUSUM tuned on
    the calibration half alarms on the held-out half) isolates what the peer check's threshold
    misses; the classifier reads its merged outputs. With ``cusum_transfer`` (default) a peer only
    (``sig:yaw_front``, ``sig:yaw_rear``) that is the group's largest no longer hides the largest
    announced member when its excess is what that member's fault explains through the median of its
    peers plus its own threshold (:func:`~fdikit.detect.design_peer_cusum` ``coef``). Measured (issue
    27, the cases where a raw Page-Hinkley still won): small yaw-group faults were missed because
    ``sig:yaw_rear``, whose reference is the median of 4 peers (the mean of the middle two: it moves
    by up to half of a faulty peer's shift) and whose threshold is the group's tightest, had the
    largest CUSUM (``bias:STEER_ANGLE:-1.5@40``: steering 2.0, yaw_rear 3.9 at 45 s); its fault-free
    CUSUM also reaches 1.4 on the held-out half (58 s), hence the ``+ 1``. Full grid, before -> with
    the transfer: yaw-rate gain 17 -> 18 of 18, steering bias 17 -> 18, drift 15 -> 18, accelerometer
    gain 6 -> 9, detected 482 -> 490 of 525, right component 475 -> 483 (98.6 %), 0 announcements
    before an onset and on the fault-free minute both, <= 1 wrong after the onset 521 both (the bound
    without the ``+ 1``: 486 detected; no peer-only veto at all: 490 detected but <= 1 wrong after the
    onset 462, yaw-group sensors named for wheel faults). Tried and not kept: a drift ``cusum_nu`` of 2
    announced ``lateral_accelerometer:bias`` at 56.1 s on the fault-free minute; 3 put three thresholds
    on their floor (a 3-sigma level test) and lost two yaw gains and a steering intermittent; a yaw
    group without ``sig:yaw_front`` (medians of 3) false-alarmed likewise. A CUSUM on the wheels
    (``cusum_groups`` with ``"wheels"``) announces a 1 % front-left gain from 50 s after 2.0 s but
    ``wheel_rl:bias`` twice on the fault-free minute.

    The stuck check waits for the longest run of equal raw samples of the calibration half times
    ``1 + stuck_margin`` (at least 0.5 s). For the steering (``STEER_ANGLE``, 1.5 deg steps) that
    run is 5.78 s, so ``stuck_after`` is 11.56 s; the held-out half holds a fault-free run of 7.82 s
    (25.66-33.48 s), so a margin below 0.36 announces ``steering:stuck`` on the fault-free minute (0.3:
    at 33.4 s) and 0.5 would leave 11 %: the margin stays 1. (A frozen ``STEER_ANGLE`` alone leaves
    ``STEER_FRACTION`` moving, so the measured angle still moves within +-0.7 deg and only this check
    sees it: ``stuck:STEER_ANGLE@35`` after 11.3 s; the whole message frozen,
    ``stuck:STEER_ANGLE_SENSOR@35``, is announced after 3.9 s by the stuck check against the steering
    the yaw rate says.)

    The announced type has hysteresis (issue 27): a revised type must win for ``revise_after_s``
    seconds in a row with a confidence of at least ``revise_conf``, and a drift never falls back to
    a bias (:class:`~fdikit.isolate.FaultTypeClassifier`'s ``revise_after``; 0 s: none); and the
    classifier's episode does not clear while the sensor is isolated (``hold_while_isolated``).

    The classifier's residual and signal come from a second :class:`~fdikit.detect.PeerCheck`
    (prefix ``tpeer``) with the rate terms ``rates`` (default :data:`PEER_RATES`), its groups
    fitted at the cut-off ``typing_fit_hz`` (group -> Hz, default ``{"yaw": 1.0}``:
    :func:`~fdikit.detect.design_peer_check`'s ``fit_hz``; the sample-wise fit of the yaw rate on
    its noisy peers gives a prediction whose 0.5 s block means move 2.5 times less than the gyro's,
    so that a nominal yaw rate looked like a gain of 2.5 to the gain test and its level had to be
    56.6; fitted at 1 Hz the block means agree, slope 0.98 on the held-out half, and the level is
    the floor, 25); detection and isolation stay on the first check (no second check when
    ``rates`` and ``typing_fit_hz`` are empty).

    With ``gain_offset`` (default) the classifier's gain test reads, for the yaw rate, the lateral
    accelerometer and the steering, the reference plus the zero offset the conditioning removed
    (:data:`GAIN_OFFSETS`): a gain of the raw sensor scales that offset too. Measured (issue 27,
    full grid of ``bench_sensor_faults.py``, with the classifier's one-parameter gain-against-step
    test): yaw-rate gains typed gain 4 -> 14 of 18 (3 of the others are x0, typed stuck),
    accelerometer gains 0 -> 3 of 9, wheel gains 38 -> 51 of 70 (no offset: the same test on the
    speed's moves), right type 425 -> 452 of 483 (88.0 -> 93.6 %), no bias typed otherwise.

    Returns
    -------
    (PeerCheck, PeerCUSUM or None, PeerCheck for the typing or None, FaultTypeClassifier,
    dict alarm channel -> announced name)
    """
    from ....detect import PeerCheck, design_peer_check, design_peer_cusum
    from ....isolate import FAULT_TYPES, FaultTypeClassifier

    band = {"wheels": 0.2, "yaw": 0.1, **(band_hz or {})}
    per = {"wheels": 600.0, "yaw": 600.0, **(per or {})}
    fit_skip = {"wheels": 0, "yaw": skip, **(fit_skip or {})}
    rates = PEER_RATES if rates is None else {g: list(rates.get(g, [])) for g in PEER_GROUPS}

    def check(rt, prefix, fit_hz=None):
        fit_hz = dict(fit_hz or {})
        parts = [design_peer_check(sig, {g: ms}, references={g: PEER_REFERENCES[g]}, band_hz=band[g],
                                   announce=[m for m in ms if m in PEER_SENSORS], skip=fit_skip[g], pfa=pfa,
                                   per=per[g], margin=margin, rates={g: rt.get(g, [])}, rate_hz=rate_hz,
                                   fit_hz=fit_hz.get(g))
                 for g, ms in PEER_GROUPS.items()]
        return PeerCheck(PEER_GROUPS, {m: c for p in parts for m, c in p.coef.items()},
                         {m: h for p in parts for m, h in p.thresholds.items()}, parts[0].dt,
                         references=PEER_REFERENCES, band_hz={g: band[g] for g in PEER_GROUPS},
                         announce=list(PEER_SENSORS), warmup=warmup, rates=rt, rate_hz=rate_hz, prefix=prefix)

    pc = check({}, "peer")
    nom = pc.run(sig)
    # the fault-type stage reads a second check with the rate terms (its residual and reference: a
    # gain's slope on the signal without the slip's); detection stays on the first, whose thresholds
    # the rate terms would tighten on the calibration half below what the held-out half reaches
    typing_fit_hz = {"yaw": 1.0} if typing_fit_hz is None else dict(typing_fit_hz)
    tc = check(rates, "tpeer", typing_fit_hz) if any(rates.values()) or typing_fit_hz else None
    tnom = tc.run(sig) if tc is not None else nom
    P = tc.prefix if tc is not None else "peer"
    sigma = {m: float(np.std(tnom[f"{P}:{m}:e"][0, skip:])) for m in PEER_SENSORS}
    blk = max(1, round(block_s / dt))
    sig_blk = {}
    for m in PEER_SENSORS:
        e = tnom[f"{P}:{m}:e"][0, skip:]
        sig_blk[m] = float(np.std(e[:e.size // blk * blk].reshape(-1, blk).mean(axis=1)))
    stuck_after = {}
    for m, rawc in _RAW_OF.items():
        x = sig[rawc][0, skip:]
        run = longest = 0
        for same in np.diff(x) == 0:
            run = run + 1 if same else 0
            longest = max(longest, run)
        stuck_after[m] = max(int(np.ceil((longest + 1) * (1.0 + stuck_margin))), round(0.5 / dt))
    n = lambda s: max(1, round(s / dt))  # noqa: E731
    # the gain test's level per member: above what the nominal residual's own (model-error) slope
    # on the signal reaches over a classifier window of the calibration half, with a margin
    from ....isolate.fault_type import _gain_test

    crit = {}
    for m in PEER_SENSORS:
        e, x = tnom[f"{P}:{m}:e"][0, skip:], tnom[f"{P}:{m}:ref"][0, skip:]
        w = min(n(window_s), e.size)
        fb = [_gain_test(e[k:k + w], x[k:k + w], blk, sig_blk[m])[0]
              for k in range(0, e.size - w + 1, n(1.0))]
        crit[m] = max(gain_crit, gain_margin * max(fb, default=0.0))
    ftc = FaultTypeClassifier(list(PEER_SENSORS), sigma, n(window_s), raw=_RAW_OF, stuck_after=stuck_after,
                              gain_offset=GAIN_OFFSETS if gain_offset else None,
                              lookback=n(lookback_s), min_len=n(0.2), spike_max=n(0.2), burst_gap=n(0.5),
                              clear_after=n(clear_after_s), isolated_by=isolated_by, confirm=confirm,
                              block=blk, sigma_block=sig_blk,
                              gain_crit=crit, revise_after=n(revise_after_s) if revise_after_s > 0 else 0,
                              revise_conf=revise_conf, hold_while_isolated=revise_after_s > 0,
                              channels={**(_CUSUM_CHANNELS if cusum else {}), "r": P + ":{m}:e",
                                        "x": P + ":{m}:ref"})
    names = {f"{m}:{t}": f"{s}:{t}" for m, s in PEER_SENSORS.items() for t in FAULT_TYPES}
    cu = None
    if cusum:
        groups = {g: list(PEER_GROUPS[g]) for g in cusum_groups}
        ann = [m for ms in groups.values() for m in ms if m in PEER_SENSORS]
        rest = [m for g in PEER_GROUPS if g not in cusum_groups for m in PEER_GROUPS[g] if m in PEER_SENSORS]
        cu = design_peer_cusum(nom, groups, skip=skip, nu=cusum_nu, margin=cusum_margin, warmup=warmup,
                               passthrough=rest, announce=ann, coef=pc.coef if cusum_transfer else None)
    return pc, cu, tc, ftc, names
