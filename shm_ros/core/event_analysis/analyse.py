"""``analyse_event(window)``: how the modes move within one earthquake record.

Short moving windows (default 10 periods of the lowest frequency of interest, step a tenth of
that) are identified one by one (input-output SSI when the window carries the structure's input
channel, else covariance-driven SSI), and the modes each finds are matched to reference modes (the
pre-event estimate's) by frequency and MAC, giving frequency and damping against time and against
the response amplitude of the window. The strong motion is the Arias-intensity interval (5-95 % by
default) of the input, or of the response without one; the pre-event phase ends one moving window
before it and the post-event phase starts once the response amplitude is back near the pre-event
level, and each phase is identified
as a whole, with a standard deviation from the spread over half-overlapping sub-windows.

Given the analysis model's natural frequencies, the followed modes are the model's: each model mode
takes the identified mode nearest in frequency (within ``MODEL_GATE``). A real building also shows
modes the model does not describe near them (a planar model's sensors see the other direction's
sway and torsion through their offset from the stiffness centre and their cross-axis sensitivity;
at the sensors their shapes look like the in-plane mode's). Those stay *guards*: a window's mode
nearer a guard than a followed mode is not taken for the followed one in windows whose response is
back near its ambient level (louder ones move the followed modes past their neighbours), so a quiet
window that found only the neighbouring sway mode leaves a gap rather than a jump.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from shm_ros.core.event_analysis.arias import significant_interval
from shm_ros.core.event_analysis.config import EventConfig, IntensitySource
from shm_ros.core.event_analysis.results import EventResult, ModeTrack, PhaseEstimate, PhaseMode, StrongMotion
from shm_ros.core.event_analysis.windows import (
    PHASE_STABILITY,
    ReferenceMode,
    WindowModes,
    identify_segment,
    match_modes,
    moving_config,
)
from shm_ros.core.identify import IdentifyConfig, Method
from shm_ros.core.preprocess import Prepared, PreprocessConfig, preprocess
from shm_ros.core.types import Window

__all__ = ["analyse_event", "running_median", "MODEL_GATE"]

# Largest relative distance between a model frequency and the identified mode it follows. A nominal
# model is some per cent off the structure (the simulated buildings' first modes: within 3 %);
# 10 % still keeps a planar building's first torsion mode (15-20 % above its first sway mode) out,
# and the other direction's first sway mode (6-10 % below) loses to the in-plane mode when both
# were identified.
MODEL_GATE = 0.10
GUARD_APART = 0.04  # a planar building's other sway direction sits 6-10 % from its in-plane mode
PHASE_PERIODS = 2.0  # block rows of a phase estimate, in periods of the lowest frequency of interest


def analyse_event(window: Window, config: EventConfig | None = None,
                  lowest_frequency_hz: float | None = None,
                  model_frequencies_hz: Sequence[float] | None = None) -> EventResult:
    """Within-event analysis of ``window`` (module doc). ``lowest_frequency_hz``: the structure's
    lowest frequency of interest (e.g. its nominal first natural frequency); ``config``'s own value
    wins, and without either the analysis model's first frequency, else the lowest mode identified
    over the whole record is taken. ``model_frequencies_hz``: the analysis model's natural
    frequencies (ascending); the followed modes are then the identified modes nearest to the lowest
    ``n_modes`` of them (module doc), else the lowest identified ones."""
    cfg = (config or EventConfig()).validate()
    model_f = np.sort(np.asarray(model_frequencies_hz, dtype=float)) if model_frequencies_hz is not None else None
    if model_f is not None and model_f.size and lowest_frequency_hz is None:
        lowest_frequency_hz = float(model_f[0])
    notes: list[str] = []
    name = window.input_channel if window.input_channel in window.channel_names else None
    method = Method(cfg.method)
    if method == Method.AUTO:
        method = Method.SSI_IO if name else Method.SSI_COV
    if method == Method.SSI_IO and name is None:
        raise ValueError("ssi-io needs the window's input channel (structure file 'input: {sensor: ...}')")
    inp = name if method == Method.SSI_IO else None
    channels = None if inp or name is None else [c for c in window.channel_names if c != name]
    base = IdentifyConfig(method=method.value, uncertainty=False, max_order=cfg.phase_max_order,
                          stability=PHASE_STABILITY)
    raw_fs = window.sample_rate_hz

    f_low = cfg.lowest_frequency_hz or lowest_frequency_hz
    if f_low is None:
        prep0 = preprocess(window.samples, raw_fs, window.channel_names,
                           PreprocessConfig(channels=channels), window.channel_status)
        whole = identify_segment(prep0, 0, prep0.data.shape[0], base, inp)
        if whole is None or whole.frequency_hz.size == 0:
            raise ValueError("no mode identified over the whole record: give the lowest frequency of interest")
        f_low = float(whole.frequency_hz[0])
        notes.append(f"lowest frequency of interest {f_low:.4g} Hz: the record's lowest identified mode")
    rate = cfg.target_rate_hz or 20.0 * f_low
    prep = preprocess(window.samples, raw_fs, window.channel_names,
                      PreprocessConfig(channels=channels, target_rate_hz=rate if rate < raw_fs / 2 else None),
                      window.channel_status)
    notes += prep.notes
    if inp is not None and inp not in prep.channel_names:
        raise ValueError(f"input channel {inp!r} is not among the usable channels {prep.channel_names}")
    fs = prep.sample_rate_hz
    n = prep.data.shape[0]
    outputs = [c for c in prep.channel_names if c != inp]
    out_idx = [prep.channel_names.index(c) for c in outputs]
    length = cfg.window_s or cfg.n_periods / f_low
    step = cfg.step_s or length / 10.0
    nw = int(round(length * fs))
    nst = max(1, int(round(step * fs)))
    if nw > n:
        raise ValueError(f"the record ({n / fs:.1f} s) is shorter than one moving window ({length:.1f} s)")
    rows = cfg.block_rows or max(math.ceil(cfg.max_order / len(outputs)) + 2, math.ceil(0.5 * fs / f_low))
    mcfg = moving_config(base, cfg.max_order, rows)

    strong = _strong_motion(prep, inp, outputs, cfg)
    starts = np.arange(0, n - nw + 1, nst)
    y = prep.data[:, out_idx]
    amp_col = int(np.argmax(np.sqrt(np.mean(y * y, axis=0))))
    ywin = np.lib.stride_tricks.sliding_window_view(y[:, amp_col], nw)[starts]
    resp = np.sqrt(np.mean(ywin * ywin, axis=1))
    if inp is not None:
        u = prep.data[:, prep.channel_names.index(inp)]
        uwin = np.lib.stride_tricks.sliding_window_view(u, nw)[starts]
        urms, upk = np.sqrt(np.mean(uwin * uwin, axis=1)), np.max(np.abs(uwin), axis=1)
        ut, uu = np.arange(n) / fs, u.copy()
    else:
        urms = upk = np.full(starts.size, np.nan)
        ut = uu = np.zeros(0)
    spans, quiet_level = _spans(starts / fs, resp, strong, length, n / fs, cfg)
    # the phases are long: block rows over two periods of the lowest mode resolve its neighbours a
    # few per cent away (another direction's sway, torsion), which the default 20 rows (under one
    # period here) blur into one pole that fails the two-A test (simulated 3-D buildings: mode 1
    # found before the event in 6 of 6 records instead of 3, within 1.2 %)
    pcfg = replace(base, block_rows=max(math.ceil(cfg.phase_max_order / len(outputs)) + 2,
                                        math.ceil(PHASE_PERIODS * fs / f_low)))
    phases, refs, guards = _phases(prep, pcfg, inp, spans, length, f_low, cfg, notes, model_f)
    found: list[WindowModes | None] = [identify_segment(prep, int(a), int(a) + nw, mcfg, inp) for a in starts]
    # guards hold only where the response is back near its ambient level: in louder windows the
    # followed modes move and may well pass a guard's frequency
    tracks = _tracks(found, refs, guards, resp <= quiet_level, cfg)
    return EventResult(window_id=window.window_id, start_ns=window.start_ns, method=method.value,
                       input_channel=inp, sample_rate_hz=fs, lowest_frequency_hz=float(f_low), window_s=nw / fs,
                       step_s=nst / fs, max_order=cfg.max_order, block_rows=rows, window_start_s=starts / fs,
                       response_rms_m_s2=resp, input_rms_m_s2=urms, input_peak_m_s2=upk,
                       amplitude_channel=outputs[amp_col], strong_motion=strong, tracks=tracks, phases=phases,
                       input_time_s=ut, input_m_s2=uu, notes=notes)


def _strong_motion(prep: Prepared, inp: str | None, outputs: list[str], cfg: EventConfig) -> StrongMotion:
    src = IntensitySource(cfg.intensity_source)
    if src == IntensitySource.AUTO:
        src = IntensitySource.INPUT if inp is not None else IntensitySource.RESPONSE
    if src == IntensitySource.INPUT:
        if inp is None:
            raise ValueError("event.intensity_source input: the window has no input channel in use")
        rec = prep.data[:, prep.channel_names.index(inp)]
    else:
        rec = prep.data[:, [prep.channel_names.index(c) for c in outputs]]
    t0, t1, total = significant_interval(rec, prep.sample_rate_hz, cfg.arias_low, cfg.arias_high)
    return StrongMotion(src.value, inp if src == IntensitySource.INPUT else None, t0, t1,
                        cfg.arias_low, cfg.arias_high, total)


def _spans(start_s: np.ndarray, resp: np.ndarray, sm: StrongMotion, length: float, dur: float,
           cfg: EventConfig) -> tuple[dict[str, tuple[float, float]], float]:
    """Pre-event: up to one moving window before the strong motion. Post-event: from the first
    window after the strong motion whose response RMS is back near the pre-event level (the
    amplitude-dependent stiffness has recovered only once the free decay has died out). Also that
    level of the response RMS."""
    pre = (0.0, sm.start_s - length)
    quiet = resp[start_s + length <= pre[1]] if pre[1] > 0 else resp[:0]
    level = cfg.recovery_ratio * float(np.median(quiet)) if quiet.size else float(np.max(resp)) / 20.0
    after = np.nonzero((start_s >= sm.end_s) & (resp <= level))[0]
    post_start = float(start_s[after[0]]) if after.size else dur
    return {"pre": pre, "strong": (sm.start_s, sm.end_s), "post": (post_start, dur)}, level


def _phases(prep: Prepared, base: IdentifyConfig, inp: str | None, spans: dict[str, tuple[float, float]],
            length: float, f_low: float, cfg: EventConfig, notes: list[str], model_f: np.ndarray | None
            ) -> tuple[list[PhaseEstimate], list[ReferenceMode], list[ReferenceMode]]:
    """Pre-event, strong-motion and post-event estimates, the reference modes to follow and the
    guards. Without model frequencies the references are the lowest ``n_modes`` at or above 0.7 x
    the lowest frequency of interest (a nominal first frequency may be some 10 % off) of the
    pre-event estimate, completed by the post-event and whole-record ones; with them, the modes of
    that pool nearest to the model's lowest ``n_modes`` (:func:`_model_references`)."""
    dur = prep.data.shape[0] / prep.sample_rate_hz
    targets = model_f[: cfg.n_modes] if model_f is not None and model_f.size else None

    whole: dict[str, WindowModes | None] = {}
    for key, (a, b) in spans.items():
        short = (b - a) < (0.5 if key == "strong" else 2.0) * length
        whole[key] = None if short else _identify_span(prep, a, b, base, inp)
    # pre-event modes first; a mode the quiet pre-event data missed comes from the post-event
    # estimate, then from the whole record (a first mode may hide in ambient noise)
    pool: list[ReferenceMode] = []
    for w in (whole["pre"], whole["post"], "whole"):
        if w == "whole":
            if targets is not None:
                if all(_nearest(pool, f) is not None for f in targets):
                    break
            elif len(pool) >= cfg.n_modes and pool[0].frequency_hz <= 1.3 * f_low:
                break
            notes.append("reference modes completed from the whole record")
            w = _identify_span(prep, 0.0, dur, base, inp)
        if isinstance(w, WindowModes):
            pool = _merge(pool, w, f_low, cfg.mac_min)
    if targets is None:
        refs, guards = pool[: cfg.n_modes], list[ReferenceMode]()
    else:
        refs, guards = _model_references(pool, targets, notes)
        if not refs:  # e.g. a short record whose whole-record modes sit low with the strong motion
            notes.append("no identified mode near the model's: the lowest identified modes are followed")
            refs = pool[: cfg.n_modes]
    if not refs:
        raise ValueError("no mode identified before, after or over the whole record")
    phases = []
    for key, (a, b) in spans.items():
        w = whole[key]
        if w is None:
            phases.append(PhaseEstimate(key, a, max(a, b), note="shorter than the phase minimum"
                                        if b - a > 0 else "no such phase in the record"))
            continue
        phases.append(_phase_estimate(prep, key, a, b, w, refs, guards, base, inp, length, cfg))
    return phases, refs, guards


