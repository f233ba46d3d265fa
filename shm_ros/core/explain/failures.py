"""Named numerical failures inside a candidate's fit, and the result that records them.

A candidate whose fit meets a named numerical failure (an eigen-solver or factorisation that does not
converge, a singular or non-finite matrix, a non-finite Hessian at the MAP) is marked failed with the
reason, and the verdict is still written (:class:`shm_ros.errors.NumericalFailure`). Only these
failures are caught: any other exception is a bug and stops the run with its traceback.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from shm_ros.errors import NumericalFailure

from .types import CandidateResult


@contextmanager
def numerical(what: str) -> Iterator[None]:
    """Turn numpy's linear-algebra failures inside the block into :class:`NumericalFailure` naming ``what``."""
    try:
        yield
    except np.linalg.LinAlgError as exc:
        raise NumericalFailure(f"{what}: {exc}") from exc


def require_finite(what: str, *arrays: np.ndarray) -> None:
    """:class:`NumericalFailure` when any value of ``arrays`` is NaN (infinities are the prior's edge)."""
    for a in arrays:
        if np.isnan(np.asarray(a, dtype=float)).any():
            raise NumericalFailure(f"{what}: NaN")


def failed_result(name: str, label: str, where: str, exc: NumericalFailure, explanation: str = "") -> CandidateResult:
    """The table row of a candidate whose fit failed numerically: not accepted, the reason said."""
    return CandidateResult(
        name=name, label=label, form="fit failed", where=where, parameters={}, intervals={},
        log_evidence_gain=float("nan"), log_evidence_gain_check=None, log_evidence_gain_err=float("nan"),
        prior_sensitivity={}, accepted=False, reasons=[f"failed: numerical failure in the fit ({exc})"],
        explanation=explanation, failed=str(exc))
