"""Advice to the robot: has the current setup recorded enough, and where to go next.

**Enough** (per mode of interest): the shape's standard deviation at the robot's point is below
``shape_std_max`` (default 0.05, on the global shape's scale, largest component 1) and the frequency
has been stable within ``frequency_tol`` (default 0.5 %) over the last ``n_stable`` (3) estimates.

**Next point** by effective independence on the nominal model (Kammer 1991): with ``Phi`` the
nominal shapes (points x modes) at the points already measured and the references, the Fisher
information of the modal coordinates is ``F = Phi^T Phi / sigma^2``; a candidate point with shape row
``phi`` adds ``phi phi^T / sigma^2`` and shrinks the modal coordinates' covariance ``F^-1``. The
expected reduction of its trace is, by the Sherman-Morrison formula,
``phi^T F^-2 phi / (sigma^2 + phi^T F^-1 phi)``; the best point maximises it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Enough", "setup_enough", "expected_reduction", "next_point"]


@dataclass
class Enough:
    enough: bool
    reasons: list[str]  # what is still missing (empty when enough)


def setup_enough(point_std: Sequence[float], frequency_history: Sequence[Sequence[float]],
                 shape_std_max: float = 0.05, frequency_tol: float = 0.005, n_stable: int = 3) -> Enough:
    """``point_std[m]``: the shape std of mode m at the robot's point (NaN: not yet estimated);
    ``frequency_history[m]``: mode m's frequency estimates so far, oldest first."""
    reasons = []
    for m, (s, hist) in enumerate(zip(point_std, frequency_history, strict=True)):
        if not np.isfinite(s):
            reasons.append(f"mode {m + 1}: not identified yet (no shape std at this point)")
        elif s >= shape_std_max:
            reasons.append(f"mode {m + 1}: shape std at this point {s:.3g} (needs < {shape_std_max})")
        last = np.asarray(hist[-n_stable:], dtype=float)
        if last.size < n_stable:
            reasons.append(f"mode {m + 1}: {last.size} of {n_stable} frequency estimates")
        elif (last.max() - last.min()) / np.mean(last) > frequency_tol:
            reasons.append(f"mode {m + 1}: frequency moved {100 * (last.max() - last.min()) / np.mean(last):.2f} % "
                           f"over the last {n_stable} estimates (needs <= {100 * frequency_tol:g} %)")
    return Enough(not reasons, reasons)


def expected_reduction(measured: np.ndarray, candidates: np.ndarray, noise_std: float = 1.0) -> np.ndarray:
    """Expected reduction of trace(cov) of the modal coordinates for each candidate row (see module doc).
    ``measured`` (k, m): nominal shape rows already measured; ``candidates`` (c, m)."""
    f = measured.T @ measured / noise_std ** 2
    finv = np.linalg.pinv(f)
    a = candidates @ finv  # rows: F^-1 phi
    num = np.sum(a * a, axis=1)
    den = noise_std ** 2 + np.sum(a * candidates, axis=1)
    return num / den


def next_point(measured: np.ndarray, candidates: np.ndarray, noise_std: float = 1.0) -> tuple[int, np.ndarray]:
    """Index of the candidate with the largest expected reduction, and every candidate's reduction."""
    r = expected_reduction(measured, candidates, noise_std)
    return int(np.argmax(r)), r
