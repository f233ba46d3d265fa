"""The form flag: does a candidate's functional form fit what it explains?

An effect acts through its factor per window ``x_w`` (on its parameter group). When its form is
right, what is left after it (the misfit less the effect) no longer depends on ``x``; when the form is
wrong (a saturating friction fitted by a softening law, a humidity course fitted by a temperature
law) a smooth function of ``x`` still explains part of the misfit. The test: the misfit after the
effect on the training windows against hinge functions of ``x`` (and its square), each mode with its
own coefficients, by the closed-form evidence of the catch-all (:func:`.likelihood.catch_all_gain`);
a gain above the acceptance threshold says ``form_fits: false``. An effect with one value of ``x``
before and one after (a step) has no form to test beyond that: it passes.
"""

from __future__ import annotations

import numpy as np

from .likelihood import catch_all_gain


def form_basis(x: np.ndarray) -> np.ndarray | None:
    """Smooth functions of the factor ``x`` (W,): x, x², and hinges at its quartiles; None when ``x``
    takes fewer than 4 distinct values (nothing beyond the effect's own levels to test)."""
    x = np.asarray(x, dtype=float)
    if np.unique(np.round(x[np.isfinite(x)], 12)).size < 4:
        return None
    cols = [x, x ** 2] + [np.minimum(x - c, 0.0) for c in np.quantile(x, [0.25, 0.5, 0.75])]
    return np.column_stack(cols)


def form_gain(x: np.ndarray, misfit_after: np.ndarray, noise_guess: float) -> float | None:
    """Summed gain (nats) of smooth functions of ``x`` on the misfit after the effect (W, K); None when
    there is no form to test."""
    basis = form_basis(x)
    if basis is None:
        return None
    gains, _ = catch_all_gain(misfit_after, basis, noise_guess)
    return float(np.sum(gains))