def _nearest(pool: list[ReferenceMode], f: float) -> int | None:
    """Index of the pool's mode nearest to ``f`` in log-frequency, if within ``MODEL_GATE``."""
    if not pool:
        return None
    d = np.abs(np.log(np.array([p.frequency_hz for p in pool]) / f))
    j = int(np.argmin(d))
    return j if d[j] <= math.log1p(MODEL_GATE) else None


def _model_references(pool: list[ReferenceMode], targets: np.ndarray, notes: list[str]
                      ) -> tuple[list[ReferenceMode], list[ReferenceMode]]:
    """The pool's modes nearest to the model frequencies ``targets`` (one each, lowest first; a model
    mode without an identified mode within the gate is not followed) and the guards: the pool's
    other modes within the gate of a model frequency or between the followed ones."""
    refs: list[ReferenceMode] = []
    taken: set[int] = set()
    for f in targets:
        j = _nearest([p for k, p in enumerate(pool) if k not in taken], float(f))
        if j is None:
            notes.append(f"no identified mode within {100 * MODEL_GATE:.0f} % of the model's {f:.4g} Hz")
            continue
        k = [k for k in range(len(pool)) if k not in taken][j]
        taken.add(k)
        refs.append(pool[k])
    refs.sort(key=lambda r: r.frequency_hz)
    top = max((r.frequency_hz for r in refs), default=0.0) * (1 + MODEL_GATE)
    # a "mode" within GUARD_APART of a followed one is that mode's own second estimate, not a neighbour
    guards = [p for k, p in enumerate(pool) if k not in taken and p.frequency_hz <= top
              and all(abs(math.log(p.frequency_hz / r.frequency_hz)) > math.log1p(GUARD_APART) for r in refs)]
    if guards:
        notes.append("modes the model does not describe, kept apart from the followed ones: "
                     + ", ".join(f"{g.frequency_hz:.4g} Hz" for g in guards))
    return refs, guards


