"""The tracked mode set: learned from the first windows, taken from the FE model, or both.

From windows: all modes of the first windows are clustered on ``|f_i - f_j| / max(f_i, f_j) +
(1 - MAC_ij)`` (average linkage, as the stabilization-diagram picking); a cluster found in at least
``min_presence`` of those windows is a tracked mode (median frequency and damping, the shape of the
member nearest the median frequency). From the model: the structure file's lowest modes read at the
sensors. Both: the clusters are matched to the FE modes by MAC and frequency (optimal assignment,
gated by ``mac_min`` and ``max_freq_gate``), so the FE model names and completes the set while the
data fix the frequencies; clusters no FE mode matches (modes the model has no DOF for, such as a
planar model's torsion and lateral modes) are tracked modes of their own.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.optimize import linear_sum_assignment

from shm_ros.core.tracking.config import ReferenceSource, TrackingConfig
from shm_ros.core.tracking.shapes import mac_table, shapes_on
from shm_ros.core.types import ModalEstimate

if TYPE_CHECKING:
    from shm_ros.core.structure import StructureSpec


@dataclass
class ReferenceMode:
    number: int
    frequency_hz: float  # median over the reference windows (or the FE frequency)
    shape: np.ndarray  # over the tracker's sensor list (NaN = sensor never seen)
    presence: float  # fraction of the reference windows in which it was found
    damping: float = float("nan")
    source: str = "windows"  # windows, model, both or born (appeared later)
    spread: float = 0.0  # relative frequency spread of its members (widens its gate)
    born_window: str = ""  # window id where a mode born later was first assigned


Cluster = tuple[float, np.ndarray, float, float, np.ndarray, float]


def cluster_modes(estimates: list[ModalEstimate], sensors: list[str], cutoff: float, min_presence: float,
                  n_windows: int | None = None) -> list[tuple]:
    """Recurring modes of ``estimates``: (median frequency, shape, presence, median damping,
    relative spread), ascending frequency. ``n_windows``: the presence denominator (default: len(estimates))."""
    f_list: list[float] = []
    d_list: list[float] = []
    shp_list: list[np.ndarray] = []
    win_list: list[int] = []
    for w, est in enumerate(estimates):
        s = shapes_on(est, sensors)
        for k, m in enumerate(est.modes):
            if np.isfinite(m.frequency_hz) and m.frequency_hz > 0:
                f_list.append(m.frequency_hz)
                d_list.append(m.damping_ratio)
                shp_list.append(s[k])
                win_list.append(w)
    if not f_list:
        return []
    found = cluster_arrays(np.array(f_list), np.array(d_list, float), np.array(shp_list), np.array(win_list),
                           cutoff, min_presence, n_windows or len(estimates))
    return [(*c[:4], c[5]) for c in found]


def cluster_arrays(f: np.ndarray, damp: np.ndarray, shp: np.ndarray, win: np.ndarray, cutoff: float,
                   min_presence: float, n_windows: int) -> list[Cluster]:
    """:func:`cluster_modes` on arrays of modes (``win``: the window of each): (median frequency,
    shape, presence, median damping, member indices, relative spread) per cluster."""
    if f.size == 0:
        return []
    if f.size == 1:
        labels = np.zeros(1, int)
    else:
        d = np.abs(f[:, None] - f[None, :]) / np.maximum(f[:, None], f[None, :]) + (1.0 - mac_table(shp, shp))
        iu = np.triu_indices(f.size, 1)
        labels = fcluster(linkage(np.clip(d[iu], 0, None), method="average"), t=cutoff,
                          criterion="distance") - 1
        labels = _split_shared_windows(labels, d, win)
        labels = _merge_disjoint(labels, d, win, cutoff)
    out = []
    for lab in np.unique(labels):
        members = np.flatnonzero(labels == lab)
        presence = np.unique(win[members]).size / n_windows
        if presence < min_presence:
            continue
        fm = float(np.median(f[members]))
        rep = members[np.argmin(np.abs(f[members] - fm))]
        dm = damp[members]
        dmed = float(np.median(dm[np.isfinite(dm)])) if np.isfinite(dm).any() else float("nan")
        spread = float(np.quantile(np.abs(f[members] / fm - 1), 0.9)) if members.size > 2 else 0.0
        out.append((fm, shp[rep], presence, dmed, members, spread))
    out.sort(key=lambda r: r[0])
    return out


def _split_shared_windows(labels: np.ndarray, d: np.ndarray, win: np.ndarray, depth: int = 4) -> np.ndarray:
    """One physical mode appears once per window: a cluster holding two modes of the same window in
    more than 10 % of its windows is two modes (a close pair whose frequencies vary by more than
    their spacing, as in an event catalogue) and is split in two, recursively."""
    labels = labels.copy()
    for _ in range(depth):
        changed = False
        for lab in np.unique(labels):
            members = np.flatnonzero(labels == lab)
            windows = np.unique(win[members])
            if members.size < 4 or (members.size - windows.size) <= 0.1 * windows.size:
                continue
            sub = d[np.ix_(members, members)]
            iu = np.triu_indices(members.size, 1)
            halves = fcluster(linkage(np.clip(sub[iu], 0, None), method="average"), t=2, criterion="maxclust")
            if np.unique(halves).size < 2:
                continue
            labels[members[halves == 2]] = labels.max() + 1
            changed = True
        if not changed:
            break
    return labels


def _merge_disjoint(labels: np.ndarray, d: np.ndarray, win: np.ndarray, cutoff: float) -> np.ndarray:
    """The converse: two neighbouring clusters that (almost) never share a window and whose mean
    distance is below three cut-offs are one mode whose frequency varied more than the cut-off
    (amplitude softening between earthquakes, damage, a season). "Almost": in 10 % of the smaller
    one's windows; in a record of fewer than ten windows (a handful of events, where 10 % is less than
    one window and a neighbouring mode seen once joins a cluster by chance), in one window while both
    hold three or more. In a window both hold, the member that lies farther from its own cluster
    leaves and stands alone."""
    labels = labels.copy()
    _, window = np.unique(win, return_inverse=True)
    few = int(window.max()) + 1 < 10
    dists: dict[tuple[int, int], float] = {}  # mean distance of two clusters, kept until one changes
    while True:
        labs, which = np.unique(labels, return_inverse=True)
        members = [np.flatnonzero(which == i) for i in range(labs.size)]
        mergeable = _disjoint_pairs(which, window, few)
        best, pair = 3 * cutoff, None
        for i, j in zip(*np.nonzero(mergeable), strict=True):  # pairs in order: ties go to the first
            a, b = int(labs[i]), int(labs[j])
            dist = dists.get((a, b))
            if dist is None:  # two single modes: their distance is the mean
                ma, mb = members[i], members[j]
                dist = dists[(a, b)] = float(d[ma[0], mb[0]]) if ma.size == mb.size == 1 else \
                    float(np.mean(d[np.ix_(ma, mb)]))
            if dist < best:
                best, pair = dist, (a, b)
        if pair is None:
            return labels
        a, b = pair
        dists = {k: v for k, v in dists.items() if a not in k and b not in k}
        ma, mb = np.flatnonzero(labels == a), np.flatnonzero(labels == b)
        for w in np.intersect1d(win[ma], win[mb]):
            # each member's mean distance to the rest of its own cluster: the worse fit leaves
            cands = [(float(np.mean(d[k, own[own != k]])) if own.size > 1 else 0.0, int(k))
                     for own in (ma, mb) for k in own[win[own] == w]]
            for _, k in sorted(cands)[1:]:
                labels[k] = labels.max() + 1
        labels[labels == b] = a


def _disjoint_pairs(which: np.ndarray, window: np.ndarray, few: bool) -> np.ndarray:
    """Pairs (i < j) of clusters that (almost) never share a window, as a boolean upper triangle;
    ``which``: each member's cluster, ``window``: each member's window, both numbered from 0. The
    windows two clusters share are counted for all pairs at once (a product of their window
    incidences), not pair by pair: the tracker's pool of unassigned modes holds tens of clusters,
    most of one mode each, and is searched for new modes every few windows."""
    seen = np.zeros((int(which.max()) + 1, int(window.max()) + 1))
    seen[which, window] = 1.0
    shared = seen @ seen.T  # distinct windows held by both (exact: sums of ones)
    held = np.diag(shared)
    fewer = np.minimum.outer(held, held)
    allowed = np.maximum(0.1 * fewer, np.where(few & (fewer >= 3), 1.0, 0.0))
    return np.triu(shared <= allowed, 1)


def model_modes(spec: StructureSpec, sensors: list[str], n_modes: int = 8,
                max_frequency_hz: float | None = None) -> list[tuple[float, np.ndarray]]:
    """The FE model's lowest modes at ``sensors`` (NaN at a sensor the model cannot read)."""
    from shm_ros.core.models import build_model

    model = build_model(spec)
    sol = model.modes(n_modes=n_modes)
    rows = np.full((len(sensors), model.n_dof), np.nan)
    for j, sid in enumerate(sensors):
        try:
            rows[j] = model.sensor_matrix([sid])[0]
        except KeyError:
            continue
    out = []
    for k, f in enumerate(sol.frequencies_hz):
        if max_frequency_hz is not None and f > max_frequency_hz:
            continue
        phi = rows @ sol.shapes[:, k]
        ok = np.isfinite(phi)
        if not ok.any() or np.max(np.abs(phi[ok])) <= 0:
            continue  # a mode the sensors cannot see
        out.append((float(f), phi / np.max(np.abs(phi[ok]))))
    return out


