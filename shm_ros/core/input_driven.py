"""Which identified modes carry the measured input to the sensors.

A short earthquake record seen by one or two sensors gives input-output SSI little to tell physical
poles from the ones that fit noise or the response to an input nobody measured (the other ground
component): the stabilization diagram keeps many of them, and across a handful of events they recur
often enough to pass for modes. A physical mode excited by the measured ground motion is seen in
the response as that motion filtered by the mode: for a pole ``mu`` (discrete time) the modal
signal ``q_k[n] = mu q_k[n-1] + u[n]``. Regressing each output channel on the input and on these
signals (real and imaginary parts) measures how much of the recorded response each mode carries
from the input. The modes are taken greedily, the largest gain in explained variance first, so that
two near-copies of one pole do not share (and each lose) its contribution; a mode's share is the
fraction of an output channel's variance it added when it was taken, the largest over channels.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.signal as sig

from shm_ros.core.types import ModalEstimate, Window

#: a mode that adds less than this share of every output channel's variance is not input-driven
MIN_SHARE = 0.02
#: a record whose modes carry less than this share of every channel's variance from the input is
#: not driven by it (ambient vibration beside a ground sensor): its modes are not judged by it
MIN_DRIVEN = 0.5


def modal_signals(u: np.ndarray, fs: float, frequency_hz: np.ndarray, damping: np.ndarray) -> np.ndarray:
    """(n_samples, 2 K): the real and imaginary parts of the input filtered by each mode's pole."""
    wn = 2 * np.pi * np.asarray(frequency_hz, float)
    z = np.clip(np.asarray(damping, float), 0.0, 0.99)
    mu = np.exp((-z * wn + 1j * wn * np.sqrt(1 - z * z)) / fs)
    cols = []
    for m in mu:
        q = sig.lfilter([1.0], [1.0, -m], u.astype(complex))
        cols += [q.real, q.imag]
    return np.column_stack(cols) if cols else np.zeros((u.size, 0))


def input_shares(u: np.ndarray, y: np.ndarray, fs: float, frequency_hz: np.ndarray, damping: np.ndarray
                 ) -> tuple[np.ndarray, float]:
    """Share of the output variance each mode carries from the input ``u`` (n,) to ``y`` (n, p)
    (see the module's text; 0 for a mode that adds nothing), and the largest share of a channel's
    variance that the input and the modes taken explain together."""
    k = len(frequency_hz)
    shares = np.zeros(k)
    u = u - u.mean()
    y = y - y.mean(axis=0)
    var = np.sum(y ** 2, axis=0)
    if k == 0 or not np.all(var > 0) or not np.any(u):
        return shares, 0.0
    x = modal_signals(u, fs, frequency_hz, damping)
    x /= np.maximum(np.linalg.norm(x, axis=0), 1e-300)
    q = (u / np.linalg.norm(u))[:, None]  # the direct (feed-through) term is always in
    explained = np.sum((q.T @ y) ** 2, axis=0) / var
    left = list(range(k))
    while left:
        bases, gains = [], []
        for j in left:
            cand = x[:, 2 * j:2 * j + 2]
            qc, r = np.linalg.qr(cand - q @ (q.T @ cand))  # the part no taken signal explains
            qc = qc[:, np.abs(np.diag(r)) > 1e-9]
            bases.append(qc)
            gains.append(np.sum((qc.T @ y) ** 2, axis=0) / var)
        best = int(np.argmax([g.sum() for g in gains]))
        j = left.pop(best)
        shares[j] = float(np.max(gains[best]))
        if shares[j] < MIN_SHARE:
            break
        q = np.column_stack([q, bases[best]])
        explained = explained + gains[best]
    return shares, float(np.max(explained))


def input_driven_modes(window: Window, est: ModalEstimate) -> tuple[ModalEstimate, int]:
    """``est`` with only the modes that carry the window's measured input to its sensors, and the
    number left out. Output-only estimates, and records the input does not drive (ambient vibration
    beside a ground sensor, :data:`MIN_DRIVEN`), are kept whole."""
    names = list(window.channel_names)
    if est.method != "ssi-io" or window.input_channel not in names or not est.modes:
        return est, 0
    outs = [names.index(s) for s in est.sensor_ids if s in names and s != window.input_channel]
    if not outs:
        return est, 0
    shares, driven = input_shares(window.samples[:, names.index(window.input_channel)],
                                  window.samples[:, outs], window.sample_rate_hz,
                                  np.array([m.frequency_hz for m in est.modes]),
                                  np.array([m.damping_ratio for m in est.modes]))
    if driven < MIN_DRIVEN:
        return est, 0
    kept = [m for m, s in zip(est.modes, shares, strict=True) if s >= MIN_SHARE]
    return replace(est, modes=kept), len(est.modes) - len(kept)
