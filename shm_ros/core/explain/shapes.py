"""Mode shapes as a second witness where frequencies cannot tell candidates apart.

Two candidates tie on frequencies when their changes of ln f are the same: a stiffness loss in the
first or in the last span of a symmetric girder, in the second or the second-last story. Their
shapes do change differently (mirror images of each other), and a tracked-modes table carries the
identified shapes per window. Per tied candidate at its MAP, the exact model's shapes at the sensors
are computed per window (the group factors quantised to :data:`N_LEVELS` levels, one eigen-solution
each) and compared with the identified ones, both unit-normalised with their signs aligned:

* only **changes** are compared (each mode's shape less its mean over the training windows), since
  the model's shapes differ from the structure's by model-form error that does not change between
  windows;
* per mode, identification scatter of unknown variance, profiled out: the shape log-likelihood of a
  candidate is ``sum_k -(n_k / 2) ln SSE_k``, with ``SSE_k`` the sum of squared differences of the
  changes over the training windows and sensors (``n_k`` entries).

Differences of this log-likelihood between tied candidates are added to their evidence gains
(:func:`shape_support`): the shapes are extra data, assumed independent of the frequencies, and the
parameters stay at each candidate's frequency MAP (a plug-in approximation; the shapes' share of the
information on the parameters is small). Candidates that change no shape in a way the sensors see
keep equal shape terms and stay tied, and two candidates that both scale the whole structure
(:data:`WHOLE`) are not told apart by shapes.
"""

from __future__ import annotations

import numpy as np

from .surrogate import Surrogate, _eig

N_LEVELS = 24  # factor levels per group at which shapes are computed (steps need two)
# groups that scale the whole structure: they move shapes only through what they leave out (a deck's
# stiffness against its bearings), a second-order change that the model-form error in those parts
# distorts as much as it shows it; two of them are not told apart by shapes (a uniform stiffness step
# came out as a uniform mass step by 37 nats of shapes on one simulated girder, the other way round
# by 160-490 nats on five)
WHOLE = ("EI", "mass")


def shape_terms(ll: dict[str, float], where: dict[str, str]) -> dict[str, float]:
    """The shape log-likelihood each tied candidate is credited with: its own, except that the
    candidates acting on :data:`WHOLE` groups all get the best of theirs (level among themselves)."""
    whole = [v for k, v in ll.items() if where[k] in WHOLE]
    top = max(whole) if whole else 0.0
    return {k: top if where[k] in WHOLE else v for k, v in ll.items()}


def _unit(phi: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Unit-normalised (over the last axis, NaN ignored) with the sign that agrees with ``ref``."""
    n = np.sqrt(np.nansum(phi ** 2, axis=-1, keepdims=True))
    u = phi / np.where(n > 0, n, 1.0)
    s = np.sign(np.nansum(u * ref, axis=-1, keepdims=True))
    return u * np.where(s == 0, 1.0, s)


def predicted_shapes(sur: Surrogate, factors: dict[str, np.ndarray], sensor_matrix: np.ndarray) -> np.ndarray:
    """Model shapes at the sensors (W, K, S) of the paired modes for per-window group factors (W,)."""
    names = list(factors)
    X = np.column_stack([np.asarray(factors[g], float) for g in names])  # (W, G)
    levels = np.empty_like(X)
    for j in range(X.shape[1]):
        u = np.unique(X[:, j])
        if u.size > N_LEVELS:  # quantise a continuous factor (shapes move smoothly with it)
            edges = np.linspace(u.min(), u.max(), N_LEVELS + 1)
            mids = 0.5 * (edges[1:] + edges[:-1])
            u = mids[np.clip(np.searchsorted(edges, X[:, j]) - 1, 0, N_LEVELS - 1)]
            levels[:, j] = u
        else:
            levels[:, j] = X[:, j]
    uniq, inv = np.unique(levels, axis=0, return_inverse=True)
    K, M = sur.groups.matrices({g: uniq[:, j] for j, g in enumerate(names)})
    _, phi = _eig(K, M, sur.n_modes)
    idx = sur._follow(phi, sur.phi_base[:, sur.model_index])  # (L, K) the paired modes, followed
    shapes = np.take_along_axis(phi, idx[:, None, :], axis=2)  # (L, dof, K)
    at = np.einsum("sd,ldk->lks", sensor_matrix, shapes)  # (L, K, S)
    return at[np.asarray(inv).ravel()]


def shape_log_likelihood(observed: np.ndarray, predicted: np.ndarray, train: np.ndarray) -> float:
    """``sum_k -(n_k / 2) ln SSE_k`` of the shape changes (module docstring); observed and predicted
    (W, K, S), NaN = not identified."""
    ref = np.nanmean(predicted[train], axis=0)  # (K, S) sign reference
    po = _unit(observed, ref[None])
    pp = _unit(predicted, ref[None])
    do = po - np.nanmean(po[train], axis=0)
    dp = pp - np.nanmean(pp[train], axis=0)
    e = (do - dp)[train]
    ok = np.isfinite(e)
    sse = np.sum(np.where(ok, e, 0.0) ** 2, axis=(0, 2))
    n = ok.sum(axis=(0, 2))
    use = (n > 0) & (sse > 0)
    return float(np.sum(-0.5 * n[use] * np.log(sse[use] / n[use])))
