"""The predict node's worker process (no ROS here: it is imported by a spawned interpreter).

Pushing hundreds of posterior draws through the model takes seconds; in a process of its own it
never blocks the node's executor. The structure is loaded and the model built once per process; the
posterior file is re-read whenever it changed on disk (the update node rewrites it after each run).
"""

from __future__ import annotations

import signal
from pathlib import Path
from typing import Any

from shm_ros.core.predict import PredictConfig

_state: dict[str, Any] = {}


def init(structure: str) -> None:
    from shm_ros.core.models import build_model
    from shm_ros.io.structure import load_structure

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the node ends this process, not Ctrl-C
    spec = load_structure(structure)
    _state.update(spec=spec, model=build_model(spec), posterior=None, stamp=None)


def ready() -> bool:
    return "model" in _state


def _posterior(path: str | None) -> Any:
    if not path:
        return None
    p = Path(path)
    p = p / "posterior.json" if p.is_dir() else p
    if not p.is_file():
        return None
    npz = p.with_name("samples.npz")
    stamp = (p.stat().st_mtime_ns, npz.stat().st_mtime_ns if npz.is_file() else 0)
    if stamp != _state["stamp"]:
        from shm_ros.report.load import load_posterior

        _state.update(posterior=load_posterior(p), stamp=stamp)
    return _state["posterior"]


def run(window: Any, config: PredictConfig, posterior_path: str | None) -> Any:
    """The prediction of one window (as ``shm-ros predict`` computes it) and its Table-3 row."""
    from shm_ros.commands.predict import predict_windows
    from shm_ros.core.predict import table3_row

    model = _state["model"]
    preds, errors = predict_windows(model, [window], _posterior(posterior_path), config,
                                    limits=_state["spec"].drift_limits)
    if errors:
        raise ValueError(errors[0])
    return preds[0], table3_row(model, preds[0])