def _match(w: WindowModes, refs: list[ReferenceMode], guards: list[ReferenceMode], max_drop: float,
           mac_min: float) -> list[int | None]:
    """:func:`match_modes` of ``w`` to ``refs``, a found mode nearer in frequency to a guard than
    to the reference it matched left out (ties go to the reference)."""
    idx = match_modes(w, refs, max_drop, mac_min)
    if not guards:
        return idx
    g = np.array([x.frequency_hz for x in guards])
    out: list[int | None] = []
    for r, j in zip(refs, idx, strict=True):
        if j is not None:
            f = float(w.frequency_hz[j])
            if np.min(np.abs(np.log(g / f))) < abs(math.log(r.frequency_hz / f)):
                j = None
        out.append(j)
    return out


def _merge(pool: list[ReferenceMode], w: WindowModes, f_low: float, mac_min: float) -> list[ReferenceMode]:
    """``pool`` plus the modes of ``w`` at or above 0.7 f_low that match none of it, by frequency."""
    cand = [ReferenceMode(float(w.frequency_hz[j]), float(w.damping_ratio[j]), w.shapes[j])
            for j in range(w.frequency_hz.size) if w.frequency_hz[j] >= 0.7 * f_low]
    if pool and cand:
        found = WindowModes(np.array([c.frequency_hz for c in cand]), np.zeros(len(cand)), np.zeros(len(cand)),
                            np.array([c.shape for c in cand]), "")
        taken = match_modes(found, pool, 0.1, mac_min, max_rise=0.1)
        cand = [c for j, c in enumerate(cand) if j not in taken]
    return sorted(pool + cand, key=lambda r: r.frequency_hz)


