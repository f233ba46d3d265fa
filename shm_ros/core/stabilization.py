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

Relative tolerances alone fail at both ends: 5 % of a 0.5 % damping ratio is 0.025 points, far
below the scatter of any estimate of it, and a heavily damped mode's frequency scatters with its
bandwidth. Both scale with the standard error of a mode's estimates from a record of ``T``
seconds, ``sigma = sqrt(zeta / (2 pi f T))`` (relative frequency and absolute damping alike,
to first order for a mode under broadband excitation). So the checks also accept differences up
to ``damping_sigmas`` (between orders) and ``two_a_sigmas`` (two-A) times ``sigma``. On the
simulated frame (test/test_identify_band.py) the median two-A damping difference of real modes
was at most 0.55 sigma, that of spurious stable columns at least 1.7 sigma.

Picking clusters the stable, physical poles (hierarchical average-linkage clustering on
``|f_i - f_j| / max(f_i, f_j) + (1 - MAC_ij)``) and keeps the clusters found at enough model
orders: no hand-picking. The two-A and MPC filters judge a cluster (a stable column) by its
poles together: it is removed only when it passes at fewer than ``column_pass_fraction`` of its
orders or at fewer orders than a mode needs, so a clean column is not lost to the orders where
one check scatters (its statistics use all its orders), and a spurious one goes whole.
What each check removed is counted in a :class:`FilterReport`.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.cluster.hierarchy import fcluster, linkage

from shm_ros.core.config import option
from shm_ros.core.modal import mac_matrix
from shm_ros.core.modal import real_shape as real_mode_shape
from shm_ros.core.ssi import PoleSet

__all__ = ["TwoAScope", "StabilityConfig", "two_a_flags", "PickingConfig", "PoleFlags", "PickedMode",
           "FilterReport", "mpc", "Clusters", "cluster_candidates", "stable_columns", "passes_needed",
           "two_a_by_column",
           "classify", "standard_error", "pick_modes", "pick_modes_reported", "real_mode_shape"]


class TwoAScope(enum.StrEnum):
    """Which poles the two-A check validates (docs/identify.md)."""

    # The building paper's use: the second estimate of A validates the poles that passed the
    # stabilization criteria. Picking judges a stable column by the share of its orders that pass,
    # so each column is checked at as few of its orders as settle that verdict (reached, or out of
    # reach); the backward A is solved only at those orders.
    COLUMNS = "columns"
    STABLE = "stable"  # stable, physical candidate poles, at the orders where they occur
    ALL = "all"  # every pole of every order (the whole diagram shows its verdict)


@dataclass
class StabilityConfig:
    freq_tol: float = option(0.01, "stable pole: relative frequency change between consecutive orders")
    damping_tol: float = option(0.05, "stable pole: relative damping change between consecutive orders")
    damping_sigmas: float = option(0.5, "stable pole: a damping change between consecutive orders up to "
                                   "this many standard errors sqrt(zeta / (2 pi f T)) is accepted too")
    mac_min: float = option(0.98, "stable pole: MAC between consecutive orders")
    two_a: bool = option(True, "require agreement of the forward and backward estimates of A")
    two_a_freq_tol: float = option(0.01, "two-A agreement: relative frequency difference")
    two_a_damping_tol: float = option(0.05, "two-A agreement: relative damping difference")
    two_a_sigmas: float = option(1.0, "two-A agreement: relative frequency and damping differences up to "
                                 "this many standard errors sqrt(zeta / (2 pi f T)) are accepted too")
    two_a_mac_min: float = option(0.9, "two-A agreement: MAC")
    two_a_scope: str = option(TwoAScope.COLUMNS.value, "poles the two-A check validates: columns (each "
                              "stable column at as few of its orders as settle its verdict), stable "
                              "(the stable, physical candidates at every order where they occur) or "
                              "all (every pole of every order); the picks are the same",
                              choices=TwoAScope)
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
    column_pass_fraction: float = option(0.2, "the two-A and MPC filters remove a cluster of stable "
                                         "poles when it passes them at fewer than this fraction of its "
                                         "orders (or at fewer orders than a mode needs)")


@dataclass
class PoleFlags:
    mpc: np.ndarray
    stable_freq: np.ndarray  # frequency stable only (the "f" symbol of a diagram)
    stable: np.ndarray  # frequency, damping and MAC stable
    two_a_ok: np.ndarray
    mpc_ok: np.ndarray
    physical_ok: np.ndarray
    # poles whose two-A verdict was computed (None: every pole's); two_a_ok is False elsewhere
    two_a_checked: np.ndarray | None = None

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


