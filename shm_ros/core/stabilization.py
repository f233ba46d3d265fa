"""Stabilization diagram, spurious-pole filters and automatic mode picking.

A pole (one model order, one eigenvalue of ``A``) is

* *stable* when the previous evaluated order has a pole within the frequency, damping and MAC
  tolerances (the usual stabilization-diagram criteria);
* *two-A consistent* when the second (backward) estimate of ``A`` at the same order has a pole
  that agrees with it (building paper: 1 % frequency, 5 % damping, MAC >= 0.9 by default);
* *collinear* when its modal phase collinearity (MPC) is at least ``mpc_min`` (real normal modes
  have MPC = 1, noise poles have scattered phases);
* *physical* when its damping ratio lies in ``(damping_min, damping_max]`` and its frequency in the
  configured band.

Picking clusters the poles that pass (hierarchical average-linkage clustering on
``|f_i - f_j| / max(f_i, f_j) + (1 - MAC_ij)``) and keeps the clusters found at enough model
orders: no hand-picking.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.cluster.hierarchy import fcluster, linkage

from shm_ros.core.config import option
from shm_ros.core.modal import mac_matrix
from shm_ros.core.modal import real_shape as real_mode_shape
from shm_ros.core.ssi import PoleSet

__all__ = ["StabilityConfig", "PickingConfig", "PoleFlags", "PickedMode", "mpc", "classify",
           "pick_modes", "real_mode_shape"]


@dataclass
class StabilityConfig:
    freq_tol: float = option(0.01, "stable pole: relative frequency change between consecutive orders")
    damping_tol: float = option(0.05, "stable pole: relative damping change between consecutive orders")
    mac_min: float = option(0.98, "stable pole: MAC between consecutive orders")
    two_a: bool = option(True, "require agreement of the forward and backward estimates of A")
    two_a_freq_tol: float = option(0.01, "two-A agreement: relative frequency difference")
    two_a_damping_tol: float = option(0.05, "two-A agreement: relative damping difference")
    two_a_mac_min: float = option(0.9, "two-A agreement: MAC")
    mpc_min: float = option(0.5, "smallest modal phase collinearity (0 disables the MPC filter)")
    damping_min: float = option(0.0, "physical pole: damping ratio above this")
    damping_max: float = option(0.20, "physical pole: damping ratio at most this")
    freq_min_hz: float = option(0.0, "physical pole: frequency at least this, Hz")
    freq_max_hz: float | None = option(None, "physical pole: frequency at most this, Hz (unset: "
                                       "0.45 x sample rate, below the anti-alias roll-off)")


@dataclass
class PickingConfig:
    distance_cutoff: float = option(0.03, "cut-off of |df|/f + (1 - MAC) in the average-linkage "
                                    "clustering of poles")
    min_fraction: float = option(0.10, "a mode is found at least at this fraction of the evaluated orders")
    min_poles: int = option(5, "a mode is found at least at this many orders")


@dataclass
class PoleFlags:
    mpc: np.ndarray
    stable_freq: np.ndarray  # frequency stable only (the "f" symbol of a diagram)
    stable: np.ndarray  # frequency, damping and MAC stable
    two_a_ok: np.ndarray
    mpc_ok: np.ndarray
    physical_ok: np.ndarray

    def candidates(self, use_filters: bool = True) -> np.ndarray:
        """Poles that enter picking: stable and physical, plus two-A and MPC when filtering."""
        base = self.stable & self.physical_ok
        return base & self.two_a_ok & self.mpc_ok if use_filters else base


@dataclass
class PickedMode:
    frequency_hz: float
    damping_ratio: float
    frequency_spread_hz: float  # standard deviation across model orders
    damping_spread: float
    mode_shape_complex: np.ndarray  # representative complex shape (unit norm)
    mpc: float
    n_poles: int
    pole_index: np.ndarray  # indices into the PoleSet
    representative_order: int


def mpc(shapes: np.ndarray) -> np.ndarray:
    """Modal phase collinearity of complex shapes (rows): 1 for a real (monophase) shape."""
    re, im = shapes.real, shapes.imag
    sxx = np.sum(re * re, axis=-1)
    syy = np.sum(im * im, axis=-1)
    sxy = np.sum(re * im, axis=-1)
    tot = sxx + syy
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(tot > 0, ((sxx - syy) ** 2 + 4 * sxy ** 2) / tot ** 2, 0.0)


def _rel(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.abs(a - b) / np.abs(a)


def classify(poles: PoleSet, cfg: StabilityConfig, sample_rate_hz: float) -> PoleFlags:
    """Evaluate every criterion for every pole."""
    n = len(poles)
    m = mpc(poles.shape)
    stable_f = np.zeros(n, bool)
    stable = np.zeros(n, bool)
    orders = np.asarray(poles.orders)
    present = [o for o in orders if np.any(poles.order == o)]
    starts = {o: np.flatnonzero(poles.order == o) for o in present}
    for prev, cur in zip(present[:-1], present[1:], strict=True):
        i, j = starts[cur], starts[prev]
        df = _rel(poles.frequency_hz[i][:, None], poles.frequency_hz[j][None, :]) < cfg.freq_tol
        dz = _rel(poles.damping_ratio[i][:, None], poles.damping_ratio[j][None, :]) < cfg.damping_tol
        mac = mac_matrix(poles.shape[i], poles.shape[j]) >= cfg.mac_min
        stable_f[i] = df.any(axis=1)
        stable[i] = (df & dz & mac).any(axis=1)
    if cfg.two_a:
        with np.errstate(invalid="ignore"):
            two_a = ((_rel(poles.frequency_hz, poles.frequency_b_hz) < cfg.two_a_freq_tol)
                     & (_rel(poles.damping_ratio, poles.damping_b) < cfg.two_a_damping_tol)
                     & (poles.mac_b >= cfg.two_a_mac_min))
    else:
        two_a = np.ones(n, bool)
    fmax = cfg.freq_max_hz if cfg.freq_max_hz is not None else 0.45 * sample_rate_hz
    physical = ((poles.damping_ratio > cfg.damping_min) & (poles.damping_ratio <= cfg.damping_max)
                & (poles.frequency_hz > cfg.freq_min_hz) & (poles.frequency_hz <= fmax))
    return PoleFlags(m, stable_f, stable, two_a, m >= cfg.mpc_min, physical)


def _cluster(freq: np.ndarray, shapes: np.ndarray, cutoff: float) -> np.ndarray:
    """Cluster labels (0..k-1). Poles further apart in frequency than ``cutoff`` can never share
    an average-linkage cluster, so the sorted frequencies are split at such gaps first and the
    (quadratic) clustering runs per group."""
    order = np.argsort(freq)
    fs = freq[order]
    gaps = np.flatnonzero(np.diff(fs) / fs[1:] > cutoff) + 1
    labels = np.empty(freq.size, int)
    next_label = 0
    for grp in np.split(np.arange(freq.size), gaps):
        idx = order[grp]
        if idx.size == 1:
            labels[idx] = next_label
            next_label += 1
            continue
        f = freq[idx]
        d = np.abs(f[:, None] - f[None, :]) / np.maximum(f[:, None], f[None, :])
        d = d + (1.0 - mac_matrix(shapes[idx], shapes[idx]))
        iu = np.triu_indices(idx.size, 1)
        z = linkage(np.clip(d[iu], 0, None), method="average")
        lab = fcluster(z, t=cutoff, criterion="distance") - 1
        labels[idx] = lab + next_label
        next_label += int(lab.max()) + 1
    return labels


def pick_modes(poles: PoleSet, flags: PoleFlags, cfg: PickingConfig,
               use_filters: bool = True) -> list[PickedMode]:
    """Automatic picking: clusters of candidate poles found at enough model orders."""
    cand = np.flatnonzero(flags.candidates(use_filters))
    n_orders = int(np.unique(poles.order).size) if len(poles) else 0
    need = max(cfg.min_poles, int(np.ceil(cfg.min_fraction * n_orders)))
    if cand.size < need:
        return []
    labels = _cluster(poles.frequency_hz[cand], poles.shape[cand], cfg.distance_cutoff)
    picked: list[PickedMode] = []
    for lab in np.unique(labels):
        members = cand[labels == lab]
        if np.unique(poles.order[members]).size < need:
            continue
        fmed = np.median(poles.frequency_hz[members])
        # one pole per order: the one nearest the cluster's median frequency
        keep_list = []
        for o in np.unique(poles.order[members]):
            at = members[poles.order[members] == o]
            keep_list.append(at[np.argmin(np.abs(poles.frequency_hz[at] - fmed))])
        keep = np.array(keep_list)
        f = poles.frequency_hz[keep]
        z = poles.damping_ratio[keep]
        rep = keep[np.argmin(np.abs(f - np.median(f)))]
        picked.append(PickedMode(
            frequency_hz=float(f.mean()), damping_ratio=float(z.mean()),
            frequency_spread_hz=float(f.std(ddof=1)) if f.size > 1 else 0.0,
            damping_spread=float(z.std(ddof=1)) if z.size > 1 else 0.0,
            mode_shape_complex=poles.shape[rep], mpc=float(flags.mpc[keep].mean()),
            n_poles=int(keep.size), pole_index=keep, representative_order=int(poles.order[rep])))
    picked.sort(key=lambda p: p.frequency_hz)
    return _merge_duplicates(picked, cfg.distance_cutoff)


def _merge_duplicates(picked: list[PickedMode], cutoff: float) -> list[PickedMode]:
    """Two accepted clusters of the same physical mode (split by a shape change): keep the larger."""
    out: list[PickedMode] = []
    for p in picked:
        if out:
            q = out[-1]
            close = abs(p.frequency_hz - q.frequency_hz) / p.frequency_hz < cutoff
            same = mac_matrix(p.mode_shape_complex[None], q.mode_shape_complex[None])[0, 0] > 0.9
            if close and same:
                if p.n_poles > q.n_poles:
                    out[-1] = p
                continue
        out.append(p)
    return out


@dataclass
class Diagram:
    """Everything a stabilization-diagram plot needs."""

    poles: PoleSet
    flags: PoleFlags
    picked: list[PickedMode] = field(default_factory=list)
    singular_values: np.ndarray | None = None
    spectrum_hz: np.ndarray | None = None
    spectrum: np.ndarray | None = None  # e.g. first singular value of the spectral matrix
