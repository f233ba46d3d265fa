"""A piece of complete grid rows -> a :class:`~shm_ros.core.types.Window`: quality checks per
channel (flags, status, diagnostics, notes), the temperature mean, the event decision and the
amplitude covariates."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from shm_ros.core.diagnostics import Level
from shm_ros.core.ingest.config import EventDetector, IngestConfig
from shm_ros.core.ingest.covariates import rms_accel
from shm_ros.core.ingest.diagnostics import DiagnosticLog
from shm_ros.core.ingest.events import EventKind, detect_event, event_kind
from shm_ros.core.ingest.quality import assess_channel
from shm_ros.core.ingest.units import units_hint_from_level
from shm_ros.core.timeutil import ns_to_iso
from shm_ros.core.types import SampleFlag, Window


@dataclass
class WindowContext:
    """What the window builder needs to know of the stream besides the samples."""

    names: Sequence[str]
    config: IngestConfig
    log: DiagnosticLog
    src: Callable[[int], str]  # diagnostic source of a channel
    channel_factor: Sequence[float | None]  # declared-units factor per channel (None: none declared)
    input_channel: str | None = None
    units_warned: set[tuple[int, str]] = field(default_factory=set)


def make_window(ctx: WindowContext, start_ns: int, vals: np.ndarray, flags: np.ndarray, dropped: np.ndarray,
                notes: list[str], grid_rate: float, nominal_rate: float,
                temperatures: tuple[np.ndarray, np.ndarray]) -> Window:
    """Check and package one piece. ``grid_rate`` is the rate of the grid the piece was cut on
    (the nominal one unless the clock drifted); ``temperatures`` are ``(stamps, values)``."""
    cfg, log = ctx.config, ctx.log
    n, C = vals.shape
    vals = np.ascontiguousarray(vals)
    flags = flags.copy()
    status = ["dropped" if dropped[c] else "ok" for c in range(C)]
    end_ns = start_ns + int(round(n * 1e9 / grid_rate))
    where = f"[{ns_to_iso(start_ns)}, {ns_to_iso(end_ns)})"
    columns = vals.T.copy()  # each channel's samples contiguous for the checks
    for c in range(C):
        name = ctx.names[c]
        if dropped[c]:
            notes.append(f"{name}: dropped (too few samples)")
            continue
        q = assess_channel(columns[c], grid_rate, dead_ptp=cfg.dead_ptp_m_s2, clip_run=cfg.clip_run,
                           saturation=cfg.saturation_m_s2, spike_k=cfg.spike_k, noisy_fraction=cfg.noisy_fraction)
        status[c] = q.status
        n_nan = int(q.nan.sum())
        if n_nan:
            flags[q.nan, c] |= np.uint8(SampleFlag.NAN)
            log.add(Level.WARN, "nan", ctx.src(c), f"{n_nan} NaN/Inf sample(s) in {where}: kept and flagged NAN",
                    start_ns, n_nan)
            notes.append(f"{name}: {n_nan} NaN/Inf samples")
        if q.dead_reason == "no finite sample":
            log.add(Level.WARN, "dead_channel", ctx.src(c), f"no finite sample in {where}", start_ns)
            notes.append(f"{name}: dead (no finite sample)")
            continue
        if q.dead_reason is not None:
            log.add(Level.WARN, "dead_channel", ctx.src(c),
                    f"stuck/zero variance (peak-to-peak {q.hi - q.lo:.3g} m/s^2) in {where}: marked dead, values kept",
                    start_ns)
            notes.append(f"{name}: dead (stuck)")
            continue
        n_clip = int(q.clipped.sum())
        if n_clip:
            flags[q.clipped, c] |= np.uint8(SampleFlag.CLIPPED)
            log.add(Level.WARN, "clipped", ctx.src(c), f"{n_clip} sample(s) flat-topped at "
                    f"{q.lo:.4g}/{q.hi:.4g} m/s^2 in {where}: flagged CLIPPED", start_ns, n_clip)
            notes.append(f"{name}: {n_clip} clipped samples")
        n_sp = int(q.spikes.sum())
        if n_sp:
            flags[q.spikes, c] |= np.uint8(SampleFlag.SPIKE)
            log.add(Level.WARN, "spike", ctx.src(c), f"{n_sp} isolated spike(s) in {where}: flagged SPIKE",
                    start_ns, n_sp)
            notes.append(f"{name}: {n_sp} spikes")
        _check_units(ctx, c, q.median, q.lo, q.hi, start_ns, notes)
    n_missing = int(((flags & SampleFlag.MISSING) != 0).sum())
    if n_missing:
        notes.append(f"{n_missing} missing samples of dropped channels set to NaN")
    temp = None
    temp_t, temp_v = temperatures
    if temp_t.size:
        inside = (temp_t >= start_ns) & (temp_t < end_ns)
        if inside.any():
            temp = float(temp_v[inside].mean())
    is_event, pga = detect_event(vals, status, nominal_rate, EventDetector(cfg.event_detector), sta_s=cfg.sta_s,
                                 lta_s=cfg.lta_s, sta_lta_on=cfg.sta_lta_on, pga_threshold=cfg.pga_threshold_m_s2)
    in_ch = ctx.input_channel if ctx.input_channel in ctx.names else None
    kind, input_pga = event_kind(vals, list(ctx.names), status, nominal_rate, in_ch, is_event, sta_s=cfg.sta_s,
                                 lta_s=cfg.lta_s, sta_lta_on=cfg.sta_lta_on,
                                 earthquake_pga_m_s2=cfg.earthquake_pga_m_s2)
    rms = rms_accel(vals, ctx.names, status, in_ch)
    w = Window(
        window_id=ns_to_iso(start_ns),
        start_ns=int(start_ns),
        sample_rate_hz=grid_rate,
        channel_names=list(ctx.names),
        samples=vals,
        flags=flags if flags.any() else None,
        channel_status=status,
        temperature_c=temp,
        is_event=is_event,
        pga_m_s2=pga,
        input_channel=in_ch,
        notes=notes,
        covariates={} if rms is None else {"rms_accel_m_s2": rms},
        event_kind=kind.value,
    )
    if kind == EventKind.EARTHQUAKE:
        log.add(Level.OK, "event", "accel", f"earthquake in {where}: input {in_ch} PGA {input_pga:.3g} m/s^2 "
                f"(peak of all channels {pga:.3g} m/s^2)", start_ns)
    elif is_event:
        ground = f"input {in_ch} PGA {input_pga:.3g} m/s^2" if in_ch else "no ground/input channel"
        log.add(Level.OK, "event", "accel", f"high-amplitude window (traffic, wind or works; {ground}) in "
                f"{where}, peak {pga:.3g} m/s^2", start_ns)
    return w


def _check_units(ctx: WindowContext, c: int, med: float, lo: float, hi: float, t: int, notes: list[str]) -> None:
    if ctx.channel_factor[c] not in (None, 1.0):
        return  # declared units were converted; the hint is about undeclared ones
    guess = units_hint_from_level(med, lo, hi)
    if guess is None:
        return
    if (c, guess) not in ctx.units_warned:
        ctx.units_warned.add((c, guess))
        ctx.log.add(Level.WARN, "units", ctx.src(c),
                    f"static level {med:.4g} looks like {guess}, not m/s^2: values NOT rescaled; "
                    "check the driver or the AccelBlock units field", t)
    notes.append(f"{ctx.names[c]}: units look like {guess}")