def standard_error(frequency_hz: np.ndarray, damping: np.ndarray, duration_s: float | None) -> np.ndarray:
    """``sqrt(zeta / (2 pi f T))``: first-order standard error of a mode's damping ratio and
    relative frequency from a record of ``T`` s (0 where ``T`` is unknown)."""
    if not duration_s:
        return np.zeros(np.shape(frequency_hz))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.nan_to_num(np.sqrt(np.abs(damping) / (2 * np.pi * np.abs(frequency_hz) * duration_s)))


def _damping_close(z1: np.ndarray, z2: np.ndarray, rel: float, absolute: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        return np.abs(z1 - z2) < np.maximum(rel * np.abs(z1), absolute)


def classify(poles: PoleSet, cfg: StabilityConfig, sample_rate_hz: float,
             duration_s: float | None = None) -> PoleFlags:
    """Evaluate every criterion for every pole (``duration_s``: the record's length, for the
    standard-error tolerances; None: relative tolerances only)."""
    sigma = standard_error(poles.frequency_hz, poles.damping_ratio, duration_s)
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
        dz = _damping_close(poles.damping_ratio[i][:, None], poles.damping_ratio[j][None, :],
                            cfg.damping_tol, cfg.damping_sigmas * sigma[i][:, None])
        mac = mac_matrix(poles.shape[i], poles.shape[j]) >= cfg.mac_min
        stable_f[i] = df.any(axis=1)
        stable[i] = (df & dz & mac).any(axis=1)
    two_a = two_a_flags(poles, cfg, sigma)
    fmax = cfg.freq_max_hz if cfg.freq_max_hz is not None else 0.45 * sample_rate_hz
    physical = ((poles.damping_ratio > cfg.damping_min) & (poles.damping_ratio <= cfg.damping_max)
                & (poles.frequency_hz > cfg.freq_min_hz) & (poles.frequency_hz <= fmax))
    return PoleFlags(m, stable_f, stable, two_a, m >= cfg.mpc_min, physical)


def two_a_flags(poles: PoleSet, cfg: StabilityConfig, sigma: np.ndarray) -> np.ndarray:
    """Per pole: its backward partner agrees in frequency, damping and MAC (all True when the
    check is off; False for a pole without a partner, e.g. one the check did not validate).
    ``sigma``: the poles' standard errors (:func:`standard_error`)."""
    if not cfg.two_a:
        return np.ones(len(poles), bool)
    wide = cfg.two_a_sigmas * sigma
    with np.errstate(invalid="ignore"):
        return ((_rel(poles.frequency_hz, poles.frequency_b_hz) < np.maximum(cfg.two_a_freq_tol, wide))
                & _damping_close(poles.damping_ratio, poles.damping_b, cfg.two_a_damping_tol, wide)
                & (poles.mac_b >= cfg.two_a_mac_min))


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
    """Automatic picking: clusters of stable poles found at enough model orders (see
    :func:`pick_modes_reported` for what the filters removed)."""
    return pick_modes_reported(poles, flags, cfg, use_filters)[0]


def pick_modes_reported(poles: PoleSet, flags: PoleFlags, cfg: PickingConfig, use_filters: bool = True,
                        clusters: Clusters | None = None) -> tuple[list[PickedMode], FilterReport]:
    """Picked modes and the :class:`FilterReport`: stable, physical poles are clustered; a cluster
    with poles at enough orders is removed by the two-A (then the MPC) filter when it passes that
    check at fewer than ``column_pass_fraction`` of its orders or at fewer orders than a mode
    needs (so a column the pole-by-pole filter kept is kept, with all its orders). ``clusters``:
    :func:`cluster_candidates` of the same poles and flags, when already made."""
    report = FilterReport.empty(len(poles), use_filters)
    stable = np.flatnonzero(flags.stable)
    report.stable = int(stable.size)
    unphysical = stable[~flags.physical_ok[stable]]
    report.removed_by[unphysical] = "physical"
    report.removed["physical"] = int(unphysical.size)
    cand, labels, need = clusters or cluster_candidates(poles, flags, cfg)
    if labels is None:
        report.removed_by[cand] = "too few orders"
        report.removed["too few orders"] += int(cand.size)
        return [], report
    checked = flags.two_a_checked
    picked: list[PickedMode] = []
    for lab in np.unique(labels):
        members = cand[labels == lab]
        if np.unique(poles.order[members]).size < need:
            report.removed_by[members] = "too few orders"
            report.removed["too few orders"] += int(members.size)
            continue
        fmed = np.median(poles.frequency_hz[members])
        # the column's orders, and for each member the index of its order among them
        col_orders, at_order = np.unique(poles.order[members], return_inverse=True)
        if use_filters:
            verdict = None
            for check, ok in (("two-A", flags.two_a_ok), ("MPC", flags.mpc_ok)):
                # share of the column's orders with a pole that passes (a second pole at one
                # order, e.g. a split pair, must not outvote the column)
                passed = np.bincount(at_order, weights=ok[members], minlength=col_orders.size) > 0
                share = float(np.mean(passed))
                # the verdict counts an order that was not checked as failing (a column is checked
                # until its verdict is settled, so this is the verdict of all its orders); the
                # report gives the pass fraction of the orders checked
                seen = np.ones(col_orders.size, bool) if check != "two-A" or checked is None else \
                    np.bincount(at_order, weights=checked[members], minlength=col_orders.size) > 0
                report.columns.append({"frequency_hz": float(fmed), "poles": int(members.size),
                                       "check": check, "orders": int(col_orders.size),
                                       "orders_checked": int(seen.sum()),
                                       "pass_fraction": round(float(np.sum(passed) / max(1, seen.sum())),
                                                              3)})
                if share < cfg.column_pass_fraction or int(np.sum(passed)) < need:
                    verdict = check
                    break
            if verdict is not None:
                report.removed_by[members] = verdict
                report.removed[verdict] += int(members.size)
                report.columns_removed[verdict] = report.columns_removed.get(verdict, 0) + 1
                continue
            for check, ok in (("two-A", flags.two_a_ok), ("MPC", flags.mpc_ok)):
                failed = ~ok[members] if check != "two-A" or checked is None else \
                    ~ok[members] & checked[members]
                report.kept_failing[check] += int(np.count_nonzero(failed))
        # one pole per order: the one nearest the cluster's median frequency (the first of equals)
        by = np.lexsort((members, np.abs(poles.frequency_hz[members] - fmed), at_order))
        first = np.r_[True, np.diff(at_order[by]) != 0]
        keep = members[by[first]]
        report.removed_by[np.setdiff1d(members, keep)] = "same order"
        report.removed["same order"] += int(members.size - keep.size)
        f = poles.frequency_hz[keep]
        z = poles.damping_ratio[keep]
        rep = keep[np.argmin(np.abs(f - np.median(f)))]
        # damping: the median over the orders, robust to the orders where it scatters
        picked.append(PickedMode(
            frequency_hz=float(f.mean()), damping_ratio=float(np.median(z)),
            frequency_spread_hz=float(f.std(ddof=1)) if f.size > 1 else 0.0,
            damping_spread=float(z.std(ddof=1)) if z.size > 1 else 0.0,
            mode_shape_complex=poles.shape[rep], mpc=float(flags.mpc[keep].mean()),
            n_poles=int(keep.size), pole_index=keep, representative_order=int(poles.order[rep])))
    picked.sort(key=lambda p: p.frequency_hz)
    merged = _merge_duplicates(picked, cfg.distance_cutoff)
    for p in picked:
        if not any(p is q for q in merged):
            report.removed_by[p.pole_index] = "duplicate"
            report.removed["duplicate"] += int(p.pole_index.size)
    report.removed_by[np.concatenate([p.pole_index for p in merged]) if merged else []] = "picked"
    return merged, report


Clusters = tuple[np.ndarray, "np.ndarray | None", int]


def cluster_candidates(poles: PoleSet, flags: PoleFlags, cfg: PickingConfig) -> Clusters:
    """The stable, physical poles, their cluster labels (None: too few poles to make a mode) and
    the number of orders a mode needs (what picking clusters; the two-A check does not change it)."""
    stable = np.flatnonzero(flags.stable)
    cand = stable[flags.physical_ok[stable]]
    n_orders = int(np.unique(poles.order).size) if len(poles) else 0
    need = max(cfg.min_poles, int(np.ceil(cfg.min_fraction * n_orders)))
    if cand.size < need:
        return cand, None, need
    return cand, _cluster(poles.frequency_hz[cand], poles.shape[cand], cfg.distance_cutoff), need


def stable_columns(poles: PoleSet, flags: PoleFlags, cfg: PickingConfig, clusters: Clusters | None = None
                   ) -> tuple[list[np.ndarray], int]:
    """The stable columns picking judges with the two-A and MPC filters (the clusters of stable,
    physical poles at enough orders: member indices) and the number of orders a mode needs."""
    cand, labels, need = clusters or cluster_candidates(poles, flags, cfg)
    if labels is None:
        return [], need
    columns = [cand[labels == lab] for lab in np.unique(labels)]
    return [m for m in columns if np.unique(poles.order[m]).size >= need], need


def passes_needed(n_orders: int, need: int, fraction: float) -> int:
    """Fewest passing orders of a column of ``n_orders`` orders that keep it: at least ``need``
    and a share of at least ``fraction`` (the same comparison as the picking's)."""
    k = max(need, int(np.ceil(fraction * n_orders)))
    while k > need and (k - 1) / n_orders >= fraction:
        k -= 1
    while k <= n_orders and k / n_orders < fraction:
        k += 1
    return k


def two_a_by_column(poles: PoleSet, flags: PoleFlags, cfg: PickingConfig,
                    validate: Callable[[np.ndarray], np.ndarray], clusters: Clusters | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Two-A verdicts of each stable column at as few of its orders as settle its verdict.

    ``validate(idx)`` returns the two-A verdict of the poles ``idx`` (all of one model order).
    A column is kept by picking when the orders with a passing pole reach
    :func:`passes_needed`, removed when they can no longer reach it; checking stops for a
    column at either point, so the verdict is that of all its orders. The next order checked is
    the one with the most unsettled columns (each order costs one backward eigenvalue problem,
    shared by the columns there). Returns the two-A flag of every pole (False where not checked)
    and the mask of the poles checked."""
    ok = np.zeros(len(poles), bool)
    checked = np.zeros(len(poles), bool)
    columns, need = stable_columns(poles, flags, cfg, clusters)
    if not columns:
        return ok, checked
    top = int(poles.order.max()) + 1
    by_order = [{int(o): m[poles.order[m] == o] for o in np.unique(poles.order[m])} for m in columns]
    remaining = [set(d) for d in by_order]
    required = [passes_needed(len(d), need, cfg.column_pass_fraction) for d in by_order]
    passed = [0] * len(columns)
    open_ = set(range(len(columns)))
    while open_:
        counts = np.bincount([o for c in open_ for o in remaining[c]], minlength=top)
        n = int(np.argmax(counts))
        here = [c for c in open_ if n in remaining[c]]
        idx = np.concatenate([by_order[c][n] for c in here])
        ok[idx] = validate(idx)
        checked[idx] = True
        for c in here:
            remaining[c].discard(n)
            passed[c] += bool(ok[by_order[c][n]].any())
            if passed[c] >= required[c] or passed[c] + len(remaining[c]) < required[c]:
                open_.discard(c)
    return ok, checked


@dataclass
class FilterReport:
    """What happened to the stable poles: how many each check removed (docs/identify.md).

    ``removed``: poles per reason - ``physical`` (damping or frequency out of range), ``two-A``
    and ``MPC`` (their stable column failed that check), ``too few orders`` (a column at fewer
    than the required orders), ``same order`` (a second pole of a column at one order),
    ``duplicate`` (a column merged into a larger one of the same mode). ``kept_failing``: poles of
    kept columns that fail a check on their own. ``columns``: each column's pass fraction per check.
    ``removed_by``: per pole of the diagram, the reason ("" = not stable, "picked" = in a mode).
    """

    stable: int
    removed: dict[str, int]
    kept_failing: dict[str, int]
    columns: list[dict]
    removed_by: np.ndarray
    filters: bool = True
    columns_removed: dict[str, int] = field(default_factory=dict)

    REASONS = ("physical", "two-A", "MPC", "too few orders", "same order", "duplicate")

    @classmethod
    def empty(cls, n_poles: int, filters: bool = True) -> FilterReport:
        return cls(0, dict.fromkeys(cls.REASONS, 0), {"two-A": 0, "MPC": 0}, [],
                   np.full(n_poles, "", dtype=object), filters)

    def to_dict(self) -> dict:
        """The JSON form (no per-pole array)."""
        return {"filters": self.filters, "stable_poles": self.stable, "removed": dict(self.removed),
                "columns_removed": dict(self.columns_removed),
                "kept_failing": dict(self.kept_failing), "columns": list(self.columns)}

    def legend(self, reason: str) -> str:
        """A legend entry, e.g. ``removed by two-A: 41 poles (1 column)``."""
        n, cols = self.removed.get(reason, 0), self.columns_removed.get(reason, 0)
        return f"removed by {reason}: {n} poles" + (f" ({cols} column{'s' * (cols != 1)})" if cols else "")


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
    report: FilterReport | None = None  # what the filters removed
