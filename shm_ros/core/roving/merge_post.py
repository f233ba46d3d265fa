"""Setups merged after identification: each setup's modes rescaled through the references.

Every setup is identified on its own (its channels: the fixed references and what the roving
sensors saw there). A mode of one setup is paired with the modes of the others by the references'
shapes (MAC of the reference components) and frequency, never by its position in the list (one
optimal assignment per setup, :func:`scipy.optimize.linear_sum_assignment`). For a paired mode the
references' components of setup ``j``, ``a_j``, are scaled onto the common reference shape ``g`` by
the least-squares factor ``alpha_j = a_j . g / a_j . a_j`` (so references 10 x larger give roving
components divided by 10), and the roving components of the setup are multiplied by the same
factor; ``g`` is the median of the scaled reference shapes (a setup whose pick blends the mode
with a neighbour can be far off), found by a few fixed-point steps. The
factor's standard error from the least-squares residual,
``s_alpha^2 = |alpha_j a_j - g|^2 / (r - 1) / a_j . a_j`` with ``r`` references, goes into the roving
components' ``shape_std`` (one reference leaves it unknown: NaN). A component measured in several
setups is their mean, its std their spread over the square root of their number, combined with the
factor's.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from shm_ros.core.modal import mac
from shm_ros.core.types import ModalEstimate
from shm_ros.errors import InputError

__all__ = ["GlobalMode", "pair_modes", "merge_post", "drop_unconfirmed"]

FREQ_TOL = 0.05  # a pair's frequencies differ by at most this fraction
MAC_MIN = 0.5  # ... and its reference shapes have at least this MAC
MIN_SETUPS_TO_CONFIRM = 4  # drop_unconfirmed acts from this many setups on
GHOST_SHARE = 0.25  # a mode in at most this share of the setups ...
GHOST_TOL = 0.02  # ... within this of one found in more ...
GHOST_MAC = 0.9  # ... with this reference MAC is a second estimate of it (module doc)


@dataclass
class GlobalMode:
    """One mode over every point and fixed sensor (docs/interfaces.md section 8, ``global_modes``)."""

    frequency_hz: float
    damping_ratio: float
    frequency_std_hz: float
    shape: dict[str, float]
    shape_std: dict[str, float]
    setups_found: int
    missing_setups: list[int] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    members: dict[int, int] = field(default_factory=dict)  # setup index -> its mode's index (post merge)

    def vector(self, keys: Sequence[str]) -> np.ndarray:
        """The shape over ``keys`` (NaN where this mode has no component)."""
        return np.array([self.shape.get(k, np.nan) for k in keys])

    def to_dict(self) -> dict:
        def clean(d: dict[str, float]) -> dict[str, float | None]:
            return {k: (None if not np.isfinite(v) else float(v)) for k, v in d.items()}
        return {"frequency_hz": float(self.frequency_hz), "damping_ratio": float(self.damping_ratio),
                "frequency_std_hz": None if not np.isfinite(self.frequency_std_hz) else float(self.frequency_std_hz),
                "shape": clean(self.shape), "shape_std": clean(self.shape_std),
                "setups_found": int(self.setups_found), "missing_setups": list(self.missing_setups),
                "notes": list(self.notes)}


def _reference_vectors(est: ModalEstimate, references: Sequence[str], where: str) -> np.ndarray:
    missing = [r for r in references if r not in est.sensor_ids]
    if missing:
        raise InputError(f"{where}: reference sensor(s) {missing} not among its channels {est.sensor_ids}")
    idx = [est.sensor_ids.index(r) for r in references]
    return np.array([np.asarray(m.mode_shape, dtype=float)[idx] for m in est.modes]).reshape(len(est.modes),
                                                                                           len(idx))


def pair_modes(setups: Sequence[ModalEstimate], references: Sequence[str], freq_tol: float = FREQ_TOL,
               mac_min: float = MAC_MIN) -> list[dict[int, int]]:
    """Groups of the same mode across setups: each a mapping setup index -> mode index in that setup.

    Groups start from the setup with the most modes; every other setup's modes are assigned to the
    groups by one optimal assignment on ``(1 - MAC of the references) + |df| / f / freq_tol`` among
    the pairs within ``freq_tol`` and ``mac_min``; a mode left over starts a group of its own."""
    refs = [_reference_vectors(e, references, f"setup {k + 1}") for k, e in enumerate(setups)]
    order = sorted(range(len(setups)), key=lambda k: -len(setups[k].modes))
    groups: list[dict[int, int]] = []
    rep_f: list[list[float]] = []
    rep_a: list[np.ndarray] = []
    for k in order:
        f = np.array([m.frequency_hz for m in setups[k].modes])
        if groups and f.size:
            gf = np.array([np.mean(v) for v in rep_f])
            df = np.abs(f[:, None] - gf[None, :]) / gf[None, :]
            m = mac(refs[k][:, None, :], np.array(rep_a)[None, :, :]) if len(references) > 1 \
                else np.ones(df.shape)
            ok = (df <= freq_tol) & (m >= mac_min)
            cost = np.where(ok, (1.0 - m) + df / freq_tol, 1e6)
            rows, cols = linear_sum_assignment(cost)
            taken = {int(r): int(c) for r, c in zip(rows, cols, strict=True) if ok[r, c]}
        else:
            taken = {}
        for i in range(f.size):
            if i in taken:
                g = taken[i]
                groups[g][k] = i
                rep_f[g].append(float(f[i]))
            else:
                groups.append({k: i})
                rep_f.append([float(f[i])])
                rep_a.append(refs[k][i])
    return sorted(groups, key=lambda g: np.mean([setups[k].modes[i].frequency_hz for k, i in g.items()]))


def _scales(a: np.ndarray, iterations: int = 20) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares factors ``alpha_j`` of reference vectors ``a`` (members, r) onto their common
    shape ``g`` (unit norm), and each factor's standard error (NaN with one reference)."""
    norms = np.sum(a * a, axis=1)
    if np.any(norms <= 0):
        raise InputError("a setup's mode has all reference components zero: it cannot be scaled")
    g = a[0] / np.sqrt(norms[0])
    for _ in range(iterations):
        alpha = a @ g / norms
        new = np.median(alpha[:, None] * a, axis=0)
        new /= np.linalg.norm(new)
        if np.allclose(new, g, rtol=0, atol=1e-15):
            break
        g = new
    alpha = a @ g / norms
    r = a.shape[1]
    res = alpha[:, None] * a - g
    std = np.sqrt(np.sum(res * res, axis=1) / (r - 1) / norms) if r > 1 else np.full(alpha.size, np.nan)
    return alpha, g, std


