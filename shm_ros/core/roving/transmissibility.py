"""Roving components of merged modes from the references' transmissibility in each setup.

A setup's own identification is short: two modes a few per cent apart (a vertical bending mode next
to a torsion mode) are mixed or missed at the model orders it picks, and the roving component it
reports can be off by tens of per cent even where its frequency is right. After the merge the
references' shape ``g`` of every mode is known from all setups, and in a band where the references
see at most as many modes as there are references, the roving channels follow the references
through one frequency-independent transmissibility ``H = Phi_p Phi_r^+``; then ``phi_p = H g``.

In each setup, for each merged mode: the short-time spectra of the references ``X_r`` and of the
roving channels ``X_p`` (Hann segments of ``segment_s``, half overlap) over the bins within
``width * zeta * f`` (plus half a bin) of the mode's frequency in that setup (its own estimate where
it found the mode, the merged one elsewhere, so a frequency moved by the robot's mass is followed);
``H`` is the least-squares fit ``X_p ~ H X_r`` over those bins and segments (the multi-reference
transmissibility ``S_pr S_rr^-1``), and the component is ``Re(H g)``, on the merged reference scale
with no rescaling step. Its standard error is the fit's: ``s^2 g^H S_rr^-1 g / 2`` with ``s^2`` the
residual power per bin, doubled for the half-overlapping segments. A mode missing in a setup's
picks gets that setup's components too.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.signal as sig

from shm_ros.core.roving.merge_post import GlobalMode
from shm_ros.core.types import ModalEstimate
from shm_ros.errors import InputError

__all__ = ["roving_components", "apply_transmissibility"]

SEGMENT_S = 8.0
WIDTH = 1.0  # half-band in half-power half-widths (zeta f)
MIN_SEGMENT = 16  # samples
OWN_TOL = 0.01  # a setup's own mode within this of the merged frequency gives that setup's frequency


def roving_components(y: np.ndarray, fs: float, n_ref: int, frequency_hz: float, damping: float,
                      ref_shape: np.ndarray, segment_s: float = SEGMENT_S, width: float = WIDTH
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Components (and standard errors) of the channels ``y[:, n_ref:]`` for the mode whose
    reference components (``y[:, :n_ref]``) are ``ref_shape`` (see module doc)."""
    n = int(min(segment_s * fs, y.shape[0] // 4))  # at least 4 segments
    nan = np.full(y.shape[1] - n_ref, np.nan)
    if n < MIN_SEGMENT:
        return nan, nan
    f, _, x = sig.stft(y.T, fs=fs, window="hann", nperseg=n, noverlap=n // 2, detrend="constant",
                       boundary=None, padded=False)  # (channels, bins, segments)
    band = np.abs(f - frequency_hz) <= width * max(damping, 1e-3) * frequency_hz + 0.5 * fs / n
    xr = x[:n_ref, band, :].reshape(n_ref, -1)
    xp = x[n_ref:, band, :].reshape(y.shape[1] - n_ref, -1)
    m = xr.shape[1]
    if m <= 2 * n_ref:
        return nan, nan
    srr = xr @ xr.conj().T
    h = np.linalg.solve(srr.T, (xp @ xr.conj().T).T).T  # (roving, refs): X_p X_r^H S_rr^-1
    g = np.asarray(ref_shape, dtype=float)
    resid = xp - h @ xr
    s2 = 2.0 * np.sum(np.abs(resid) ** 2, axis=1) / (m - n_ref)  # x2: half-overlapping segments
    var = s2 * float(np.real(g @ np.linalg.solve(srr, g))) / 2
    return (h @ g).real, np.sqrt(var)


def apply_transmissibility(modes: Sequence[GlobalMode], data: Sequence[np.ndarray], fs: Sequence[float],
                           estimates: Sequence[ModalEstimate], references: Sequence[str],
                           segment_s: float = SEGMENT_S, width: float = WIDTH) -> None:
    """Replace every merged mode's roving components (and their ``shape_std``) by the setups'
    transmissibility ones, in place. ``data[k]``: setup ``k``'s channels in the order of
    ``estimates[k].sensor_ids``, the references first."""
    r = len(references)
    for g in modes:
        ref = np.array([g.shape[name] for name in references])
        shape, std = dict(g.shape), dict(g.shape_std)  # kept where a setup is too short for spectra
        for y, rate, est in zip(data, fs, estimates, strict=True):
            if list(est.sensor_ids[:r]) != list(references):
                raise InputError(f"a setup's channels {est.sensor_ids} must start with the references {references}")
            own = [m.frequency_hz for m in est.modes if abs(m.frequency_hz / g.frequency_hz - 1) <= OWN_TOL]
            f0 = min(own, key=lambda f: abs(f - g.frequency_hz)) if own else g.frequency_hz
            val, err = roving_components(y, rate, r, f0, g.damping_ratio, ref, segment_s, width)
            for name, v, e in zip(est.sensor_ids[r:], val, err, strict=True):
                if np.isfinite(v):
                    shape[name], std[name] = float(v), float(e)
        top = max((v for v in shape.values() if np.isfinite(v)), key=abs)
        g.shape = {k: v / top for k, v in shape.items()}
        g.shape_std = {k: v / abs(top) for k, v in std.items()}
        if g.missing_setups:
            g.notes = [n.replace("; no shape at the points only those setups measured", "") for n in g.notes]
            g.notes.append("the roving components at every setup's points come from the references' "
                           "transmissibility, those of the setups that did not find the mode included")
