"""Mode shapes as a second witness where frequencies cannot tell candidates apart.

Two candidates tie on frequencies when their changes of ln f are the same: a stiffness loss or an
added mass in the first or in the last span of a symmetric girder. Their shapes do change
differently (mirror images of each other), and a tracked-modes table carries the identified shapes
per window. Per tied candidate at its MAP, the exact model's shapes at the sensors
are computed per window (the group factors quantised to :data:`N_LEVELS` levels, one eigen-solution
each) and compared with the identified ones, both unit-normalised with their signs aligned:

* only **changes** are compared (each mode's shape less its mean over the training windows), since
  the model's shapes differ from the structure's by model-form error that does not change between
  windows;
* per mode, identification scatter of unknown variance, profiled out: the shape log-likelihood of a
  candidate is ``sum_k -(n_k / 2) ln SSE_k``, with ``SSE_k`` the sum of squared differences of the
  changes over the training windows and sensors (``n_k`` entries).

Differences of this log-likelihood between tied candidates are added to their evidence gains
(:func:`break_tie`): the shapes are extra data, assumed independent of the frequencies, and the
parameters stay at each candidate's frequency MAP (a plug-in approximation; the shapes' share of the
information on the parameters is small). Candidates that change no shape in a way the sensors see
keep equal shape terms and stay tied; two candidates on the same group, or that both scale the whole
structure (:data:`WHOLE`), are not told apart by shapes.
"""

from __future__ import annotations

import math

import numpy as np

from shm_ros.core.modal import sign_aligned
from shm_ros.core.observations import ModalObservations

from .candidates.base import Modification
from .surrogate import Surrogate, _eig
from .types import CandidateResult

N_LEVELS = 24  # factor levels per group at which shapes are computed (steps need two)
# groups that scale the whole structure: they move shapes only through what they leave out (a deck's
# stiffness against its bearings), a second-order change that the model-form error in those parts
# distorts as much as it shows it; two of them are not told apart by shapes (a uniform stiffness step
# came out as a uniform mass step by 37 nats of shapes on one simulated girder, the other way round
# by 160-490 nats on five)
WHOLE = ("EI", "mass")


def shape_terms(ll: dict[str, float], where: dict[str, str]) -> dict[str, float]:
    """The shape log-likelihood each tied candidate is credited with: the best among the candidates
    on the same group (the shapes tell apart where a change acts, not how it follows a covariate,
    which the frequencies judge far better: a frost knee and a temperature knee of the same bearings,
    tied to 0.1 nats on frequencies, came 44 nats apart on shapes on a simulated girder), and the
    candidates acting on :data:`WHOLE` groups all get the best of theirs (level among themselves)."""
    key = {k: "whole" if w in WHOLE else w for k, w in where.items()}
    best: dict[str, float] = {}
    for k, v in ll.items():
        best[key[k]] = max(v, best.get(key[k], -math.inf))
    return {k: best[key[k]] for k in ll}


def _unit(phi: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Unit-normalised (over the last axis, NaN ignored) with the sign that agrees with ``ref``."""
    n = np.sqrt(np.nansum(phi ** 2, axis=-1, keepdims=True))
    return sign_aligned(phi / np.where(n > 0, n, 1.0), ref)


def predicted_shapes(sur: Surrogate, factors: dict[str, np.ndarray], sensor_matrix: np.ndarray) -> np.ndarray:
    """Model shapes at the sensors (W, K, S) of the paired modes for per-window group factors (W,)."""
    names = list(factors)
    X = np.column_stack([np.asarray(factors[g], float) for g in names])  # (W, G)
    levels = X.copy()
    for j, x in enumerate(X.T):
        if np.unique(x).size > N_LEVELS:  # quantise a continuous factor (shapes move smoothly with it)
            edges = np.linspace(x.min(), x.max(), N_LEVELS + 1)
            mids = 0.5 * (edges[1:] + edges[:-1])
            levels[:, j] = mids[np.clip(np.searchsorted(edges, x) - 1, 0, N_LEVELS - 1)]
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


def shape_terms_of(fits: list[tuple[str, str, Modification]], sur: Surrogate, obs: ModalObservations,
                   kept: list[int], train: np.ndarray) -> dict[str, float] | None:
    """The shape term of each fit ``(label, group, its modification at the MAP)``, by label
    (:func:`shape_terms`); None without identified shapes or where a candidate changes no group."""
    if not obs.has_shapes or obs.shapes is None:
        return None
    try:
        S = sur.groups.model.sensor_matrix(list(obs.sensor_ids))
    except KeyError:
        return None
    observed = obs.shapes[:, kept, :]
    ll = {}
    for label, _, mod in fits:
        if not mod.groups:  # a damping candidate changes no shape
            return None
        ll[label] = shape_log_likelihood(observed, predicted_shapes(sur, {g: x[0] for g, x in mod.groups.items()}, S),
                                         train)
    return shape_terms(ll, {label: where for label, where, _ in fits})


def break_tie(tied: list[CandidateResult], ll: dict[str, float], tie_nats: float) -> list[CandidateResult]:
    """The tie again with the shape terms ``ll`` added to the evidence gains: a candidate more than
    ``tie_nats`` behind the best in shapes, and more than ``tie_nats`` behind it in evidence and shapes
    together, leaves the tie (not accepted, with the reason); the rest stay tied with their relative
    support recomputed. Returns the tie, best first."""
    top = max(ll.values())
    total = {c.label: c.log_evidence_gain + ll[c.label] - top for c in tied}
    best = max(tied, key=lambda c: total[c.label])
    keep = []
    for c in tied:
        c.extra["shape_log_likelihood"] = ll[c.label] - ll[best.label]
        behind = ll[best.label] - ll[c.label]
        if c is not best and behind > tie_nats and total[best.label] - total[c.label] > tie_nats:
            c.accepted = False
            c.tied_with = []
            c.extra.pop("relative_support", None)
            c.reasons.append(f"failed: the identified shapes' changes prefer {best.label} by {behind:.1f} nats "
                             "(the frequencies cannot tell them apart)")
        else:
            keep.append(c)
    keep.sort(key=lambda c: -total[c.label])
    z = [math.exp(total[c.label] - total[best.label]) for c in keep]
    for c, zi in zip(keep, z, strict=True):
        c.tied_with = [o.label for o in keep if o is not c]
        c.extra["relative_support"] = zi / sum(z)
        c.reasons.append(f"shapes: log-likelihood of the shape changes {c.extra['shape_log_likelihood']:+.1f} "
                         f"nats against {best.label}")
    return keep
