"""The example building's calibration on its earlier earthquakes (``shm-ros example``).

A monitoring system has, before a later earthquake, the modal posterior of its ambient windows (the
update node's) and the records of the earthquakes it has seen. The earthquakes calibrate in the time
domain, where the input is measured: a time-domain posterior of their records (likelihood ``time``,
each event its own error variance) whose prior is the modal posterior (per parameter a normal of its
mean and standard deviation: the ambient windows' information carried forward). That posterior and
the same records (``calibration_windows``, from which the predict node learns the model error out of
sample) are what the predict node predicts the later earthquakes with; the time-domain step is the
job here, run beside the building's graph once the update node has written its posterior.
"""

from __future__ import annotations

import copy
import time
from pathlib import Path
from typing import Any

#: sampler of the time-domain step unless the example file's ``calibration:`` says otherwise
SAMPLER = {"likelihood": "time", "n_chains": 8, "n_steps": 150, "max_steps": 150, "evidence": False,
           "ess_target": 50.0, "rhat_target": 1.2, "residual_ar_order": 0, "variance_per_event": True}


def modal_priors(spec: Any, modal: dict[str, Any]) -> list[Any]:
    """The structure's parameters with, for each the modal posterior has, the prior normal(mean, std)
    of that posterior (the others keep the structure's prior)."""
    from shm_ros.core.structure import PriorSpec

    params = copy.deepcopy(spec.parameters)
    for p in params:
        s = modal.get(p.name)
        if s is not None and float(s["std"]) > 0:
            p.prior = PriorSpec("normal", {"mean": float(s["mean"]), "std": float(s["std"])})
    return params


def calibrate_on_events(structure: str, windows: list[str], modal_dir: str, out_dir: str, sampler: dict[str, Any],
                        wait_s: float = 1800.0) -> None:
    """Wait (at most ``wait_s``) for the modal posterior in ``modal_dir``, then write the
    time-domain posterior of the window files ``windows`` (``posterior.json``, ``samples.npz``)
    into ``out_dir``. Runs in a process of its own."""
    import os

    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from dataclasses import fields

    from shm_ros.core.bayes.records import RecordSet
    from shm_ros.core.bayes.timedomain import AccelerationRecord
    from shm_ros.core.bayes.update import UpdateConfig, update
    from shm_ros.core.models import build_model
    from shm_ros.core.predict import PredictConfig, event_from_window
    from shm_ros.core.predict.signals import prepare
    from shm_ros.io import jsonio
    from shm_ros.io.posterior_files import write_posterior
    from shm_ros.io.structure import load_structure
    from shm_ros.io.window_files import load_window

    modal_file = Path(modal_dir) / "posterior.json"
    end = time.monotonic() + wait_s
    while not modal_file.is_file():
        if time.monotonic() > end:
            raise TimeoutError(f"{modal_file}: no modal posterior after {wait_s:.0f} s")
        time.sleep(1.0)
    modal = jsonio.loads(modal_file.read_text(encoding="utf-8"))["parameters"]
    spec = load_structure(structure)
    model = build_model(spec)
    cfg = PredictConfig()  # the predict node's record preparation (baseline, pre-event window)
    recs = []
    for path in windows:
        ev = event_from_window(load_window(path), model)
        u, y, _ = prepare(ev, cfg)
        recs.append(AccelerationRecord(1.0 / ev.fs, u, y, ev.channel_ids))
    settings = {**SAMPLER, **sampler}
    known = {f.name for f in fields(UpdateConfig)}
    uc = UpdateConfig(**{k: v for k, v in settings.items() if k in known})
    post = update(model, RecordSet(recs), uc, modal_priors(spec, modal))
    write_posterior(out_dir, post, {"calibration": settings, "windows": windows, "prior": str(modal_file)}, uc.seed)


def start_calibration(part: dict[str, Any], doc: dict[str, Any], log: Any) -> Any:
    """Start :func:`calibrate_on_events` for the part's calibration windows (None without them) in a
    process of its own: it waits for the update node's posterior, which the graph writes."""
    import multiprocessing

    pred = part["settings"].get("predict") or {}
    if not part.get("calibration"):
        return None
    n = len(part["calibration"])
    log(f"building: {n} earlier earthquakes calibrate in the time domain (prior: the update node's modal "
        f"posterior); the later {len(part['scenario'].earthquakes) - n} are predicted")
    sampler = {"seed": part["scenario"].seed, **(doc.get("calibration") or {})}
    job = multiprocessing.get_context("spawn").Process(
        target=calibrate_on_events, name="example-calibration",
        args=(str(part["files"].structure), list(pred["calibration_windows"]), part["settings"]["update"]["output_dir"],
              pred["posterior"], sampler))
    job.start()
    return job


def finish_calibration(job: Any) -> None:
    """Collect the process once the graph is done (its posterior was needed before the last prediction)."""
    import sys

    if job is None:
        return
    job.join(timeout=60.0)
    if job.is_alive():  # the graph ended without the posterior: the report says what is missing
        job.terminate()
        job.join()
    if job.exitcode:
        print(f"[example] the time-domain calibration failed (exit code {job.exitcode})", file=sys.stderr)
