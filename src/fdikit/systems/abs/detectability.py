"""The Neyman-Pearson bound of the ABS faults (:func:`fdikit.evaluate.known_signal_dprime`).

:func:`abs_detectability` applies it to the ABS
plant over a window of the record in which the closed loop is smooth (before the ABS engages:
0.5-2.6 s after the start for the default stop), where the nominal measurements are close to
Gaussian and a fault's effect is one deterministic signal: ``delta`` is the noise-free
difference of the measurements between the faulty and the nominal plant (block-averaged to keep
the covariance well estimated), ``Sigma`` the covariance of the same quantities over noisy
nominal runs (measurement and process noise).

What it shows for this plant (measured, 4000 nominal runs, 5-sample blocks, 0.5-2.6 s)::

    fault            d' 23 dB   d' 17 dB   d' measurement noise only   Pd bound at 1e-4 (23 dB)
    F5 tau_m +15 %     0.97       0.55       8.97                        0.003
    F4 I_w +2 %        1.10       0.56      11.1                         0.004
    F3 K_f +2 %       15.4        7.8      157                           1.000

The process noise of Section III-A (on every state, 0.5 % of its mean square at 23 dB) swamps
the tau_m and I_w signatures before the ABS engages. After that, tau_m no longer acts at all: the
master-cylinder pressure has settled (eq. (5), tau_m = 0.02 s) long before the first valve
cycle, so every later sample depends on F5 only through the state it leaves behind at the window's
end, which differs from the nominal one by 0.3 standard deviations of the nominal spread across
runs (T_b: -0.49 against 1.69 N·m). Adding that state to the window's quantities bounds the
information of the *whole* record (``d_prime_whole_record_bound``). So F5 at its minimum size is
undetectable in this plant by *any* method: Table V's sensitivity is bounded by 6/7 (85.7 %)
here. I_w, in contrast, acts on every slip cycle once the ABS works (its r3 signature flips
sign with each cycle); summed over the stop, the directional GLRT of
:class:`fdikit.detect.DirectionalGLRT` collects about five standard deviations of evidence at
23 dB (:func:`fdikit.systems.abs.campaign.extended_tests`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import DataError
from ...evaluate.detectability import known_signal_dprime
from .plant import Scenario, simulate

__all__ = ["abs_detectability", "demo_summary"]


def abs_detectability(fault: str, magnitude: float, *, snr_db: float | None = 23.0, window=(0.5, 2.6),
                      block: int = 5, runs: int = 4000, seed: int = 0, pfa: float = 1e-4,
                      shrinkage: float = 0.05, scenario=None) -> dict[str, Any]:
    """The known-signal bound for one ABS fault over a window of the stop.

    Parameters
    ----------
    fault : str
        Fault class ("F1.1", ..., "F5").
    magnitude : float
        Relative parameter change (inside the class).
    snr_db : float or None
        Process-noise SNR of the nominal runs (None: measurement noise only).
    window : (float, float)
        Start and end of the window, s from the start of the record.
    block : int
        Samples averaged into one quantity (per measurement channel).
    runs : int
        Nominal noisy runs for the covariance (must exceed the number of quantities).
    pfa : float
        False-alarm probability of the bound ``Phi(d' - z_pfa)``.
    scenario : Scenario, optional
        The manoeuvre (default :class:`fdikit.systems.abs.plant.Scenario`); its fault, noise and
        measurement-noise settings are replaced.

    Returns
    -------
    dict
        ``d_prime``, ``d_prime_measurement_only`` (white measurement noise alone, no process
        noise), ``pd_bound`` (at ``pfa``), ``quantities``, ``state_delta_end`` (noise-free faulty
        minus nominal state at the window's end, x1..x6) and ``state_std_end`` (standard
        deviation of the nominal states across noisy runs there); ``parameter_acts_after_window``
        (whether the faulty parameter still changes the vector field or the output map at the
        nominal state at the window's end, relative change above 1e-9) and, when it does not,
        ``d_prime_whole_record_bound`` / ``pd_bound_whole_record``: the bound with the state at
        the window's end added to the quantities, which covers every later sample too (they
        depend on the fault only through that state); and the settings.

    Examples
    --------
    >>> b = abs_detectability("F3", 0.02, runs=400, block=20)
    >>> b["d_prime"] > 5
    True
    """
    from dataclasses import replace

    from scipy.stats import norm

    from .plant import FAULT_CLASSES, Scenario, simulate

    if fault not in FAULT_CLASSES or fault == "F0":
        raise DataError(f"fault must be one of {[f for f in FAULT_CLASSES if f != 'F0']}, got {fault!r}")
    base = Scenario() if scenario is None else scenario
    t0, t1 = (float(w) for w in window)
    k0, k1 = round(t0 / base.sample_dt), round(t1 / base.sample_dt)
    if not (0 <= k0 < k1 <= base.n_samples):
        raise DataError(f"window {window} s must lie inside the {base.t_end} s record")
    if int(block) != block or block < 1 or (k1 - k0) < block:
        raise DataError(f"block must be an integer in [1, {k1 - k0}], got {block}")
    if not 0 < pfa < 1:
        raise DataError(f"pfa must be in (0, 1), got {pfa}")
    nb = (k1 - k0) // block
    k1 = k0 + nb * block

    def blocks(y):
        return y[:, k0:k1, :].reshape(y.shape[0], nb, block, 2).mean(axis=2).reshape(y.shape[0], -1)

    quiet = dict(snr_db=None, meas_var=0.0)
    stride = base.substeps
    nom = simulate(None, replace(base, fault="F0", magnitude=None, **quiet), runs=1, seed=seed,
                   keep_states=True, state_stride=stride)
    bad = simulate(None, replace(base, fault=fault, magnitude=float(magnitude), **quiet), runs=1, seed=seed,
                   keep_states=True, state_stride=stride)
    delta = (blocks(bad.y.values) - blocks(nom.y.values))[0]
    if runs <= delta.size:
        raise DataError(f"runs ({runs}) must exceed the {delta.size} quantities (widen block or add runs)")
    noisy = simulate(None, replace(base, fault="F0", magnitude=None, snr_db=snr_db), runs=runs, seed=seed + 1,
                     keep_states=True, state_stride=stride)
    Y = blocks(noisy.y.values)
    dp = known_signal_dprime(delta, Y, shrinkage=shrinkage)
    dp_meas = float(np.sqrt(np.sum(delta**2) / (base.meas_var / block)))
    ke = min(k1, nom.x.n_samples) - 1
    # does the faulty parameter still act at the window's end? (vector field and output map at the
    # nominal state there; 0 for tau_m once P_m has settled)
    from .plant import ABSPlant

    plant = ABSPlant()
    p0 = dict(plant.params)
    p1 = dict(p0)
    p1[FAULT_CLASSES[fault].param] *= 1.0 + float(magnitude)
    te = ke * base.sample_dt
    x = nom.x.values[0, ke][None]
    u = np.zeros((1, 9))
    u[0, 0] = plant.pedal_force(te, base.t_brake, base.pedal_ramp if base.pedal == "ramp" else None)
    u[0, 1:3] = nom.u.values[0, min(ke, nom.u.n_samples - 1), 1:3]
    f0, f1 = plant.f(te, x, u, p0), plant.f(te, x, u, p1)
    h0, h1 = plant.h(te, x, u, p0), plant.h(te, x, u, p1)
    change = max(float(np.max(np.abs(f1 - f0) / (np.abs(f0) + 1.0))),
                 float(np.max(np.abs(h1 - h0) / (np.abs(h0) + 1.0))))
    acts = change > 1e-9
    # window data plus the state at its end: if the parameter no longer acts, every later sample
    # depends on the fault only through that state, so this bounds the information of the record
    Xe = noisy.x.values[:, ke]
    dxe = bad.x.values[0, ke] - nom.x.values[0, ke]
    dp_state = known_signal_dprime(np.concatenate([delta, dxe]), np.hstack([Y, Xe]), shrinkage=shrinkage)
    return {
        "fault": fault, "magnitude": float(magnitude), "snr_db": snr_db, "window": [t0, k1 * base.sample_dt],
        "block": int(block), "quantities": int(delta.size), "runs": int(runs), "pfa": float(pfa),
        "d_prime": dp, "d_prime_measurement_only": dp_meas,
        "pd_bound": float(norm.sf(norm.isf(pfa) - dp)),
        "pd_bound_measurement_only": float(norm.sf(norm.isf(pfa) - dp_meas)),
        "parameter_acts_after_window": bool(acts), "relative_vector_field_change_end": change,
        "d_prime_with_state": dp_state,
        "d_prime_whole_record_bound": None if acts else dp_state,
        "pd_bound_whole_record": None if acts else float(norm.sf(norm.isf(pfa) - dp_state)),
        "state_delta_end": dxe.tolist(),
        "state_std_end": noisy.x.values[:, ke].std(axis=0).tolist(),
        "max_abs_output_delta": float(np.max(np.abs(bad.y.values[0, k0:k1] - nom.y.values[0, k0:k1]))),
        "shrinkage": float(shrinkage), "z_pfa": float(norm.isf(pfa)),
        "note": "upper bound on Pd of any detector using this window (Neyman-Pearson, known signal)",
        "pd_bound_formula": "Phi(d' - z_pfa)",
    }


def demo_summary(details: dict | None = None) -> dict[str, Any]:
    """``fdikit demo`` section: the I_w fault the paper's tests miss, the tau_m fault nobody can see.

    Designs the extended ABS tests on 300 nominal runs (pfa 1 % per test), runs 20 nominal stops,
    20 with I_w -2 % and 20 with tau_m +15 % (23 dB; the tau_m stops with the nominal stops' noise,
    so that the same tests firing in both shows the fault changes nothing), and reports which tests
    fired, the directional test's estimate of the I_w change, and the Neyman-Pearson bound of the
    tau_m fault (800 nominal runs).

    ``details``, when given, receives ``bank`` (the designed tests) and ``cases``: per label, the
    ``fault``, ``magnitude``, ``residuals`` (Signals of the 20 runs) and ``fired`` (runs, tests),
    for the demo's report.

    Returns
    -------
    dict
    """
    import time

    from .campaign import abs_residuals, design_tests, extended_tests, residual_generators

    t0 = time.perf_counter()
    specs = extended_tests(40)
    bank = design_tests(specs, design_runs=300, pfa=0.01, seed=3)
    gens = residual_generators(specs)
    out: dict[str, Any] = {}
    for label, fault, mag in (("nominal (false alarms)", "F0", None), ("I_w -2 %", "F4", -0.02),
                              ("tau_m +15 % (same noise as nominal)", "F5", 0.15)):
        res = simulate(None, Scenario(fault=fault, magnitude=mag), runs=20, seed=4)
        r = abs_residuals(res.y.concat_channels(res.u), gens)
        fired, _ = bank.alarms(r)
        if details is not None:
            details.setdefault("cases", {})[label] = {"fault": fault, "magnitude": mag, "residuals": r,
                                                      "fired": fired}
        rates = {n: float(fired[:, j].mean()) for j, n in enumerate(bank.names)}
        row = {"fired_fraction": {k: v for k, v in rates.items() if v > 0} or "none"}
        if fault == "F4":
            spec = next(s for s in specs if s.name == "G_D_Iw")
            eta = bank.processor(spec).run(r)[f"{spec.name}:eta"][:, -1]
            row["I_w_change_estimate_median"] = round(float(np.median(eta)), 4)
        out[label] = row
    b = abs_detectability("F5", 0.15, runs=800, block=10)
    out["tau_m +15 % bound"] = (f"d' = {b['d_prime_whole_record_bound']:.2f} over the whole record: any "
                                f"detector's Pd <= {b['pd_bound_whole_record']:.4f} at Pfa 1e-4")
    out["seconds"] = round(time.perf_counter() - t0, 2)
    if details is not None:
        details["bank"] = bank
    return out
