"""The one place the generator touches OpenSeesPy: a fresh model, eigen frequencies, quiet logging.

OpenSees keeps one global domain per process, so every builder starts with :func:`fresh` (which
calls ``ops.wipe()``) and a campaign never holds two models at once.
"""

from __future__ import annotations

import os

import numpy as np

try:
    import openseespy.opensees as ops
except ImportError as exc:  # pragma: no cover - a clear message for a missing optional dependency
    raise ImportError("the truth generator needs OpenSeesPy (pip install 'openseespy<3.8') and the "
                      "Debian packages libblas3 liblapack3") from exc

__all__ = ["ops", "fresh", "eigen_hz", "eigen_shapes"]


def fresh(ndm: int, ndf: int) -> None:
    """Wipe the global OpenSees domain and start a basic model of ``ndm`` dimensions, ``ndf`` DOFs/node."""
    ops.wipe()
    ops.logFile(os.devnull, "-noEcho")  # OpenSees' warnings would flood the test log
    ops.model("basic", "-ndm", ndm, "-ndf", ndf)


def _analysis_setup() -> None:
    ops.constraints("Transformation")
    ops.numberer("RCM")
    ops.system("BandGeneral")


def eigen_hz(n: int, solver: str = "-fullGenLapack") -> np.ndarray:
    """The lowest ``n`` natural frequencies (Hz) of the current model (dense LAPACK solver: exact
    for the small models here and indifferent to massless DOFs)."""
    _analysis_setup()
    lam = np.asarray(ops.eigen(solver, n), dtype=float)
    return np.sqrt(np.clip(lam, 0.0, None)) / (2.0 * np.pi)


def eigen_shapes(n: int, points: list[tuple[int, int]], solver: str = "-fullGenLapack"
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies (n,) and shapes (n_points, n) read at (node, dof) pairs (dof 1-based)."""
    f = eigen_hz(n, solver)
    phi = np.array([[ops.nodeEigenvector(node, k + 1, dof) for k in range(n)] for node, dof in points])
    return f, phi