def _identify_span(prep: Prepared, a_s: float, b_s: float, cfg: IdentifyConfig, inp: str | None
                   ) -> WindowModes | None:
    fs = prep.sample_rate_hz
    a, b = max(0, int(round(a_s * fs))), min(prep.data.shape[0], int(round(b_s * fs)))
    return identify_segment(prep, a, b, cfg, inp) if b > a else None


def _phase_estimate(prep: Prepared, key: str, a: float, b: float, w: WindowModes, refs: list[ReferenceMode],
                    guards: list[ReferenceMode], base: IdentifyConfig, inp: str | None, length: float,
                    cfg: EventConfig) -> PhaseEstimate:
    span = b - a
    n_sub = int(min(cfg.sub_windows, max(3, math.floor(2 * span / length) - 1)))
    sub = 2 * span / (n_sub + 1)
    # the strong motion lowers the followed modes past their neighbours: no guards there
    idx = _match(w, refs, guards if key != "strong" else [], cfg.max_drop, cfg.mac_min)
    subs = [_identify_span(prep, a + k * sub / 2, a + k * sub / 2 + sub, base, inp) for k in range(n_sub)]
    sub_f = np.full((n_sub, len(refs)), np.nan)
    sub_z = np.full((n_sub, len(refs)), np.nan)
    for k, s in enumerate(subs):
        if s is None:
            continue
        # sub-window modes are matched to the phase's own estimate, not to the references
        own = [ReferenceMode(float(w.frequency_hz[j]), float(w.damping_ratio[j]), w.shapes[j]) if j is not None
               else refs[r] for r, j in enumerate(idx)]
        for r, j in enumerate(match_modes(s, own, cfg.max_drop, cfg.mac_min)):
            if j is not None:
                sub_f[k, r], sub_z[k, r] = s.frequency_hz[j], s.damping_ratio[j]
    scale = math.sqrt(sub / span)
    modes = []
    for r, j in enumerate(idx):
        if j is None:
            continue
        ok = np.isfinite(sub_f[:, r])
        sf = float(np.std(sub_f[ok, r], ddof=1)) * scale if ok.sum() >= 3 else float("nan")
        sz = float(np.std(sub_z[ok, r], ddof=1)) * scale if ok.sum() >= 3 else float("nan")
        modes.append(PhaseMode(r + 1, float(w.frequency_hz[j]), float(w.damping_ratio[j]), sf, sz, int(ok.sum())))
    return PhaseEstimate(key, a, b, modes, sub_window_s=sub)