def merge_post(setups: Sequence[ModalEstimate], references: Sequence[str], freq_tol: float = FREQ_TOL,
               mac_min: float = MAC_MIN) -> list[GlobalMode]:
    """Global modes from separately identified setups (see module doc). Each estimate's
    ``sensor_ids`` name the references (the same ids in every setup) and the roving channels (ids
    of the measurement points, unique to where they were measured)."""
    if not setups:
        raise InputError("no setup to merge")
    if not references:
        raise InputError("merging setups needs at least one reference sensor")
    out: list[GlobalMode] = []
    for group in pair_modes(setups, references, freq_tol, mac_min):
        members = sorted(group)
        a = np.array([_reference_vectors(setups[k], references, f"setup {k + 1}")[group[k]] for k in members])
        alpha, g, s_alpha = _scales(a)
        comps: dict[str, list[tuple[float, float]]] = {}
        for j, k in enumerate(members):
            est, mode = setups[k], setups[k].modes[group[k]]
            for name, v in zip(est.sensor_ids, np.asarray(mode.mode_shape, dtype=float), strict=True):
                if name in references:
                    continue
                comps.setdefault(name, []).append((alpha[j] * v, abs(v) * s_alpha[j]))
        shape = {r: float(v) for r, v in zip(references, g, strict=True)}
        std = {r: float(v) for r, v in zip(references, np.std(alpha[:, None] * a, axis=0, ddof=1)
                                             / np.sqrt(len(members)) if len(members) > 1
                                             else np.full(len(references), np.nan), strict=True)}
        for name, vals in comps.items():
            v = np.array(vals)
            spread = np.std(v[:, 0], ddof=1) / np.sqrt(len(v)) if len(v) > 1 else 0.0
            shape[name] = float(np.mean(v[:, 0]))
            std[name] = float(np.sqrt(spread ** 2 + np.mean(v[:, 1] ** 2) / len(v)))
        top = max(shape.values(), key=abs)
        shape = {k: v / top for k, v in shape.items()}
        std = {k: v / abs(top) for k, v in std.items()}
        modes = [setups[k].modes[group[k]] for k in members]
        f = np.array([m.frequency_hz for m in modes])
        fs = np.array([m.frequency_std_hz for m in modes])
        if np.all(np.isfinite(fs) & (fs > 0)):
            w = 1.0 / fs ** 2
            freq, fstd = float(np.sum(w * f) / np.sum(w)), float(1.0 / np.sqrt(np.sum(w)))
        else:
            freq = float(np.mean(f))
            fstd = float(np.std(f, ddof=1) / np.sqrt(f.size)) if f.size > 1 else float("nan")
        missing = [k + 1 for k in range(len(setups)) if k not in group]
        notes = [f"not found in setup(s) {missing}: merged from the other {len(members)}; no shape at "
                 "the points only those setups measured"] if missing else []
        out.append(GlobalMode(freq, float(np.mean([m.damping_ratio for m in modes])), fstd, shape, std,
                              len(members), missing, notes, dict(group)))
    return out


def drop_unconfirmed(modes: list[GlobalMode], n_setups: int, references: Sequence[str]
                     ) -> tuple[list[GlobalMode], list[str]]:
    """The modes the setups confirm, and a note for each one left out (module doc)."""
    if n_setups < MIN_SETUPS_TO_CONFIRM:
        return list(modes), []
    keep, notes = [], []
    for g in modes:
        ref = g.vector(references)
        twins = [h for h in modes if h.setups_found > g.setups_found
                 and abs(h.frequency_hz / g.frequency_hz - 1) <= GHOST_TOL
                 and float(mac(ref, h.vector(references))) >= GHOST_MAC]
        if twins and g.setups_found <= GHOST_SHARE * n_setups:
            main = max(twins, key=lambda h: h.setups_found)
            main.notes.append(f"a second estimate at {g.frequency_hz:.4g} Hz from {g.setups_found} setup(s), "
                              "with the same reference shape, left out")
        elif g.setups_found == 1:
            notes.append(f"a mode at {g.frequency_hz:.4g} Hz found in one setup of {n_setups} only: left out")
        else:
            keep.append(g)
    return keep, notes
