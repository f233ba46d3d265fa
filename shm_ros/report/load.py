"""Report inputs from the files the other commands write (``shm-ros report`` builds offline).

* ``ingest --out DIR``: ``DIR/windows.json`` (records, diagnostics, dropped stretches) and the
  windows' samples in ``DIR/windows/*.npz``;
* ``identify --out modes.json``: modal estimates (docs/interfaces.md §3);
* ``track --out DIR``: ``DIR/tracked_modes.csv`` (§4) and ``DIR/tracking.json`` (reference modes,
  environmental model, novelty);
* ``update --out DIR``: ``DIR/posterior.json`` (§6) and ``DIR/samples.npz``;
* ``simulate``: ``truth.json``.

Every reader raises ``ReportInputError`` naming the file and what is wrong with it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.errors import InputError
from shm_ros.report.inputs import DiagnosticRow, IdentifyInputs, IngestInputs, WindowHealth

__all__ = ["ReportInputError", "load_identify", "load_ingest", "load_json", "load_posterior", "load_tracking"]


class ReportInputError(InputError):
    """An input file of the report is missing or unreadable (the message names it)."""


def load_json(path: str | Path) -> dict[str, Any]:
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ReportInputError(f"{p}: cannot read ({exc.strerror or exc})") from exc
    except json.JSONDecodeError as exc:
        raise ReportInputError(f"{p}: not JSON ({exc})") from exc
    if not isinstance(doc, dict):
        raise ReportInputError(f"{p}: expected a JSON object")
    return doc


def load_ingest(path: str | Path) -> IngestInputs:
    """``windows.json`` of ``shm-ros ingest`` (the file or its folder)."""
    p = Path(path)
    if p.is_dir():
        p = p / "windows.json"
    doc = load_json(p)
    try:
        windows = [WindowHealth.from_record(r) for r in doc.get("windows", [])]
    except (KeyError, TypeError, ValueError) as exc:
        raise ReportInputError(f"{p}: field 'windows': bad record ({exc})") from exc
    return IngestInputs(windows, [DiagnosticRow.from_any(d) for d in doc.get("diagnostics", [])],
                        [dict(d) for d in doc.get("dropped", [])])


def load_identify(modes_path: str | Path, windows_dir: str | Path | None = None,
                  n_diagrams: int = 3) -> IdentifyInputs:
    """Estimates of ``modes.json``; when the windows' samples are at hand (``windows_dir`` of
    ``shm-ros ingest``), the stabilization diagrams of ``n_diagrams`` sample windows are computed
    again with the identification settings recorded in ``modes.json``."""
    from shm_ros.io.modes_json import read_modes_json

    p = Path(modes_path)
    try:
        estimates = read_modes_json(p)
    except (OSError, KeyError, TypeError, ValueError) as exc:
        raise ReportInputError(f"{p}: cannot read modal estimates ({exc})") from exc
    inputs = IdentifyInputs(estimates)
    if windows_dir is not None and estimates and n_diagrams > 0:
        inputs.diagrams = _diagrams(p, Path(windows_dir), estimates, n_diagrams)
    return inputs


def _diagrams(modes_path: Path, windows_dir: Path, estimates: list, n: int) -> dict[str, Any]:
    from shm_ros.core.identify import IdentifyConfig, identify_window_detailed
    from shm_ros.io.window_files import load_window

    wdir = windows_dir if windows_dir.name == "windows" else windows_dir / "windows"
    files = sorted(wdir.glob("*.npz")) if wdir.is_dir() else []
    if not files:
        return {}
    cfg_doc = (load_json(modes_path).get("provenance") or {}).get("configuration", {}).get("identify") or {}
    try:
        cfg = IdentifyConfig.from_dict(cfg_doc)
    except (TypeError, ValueError):
        cfg = IdentifyConfig()
    cfg.spectrum, cfg.uncertainty = True, False  # the plot's spectrum; no jackknife needed
    ordered = sorted(estimates, key=lambda e: e.start_ns)
    picks = [ordered[i].window_id for i in sorted({0, len(ordered) // 2, len(ordered) - 1})[:n]]
    out: dict[str, Any] = {}
    for wid in picks:
        # file names of `shm-ros ingest`: w<index>_<window id without ':' and '-'>.npz
        tag = wid.replace(":", "").replace("-", "")
        for f in (f for f in files if f.stem.split("_", 1)[-1] == tag):
            w = load_window(f)
            if w.window_id != wid:
                continue
            try:
                out[wid] = identify_window_detailed(w, cfg).diagram
            except (ValueError, ArithmeticError, np.linalg.LinAlgError):
                pass  # that window is shown without a diagram, as identify left it
            break
    return out


def load_tracking(path: str | Path) -> Any:
    """A ``TrackingResult`` from ``tracked_modes.csv`` (or the folder of ``shm-ros track`` with its
    ``tracking.json``); what only ``tracking.json`` holds is empty when it is absent."""
    from shm_ros.core.tracking import EnvironmentalFit, ReferenceMode, TrackingResult
    from shm_ros.io.tables import TableError, read_tracked_modes

    p = Path(path)
    csv_path, json_path = (p / "tracked_modes.csv", p / "tracking.json") if p.is_dir() else \
        (p, p.with_name("tracking.json"))
    try:
        obs = read_tracked_modes(csv_path)
    except TableError as exc:
        raise ReportInputError(str(exc)) from exc
    n_w = obs.n_windows
    doc = load_json(json_path) if json_path.is_file() else {}
    nov = doc.get("novelty") or {}
    score = np.array([math.nan if v is None else float(v) for v in nov.get("scores", [])], float)
    if score.size != n_w:
        score = np.full(n_w, math.nan)
    thr = nov.get("threshold")
    threshold = math.inf if thr is None else float(thr)
    n_train = int(nov.get("training_windows", 0) or 0)
    alarm = np.isfinite(score) & (score > threshold)
    alarm[:n_train] = False  # the tracking core's rule: the training period defines normal
    reference = [ReferenceMode(int(r["mode"]), float(r["frequency_hz"]),
                               np.array([math.nan if (v := r.get("mode_shape", {}).get(s)) is None else v
                                         for s in obs.sensor_ids], float), float(r.get("presence", math.nan)))
                 for r in doc.get("reference_modes", [])]
    env = []
    for e in doc.get("environment", []):
        vals: dict[str, Any] = {k: (math.nan if v is None else v) for k, v in e.items()}
        try:
            env.append(EnvironmentalFit(**vals))
        except TypeError:
            continue  # a field this version does not know: show the mode without its fit
    return TrackingResult(obs, reference, np.full((n_w, obs.n_modes), math.nan), env, score, threshold, alarm,
                          n_train, int(doc.get("unassigned_modes", 0) or 0), None, [],
                          list(obs.notes) + list(doc.get("notes", [])))


def load_posterior(path: str | Path, samples: str | Path | None = None) -> Any:
    """A ``Posterior`` from ``posterior.json`` (or the folder of ``shm-ros update``) and its
    ``samples.npz`` (default: next to it); without samples there are no corner/trace plots."""
    from shm_ros.core.bayes.update import ParameterSummary, Posterior

    p = Path(path)
    if p.is_dir():
        p = p / "posterior.json"
    doc = load_json(p)
    try:
        params = {n: ParameterSummary(float(v["map"]), float(v["mean"]), float(v["std"]),
                                      (float(v["ci95"][0]), float(v["ci95"][1])), float(v.get("median", v["mean"])))
                  for n, v in doc["parameters"].items()}
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise ReportInputError(f"{p}: field 'parameters': {exc}") from exc
    names = list(params)
    npz = Path(samples) if samples is not None else p.with_name("samples.npz")
    chains = np.zeros((0, 0, len(names)))
    flat, lp, chain_names = np.zeros((0, len(names))), np.zeros(0), names
    if npz.is_file():
        try:
            with np.load(npz, allow_pickle=False) as z:
                flat, lp, chains = np.array(z["samples"]), np.array(z["log_prob"]), np.array(z["chains"])
                chain_names = [str(c) for c in z["chain_names"]] if "chain_names" in z else names
        except (OSError, KeyError, ValueError) as exc:
            raise ReportInputError(f"{npz}: cannot read samples ({exc})") from exc
    elif samples is not None:
        raise ReportInputError(f"{npz}: no such file")
    le = doc.get("log_evidence")
    lee = doc.get("log_evidence_err")
    return Posterior(names, params, flat, lp, chains, chain_names, dict(doc.get("diagnostics") or {}),
                     dict(doc.get("fit") or {}), dict(doc.get("fit_nominal") or {}),
                     None if le is None else float(le), None if lee is None else float(lee),
                     dict(doc.get("noise") or {}), dict(doc.get("priors") or {}), list(doc.get("warnings") or []))