def running_median(x: np.ndarray, n: int) -> np.ndarray:
    """Centred running median over ``n`` samples ignoring NaN; NaN where fewer than ``n // 2 + 1``
    of them are finite (so one window's outlier never makes the minimum alone)."""
    x = np.asarray(x, dtype=float)
    if n <= 1:
        return x.copy()
    h = n // 2
    pad = np.concatenate([np.full(h, np.nan), x, np.full(n - 1 - h, np.nan)])
    view = np.lib.stride_tricks.sliding_window_view(pad, n)
    enough = np.sum(np.isfinite(view), axis=1) >= h + 1
    out = np.full(x.size, np.nan)
    if np.any(enough):
        out[enough] = np.nanmedian(view[enough], axis=1)
    return out


def _tracks(found: list[WindowModes | None], refs: list[ReferenceMode], guards: list[ReferenceMode],
            quiet: np.ndarray, cfg: EventConfig) -> list[ModeTrack]:
    nwin = len(found)
    f = np.full((nwin, len(refs)), np.nan)
    z = np.full((nwin, len(refs)), np.nan)
    sp = np.full((nwin, len(refs)), np.nan)
    for k, w in enumerate(found):
        if w is None:
            continue
        for r, j in enumerate(_match(w, refs, guards if quiet[k] else [], cfg.max_drop, cfg.mac_min)):
            if j is not None:
                f[k, r], z[k, r], sp[k, r] = w.frequency_hz[j], w.damping_ratio[j], w.frequency_spread_hz[j]
    tracks = []
    for r, ref in enumerate(refs):
        sm = running_median(f[:, r], cfg.smooth_windows)
        low = int(np.nanargmin(sm)) if np.any(np.isfinite(sm)) else None
        tracks.append(ModeTrack(r + 1, ref.frequency_hz, ref.damping_ratio, f[:, r], z[:, r], sp[:, r], sm, low))
    return tracks