def build_reference(estimates: list[ModalEstimate], sensors: list[str], cfg: TrackingConfig,
                    model: list[tuple[float, np.ndarray]] | None = None) -> list[ReferenceMode]:
    """The tracked mode set, numbered from 1 (see the module docstring)."""
    source = ReferenceSource(cfg.reference_source)
    if source is not ReferenceSource.WINDOWS and not model:
        raise ValueError(f"reference_source={source.value} needs the structure's FE modes")
    if source is ReferenceSource.MODEL:
        assert model is not None
        return [ReferenceMode(k + 1, f, s, float("nan"), source="model") for k, (f, s) in enumerate(model)]
    clusters = cluster_modes(estimates, sensors, cfg.cluster_cutoff, cfg.min_presence)
    if source is ReferenceSource.WINDOWS:
        return [ReferenceMode(k + 1, f, s, p, d, spread=w) for k, (f, s, p, d, w) in enumerate(clusters)]
    assert model is not None
    # both: FE modes name the set; a cluster takes the number of the FE mode it matches by shape and
    # frequency. The FE model is a few % off, not tens: a mode the model has no DOF for (a torsion or
    # lateral mode of a planar model) can resemble a far-off FE mode at the sensors and must not take
    # its name; it stays a mode of its own, named by the data
    mac = mac_table(np.array([c[1] for c in clusters]).reshape(len(clusters), len(sensors)),
                    np.array([m[1] for m in model]))
    fc_ = np.array([c[0] for c in clusters], float)
    fm_ = np.array([m[0] for m in model], float)
    df = np.abs(fc_[:, None] - fm_[None, :]) / np.maximum(fc_[:, None], fm_[None, :])
    ok = (mac >= cfg.mac_min) & (df <= cfg.max_freq_gate)
    cost = np.where(ok, (1.0 - mac) + cfg.freq_weight * df, 1e6)
    rows, cols = linear_sum_assignment(cost) if mac.size else (np.zeros(0, int), np.zeros(0, int))
    matched = {int(r): int(c) for r, c in zip(rows, cols, strict=True) if ok[r, c]}
    refs: list[ReferenceMode] = []
    for c, (f, s) in enumerate(model):
        r = next((r for r, cc in matched.items() if cc == c), None)
        if r is None:
            refs.append(ReferenceMode(0, f, s, 0.0, source="model"))
        else:
            fc, sc, pc, dc, wc = clusters[r]
            refs.append(ReferenceMode(0, fc, sc, pc, dc, source="both", spread=wc))
    refs += [ReferenceMode(0, f, s, p, d, spread=w) for r, (f, s, p, d, w) in enumerate(clusters) if r not in matched]
    for k, ref in enumerate(refs):
        ref.number = k + 1
    return refs
