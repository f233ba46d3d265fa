"""The predict node's worker process (no ROS here: it is imported by a spawned interpreter).

Pushing hundreds of posterior draws through the model takes seconds; in a process of its own it
never blocks the node's executor. The structure is loaded and the model built once per process; the
posterior file is re-read whenever it changed on disk (the update node rewrites it after each run).
With calibration windows the model error is learnt from them out of sample once per posterior.
"""

from __future__ import annotations

import signal
from pathlib import Path
from typing import Any

from shm_ros.core.predict import PredictConfig

_state: dict[str, Any] = {}


def init(structure: str, calibration: tuple[str, ...] = ()) -> None:
    from shm_ros.core.models import build_model
    from shm_ros.io.structure import load_structure
    from shm_ros.io.window_files import load_window

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the node ends this process, not Ctrl-C
    spec = load_structure(structure)
    _state.update(spec=spec, model=build_model(spec), posterior=None, stamp=None,
                  calibration=[load_window(p) for p in calibration], model_error=None)


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

        _state.update(posterior=load_posterior(p), stamp=stamp, model_error=None)
    return _state["posterior"]


def _model_error(posterior: Any, config: PredictConfig) -> Any:
    """The out-of-sample model error of ``posterior`` (learnt once per posterior file), or None
    without calibration windows or posterior."""
    if posterior is None or not _state["calibration"]:
        return None
    if _state["model_error"] is None:
        from shm_ros.commands.predict import learn_model_error

        _state["model_error"] = learn_model_error(_state["model"], posterior, _state["calibration"], config)
    return _state["model_error"]


def run(window: Any, config: PredictConfig, posterior_path: str | None) -> Any:
    """The prediction of one window (as ``shm-ros predict`` computes it), its Table-3 row and its
    traces as JSON text (encoded here, not in the node: tens of MB of numbers)."""
    from shm_ros.commands.predict import predict_windows
    from shm_ros.core.predict import table3_row
    from shm_ros.io.prediction_files import series_text

    model = _state["model"]
    posterior = _posterior(posterior_path)
    preds, errors = predict_windows(model, [window], posterior, config, limits=_state["spec"].drift_limits,
                                    model_error=_model_error(posterior, config))
    if errors:
        raise ValueError(errors[0])
    return preds[0], table3_row(model, preds[0]), series_text(preds[0])
