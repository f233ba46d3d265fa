"""Where the fixed references go: seen by every mode of interest, from the nominal model.

Merging setups rescales each mode through its reference components (merge_post.py): a mode whose
references sit near its nodes is scaled from components of the size of the noise, and its glued
shape scatters from setup to setup. The references are therefore placed where the *weakest* mode of
interest is seen best: among candidate locations, the set of ``n_refs`` that maximises
``min_m sum_r phi_m(x_r)^2`` (nominal shapes scaled to a largest component of 1 over the
candidates), searched exhaustively over pairs (or greedily beyond two references), ties broken by
effective independence (``det Phi^T Phi``, Kammer 1991) so the references also tell the modes apart.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np

__all__ = ["reference_scores", "place_references", "deck_references"]


def reference_scores(shapes: np.ndarray) -> tuple[float, float]:
    """(weakest mode's squared reference norm, det of the references' Fisher matrix) of rows ``shapes``."""
    return float(np.min(np.sum(shapes * shapes, axis=0))), float(np.linalg.det(shapes.T @ shapes)
                                                                  if shapes.shape[0] >= shapes.shape[1] else 0.0)


def place_references(candidates: Sequence[float], shapes: np.ndarray, n_refs: int = 2) -> list[int]:
    """Indices of the candidates for ``n_refs`` references (see module doc); ``shapes`` (candidates,
    modes) are the nominal modes of interest at the candidates."""
    phi = np.asarray(shapes, dtype=float)
    if phi.shape[0] != len(candidates) or n_refs < 1 or n_refs > phi.shape[0]:
        raise ValueError(f"place_references: {n_refs} references among {phi.shape[0]} candidates")
    phi = phi / np.abs(phi).max(axis=0)
    pairs = itertools.combinations(range(phi.shape[0]), min(n_refs, 2))
    chosen = list(max(pairs, key=lambda idx: reference_scores(phi[list(idx)])))
    while len(chosen) < n_refs:
        rest = [i for i in range(phi.shape[0]) if i not in chosen]
        chosen.append(max(rest, key=lambda i: reference_scores(phi[chosen + [i]])))
    return sorted(chosen, key=lambda i: candidates[i])


def deck_references(spec, n_refs: int = 2, n_modes: int = 3, step_m: float = 0.5) -> list[float]:
    """A girder's reference positions x (m) for the lowest ``n_modes`` nominal modes, on a grid of
    ``step_m`` along the deck (see module doc)."""
    model = spec.model_kind.build(spec)
    length = float(np.max(model.node_x))
    xs = np.arange(step_m, length - step_m / 2, step_m)
    shapes = model.deck_observation(xs) @ model.modes(n_modes=n_modes).shapes
    return [float(xs[i]) for i in place_references(list(xs), shapes, n_refs)]
