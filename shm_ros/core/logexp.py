"""Sums of exponentials in log space: the one helper every stage uses.

numpy only: scipy's ``logsumexp`` costs several times more on the small arrays of the likelihoods'
hot paths (the drift's ratio grid is averaged once per batch of parameter vectors)."""

from __future__ import annotations

import numpy as np


def logsumexp(a: np.ndarray, axis: int | None = None) -> np.ndarray:
    """ln of the sum of exp(a) along ``axis`` (all of ``a`` when None); -inf where every term is."""
    a = np.asarray(a, dtype=float)
    mx = np.max(a, axis=axis, keepdims=True)
    mx = np.where(np.isfinite(mx), mx, 0.0)
    with np.errstate(divide="ignore"):
        out = np.log(np.sum(np.exp(a - mx), axis=axis, keepdims=True)) + mx
    return np.squeeze(out, axis=axis) if axis is not None else out.reshape(())


def log_mean_exp(a: np.ndarray, axis: int = 0) -> np.ndarray:
    """ln of the mean of exp(a) along ``axis`` (a uniform prior's average over a grid)."""
    return logsumexp(a, axis) - np.log(np.shape(a)[axis])
