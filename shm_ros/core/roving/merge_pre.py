"""Setups merged before identification: one subspace model over all setups.

Each setup ``j`` gives the block-Hankel matrix of its output correlations against the references
(covariance-driven SSI, :func:`shm_ros.core.ssi.correlations`): ``H_j = O_j Z_j``, whose reference
rows ``H_j^ref = O_ref Z_j`` share the references' observability while ``Z_j`` (the excitation of that
setup) differs. Each setup is brought onto the first one's ``Z_1`` by the least-squares map
``M_j = (H_j^ref)^+_n H_1^ref`` (pseudo-inverse truncated to the model order ``n``), so that
``H_j^mov M_j = O_mov,j Z_1``. The merged matrix has, in every block row, the references (mean of
``H_j^ref M_j``) followed by each setup's roving rows: one Hankel matrix of the whole structure
(the pre-identification re-scaling of Döhler 2011 and Amador & Brincker 2021, here on the
correlation Hankel matrices), identified once: one SVD, poles of every order, the project's
stability classification and automatic picking (:mod:`shm_ros.core.stabilization`). Shapes come out
over references and every roving channel at one scale.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.linalg as sla

from shm_ros.core import ssi
from shm_ros.core.identify import IdentifyConfig, max_order_of
from shm_ros.core.roving.merge_post import GlobalMode
from shm_ros.core.stabilization import classify, pick_modes_reported, real_mode_shape
from shm_ros.errors import InputError

__all__ = ["merged_hankel", "merge_pre"]


REL_RANK = 1e-2  # singular values of the references' Hankel matrix below this x the largest are noise


def _truncated_pinv(h: np.ndarray, rank: int) -> np.ndarray:
    """Pseudo-inverse of ``h`` on its leading singular values: at most ``rank`` and none below
    ``REL_RANK`` x the largest (inverting the noise floor would amplify it into every setup)."""
    u, s, vt = sla.svd(h, full_matrices=False, check_finite=False)
    n = max(1, min(rank, int(np.sum(s > s[0] * REL_RANK))))
    return (vt[:n].T / s[:n]) @ u[:, :n].T


def merged_hankel(datasets: Sequence[np.ndarray], channels: Sequence[Sequence[str]], references: Sequence[str],
                  block_rows: int, order: int) -> tuple[np.ndarray, list[str]]:
    """The merged block-Hankel matrix (rows: block row by block row, references then each setup's
    roving channels) and the channel names of one block row."""
    if not datasets:
        raise InputError("no setup to merge")
    i, nr = block_rows, len(references)
    ref_blocks, mov_blocks, names = [], [], list(references)
    target = None
    for k, (y, ch) in enumerate(zip(datasets, channels, strict=True)):
        ch = list(ch)
        missing = [r for r in references if r not in ch]
        if missing:
            raise InputError(f"setup {k + 1}: reference channel(s) {missing} not among {ch}")
        mov = [c for c in ch if c not in references]
        order_idx = [ch.index(r) for r in references] + [ch.index(c) for c in mov]
        y = np.asarray(y, dtype=float)[:, order_idx]
        r = ssi.correlations(y, np.arange(nr), 2 * i)
        h = ssi.block_hankel_of_correlations(r, i).reshape(i, len(order_idx), i * nr)
        h_ref, h_mov = h[:, :nr].reshape(i * nr, -1), h[:, nr:]
        if target is None:
            target = h_ref
            m = np.eye(i * nr)
        else:
            m = _truncated_pinv(h_ref, order) @ target
        ref_blocks.append((h_ref @ m).reshape(i, nr, -1))
        mov_blocks.append(np.einsum("abc,cd->abd", h_mov, m))
        names += mov
    if len(set(names)) != len(names):
        raise InputError(f"roving channel names must be unique across setups, got {names}")
    merged = np.concatenate([np.mean(ref_blocks, axis=0), *mov_blocks], axis=1)
    return merged.reshape(i * len(names), -1), names


def merge_pre(datasets: Sequence[np.ndarray], channels: Sequence[Sequence[str]], references: Sequence[str],
              sample_rate_hz: float, config: IdentifyConfig) -> tuple[list[GlobalMode], list[str]]:
    """Global modes from one subspace model over all setups (already pre-processed, one rate).
    ``config``: block rows (required), max order, stability and picking. Returns the modes and the
    notes."""
    if config.block_rows is None:
        raise InputError("merge_pre: identify.block_rows must be set (no band is chosen for merged setups)")
    nmax = max_order_of(config, config.method)
    h, names = merged_hankel(datasets, channels, references, config.block_rows, nmax)
    o, s = ssi.observability_from(h, nmax)
    model = ssi.SubspaceModel(o, s, len(names), sample_rate_hz, "ssi-cov", config.block_rows)
    orders = np.arange(max(1, config.min_order), o.shape[1] + 1, config.order_step)
    st = config.stability
    duration = min(np.shape(y)[0] for y in datasets) / sample_rate_hz
    poles = ssi.poles_all_orders(model, orders, two_a=st.two_a, match_scale=(
        st.two_a_freq_tol, st.two_a_damping_tol, st.two_a_mac_min), shapes_for=(st.freq_tol, st.damping_tol),
        std_scale=max(st.damping_sigmas, st.two_a_sigmas) / np.sqrt(duration))
    flags = classify(poles, st, sample_rate_hz, duration_s=duration)
    picked, _ = pick_modes_reported(poles, flags, config.picking, use_filters=config.use_filters)
    out = []
    for p in picked:
        phi = real_mode_shape(p.mode_shape_complex)
        out.append(GlobalMode(p.frequency_hz, p.damping_ratio, float("nan"),
                              {n: float(v) for n, v in zip(names, phi, strict=True)},
                              {n: float("nan") for n in names}, len(datasets)))
    notes = [f"pre-identification merge of {len(datasets)} setups: {len(names)} channels per block row, "
             f"{config.block_rows} block rows, orders up to {nmax}"]
    return out, notes
