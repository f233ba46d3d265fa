"""The offline roving pipeline: tf tracks -> setups -> clock offset -> identification -> global modes.

Input: the sample times, the fixed references' accelerations, each roving sensor's three axes in its
own frame and a filled :class:`~shm_ros.core.roving.transforms.TransformBuffer`. Each roving sensor's
acceleration is rotated into the structure's frame and the component along its ``direction`` kept;
setups are cut where every roving sensor dwells (:func:`~shm_ros.core.roving.setups.cut_setups`); in
each setup the roving sensors' clock offset against the references is estimated
(:func:`~shm_ros.core.roving.clock.estimate_clock_offset`) and corrected; each setup is identified
(band of interest and block rows from the nominal model, SSI-cov with the references as reference
channels) and the setups merged (``post``, the default, or ``pre``). After the post merge each
mode's roving components come from the references' transmissibility in every setup
(:mod:`~shm_ros.core.roving.transmissibility`) and its frequency is extrapolated to the robot off the
structure (:mod:`~shm_ros.core.roving.carrier_mass`): one robot mass fitted to the setups of the
modes of interest (the nominal model's lowest ``unload_modes``, assigned by shape and frequency),
each of them the median of its setups shifted back; the other modes fitted one by one.

Each setup's Hankel matrix spans four periods of the lowest mode of interest (``block_periods``, two
by default for a window): at two, the girder-roving scenario's third vertical mode (18.3 Hz, a
torsion mode 4 % below it) came out 0.3 % low on average over 30 development seeds with the robot's
true mass put in; at three to five the bias was gone (docs/roving.md).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from shm_ros.core.band import nominal_frequencies
from shm_ros.core.delay import shift
from shm_ros.core.identify import IdentifyConfig, identify_prepared
from shm_ros.core.preprocess import Prepared, PreprocessConfig, decimate, preprocess
from shm_ros.core.roving.carrier_mass import carrier_mass, shifted_median, unloaded_frequency
from shm_ros.core.roving.clock import estimate_clock_offset
from shm_ros.core.roving.merge_post import GlobalMode, drop_unconfirmed, merge_post
from shm_ros.core.roving.merge_pre import merge_pre
from shm_ros.core.roving.nominal import NominalAtPoints
from shm_ros.core.roving.offline import MergeMethod
from shm_ros.core.roving.second_look import second_look
from shm_ros.core.roving.setups import (
    DEFAULT_FILTER_S,
    DEFAULT_MIN_DWELL_S,
    DEFAULT_TOLERANCE_M,
    SetupCut,
    cut_setups,
    sensor_track,
    setup_channels,
)
from shm_ros.core.roving.transforms import TransformBuffer
from shm_ros.core.roving.transmissibility import apply_transmissibility
from shm_ros.core.structure import StructureSpec
from shm_ros.core.types import ModalEstimate
from shm_ros.errors import InputError, NoWindowsError

__all__ = ["RovingConfig", "RovingResult", "prepare_setup", "roving_modes"]

AXIS = {"vertical": 2, "x": 0, "y": 1}
SETUP_BLOCK_PERIODS = 4.0  # periods of the lowest mode of interest in a setup's Hankel span (module doc)


@dataclass
class RovingConfig:
    tolerance_m: float = DEFAULT_TOLERANCE_M
    min_dwell_s: float = DEFAULT_MIN_DWELL_S
    filter_s: float = DEFAULT_FILTER_S
    merge: str = MergeMethod.POST.value
    correct_clock: bool = True
    second_look: bool = True  # search a setup's diagram for merged modes it missed (second_look.py)
    # roving components from the references' transmissibility on the merged reference shapes
    transmissibility: bool = True
    unload: bool = True  # frequencies at phi = 0 of the robot's point (carrier_mass.py), post merge only
    unload_modes: int = 3  # the modes of interest whose setups fit one robot mass (carrier_mass.py)
    identify: IdentifyConfig = field(default_factory=lambda: IdentifyConfig(
        method="ssi-cov", uncertainty=False, block_periods=SETUP_BLOCK_PERIODS))


@dataclass
class RovingResult:
    cut: SetupCut
    global_modes: list[GlobalMode]
    clock_offsets_s: list[float]  # per setup (first roving sensor)
    references: list[str]
    notes: list[str]

    @property
    def clock_offset_s(self) -> float:
        return float(np.median(self.clock_offsets_s)) if self.clock_offsets_s else float("nan")

    def to_dict(self) -> dict:
        """The ``setups`` and ``global_modes`` of modes.json (docs/interfaces.md section 8)."""
        setups = [s.to_dict(self.references) for s in self.cut.setups]
        for s, off in zip(setups, self.clock_offsets_s, strict=False):
            s["clock_offset_s"] = off
        return {"setups": setups, "global_modes": [g.to_dict() for g in self.global_modes],
                "roving": {"moving_samples": self.cut.moving_samples, "missing_samples": self.cut.missing_samples,
                           "short_samples": self.cut.short_samples, "errors": self.cut.errors(),
                           "clock_offset_s": self.clock_offset_s, "notes": list(self.notes)}}


def prepare_setup(y: np.ndarray, names: list[str], n_ref: int, fs: float, cfg: RovingConfig,
                  offset_s: float | None = None) -> tuple[float, Prepared]:
    """One setup's channels (references first): the roving sensors' clock offset (estimated unless
    ``offset_s`` is given), and the data pre-processed for identification with that offset
    corrected (``cfg.correct_clock``)."""
    off = estimate_clock_offset(y[:, n_ref], y[:, :n_ref], fs).offset_s if offset_s is None else offset_s
    if cfg.correct_clock:
        y = y.copy()
        y[:, n_ref:] = shift(y[:, n_ref:], fs, off)
    return off, preprocess(y, fs, names, PreprocessConfig())


def roving_modes(spec: StructureSpec, times_ns: np.ndarray, fs: float, references: Mapping[str, np.ndarray],
                 roving: Mapping[str, np.ndarray], buffer: TransformBuffer, config: RovingConfig | None = None
                 ) -> RovingResult:
    cfg = config or RovingConfig()
    tracks, along = [], {}
    for s in spec.roving:
        tr = sensor_track(buffer, spec.frame, s, times_ns, roving[s.id])
        assert tr.acceleration is not None
        tracks.append(tr)
        along[s.id] = tr.acceleration[:, AXIS[s.direction]] * s.source.sign
    cut = cut_setups(tracks, spec.measurement_points, cfg.tolerance_m, cfg.min_dwell_s, cfg.filter_s)
    if not cut.setups:
        raise NoWindowsError(f"no setup: no stretch of >= {cfg.min_dwell_s} s where every roving sensor stays within "
                             f"{cfg.tolerance_m} m of a measurement point")
    refs = list(references)
    icfg = replace(cfg.identify, reference_channels=refs,
                   nominal_frequencies_hz=cfg.identify.nominal_frequencies_hz or nominal_frequencies(spec, 6))
    channels = [setup_channels(setup, references, along) for setup in cut.setups]
    offsets, failed = _clock_offsets([y for y, _ in channels], len(refs), fs)
    preps = [prepare_setup(y, names, len(refs), fs, cfg, off)[1]
             for (y, names), off in zip(channels, offsets, strict=True)]
    notes = [f"{len(cut.setups)} setups; clock offset of the roving sensors {1e3 * float(np.median(offsets)):.1f} ms "
             f"({'corrected' if cfg.correct_clock else 'not corrected'})"] + failed
    results = [identify_prepared(p, icfg) for p in preps]
    if MergeMethod(cfg.merge) == MergeMethod.POST:
        modes = merge_post([r.estimate for r in results], refs)
        if cfg.second_look and second_look(results, modes, refs):
            modes = merge_post([r.estimate for r in results], refs)
            notes.append("a second look at the setups' diagrams found modes the automatic picking had missed")
        modes, more = drop_unconfirmed(modes, len(results), refs)
        notes += more
        if cfg.transmissibility:
            apply_transmissibility(modes, [p.data for p in preps], [p.sample_rate_hz for p in preps],
                                   [r.estimate for r in results], refs)
            notes.append("roving components from the references' transmissibility on the merged reference shapes")
        if cfg.unload:
            notes += _unload(modes, [r.estimate for r in results], cut,
                             NominalAtPoints(spec, cfg.unload_modes) if cfg.unload_modes > 0 else None,
                             spec.roving[0].carrier_mass_kg)
    else:
        band = results[0].band
        assert band is not None
        dec = [decimate(p, band.decimation, "band of interest") for p in preps]
        modes, more = merge_pre([d.data for d in dec], [d.channel_names for d in dec], refs, dec[0].sample_rate_hz,
                                replace(icfg, block_rows=band.block_rows))
        notes += more
    return RovingResult(cut, modes, offsets, refs, notes)


def _clock_offsets(data: list[np.ndarray], n_ref: int, fs: float) -> tuple[list[float], list[str]]:
    """Each setup's clock offset; a setup whose roving channel is too weakly coherent with the
    references for an estimate (a point near a node of every mode) takes the median of the others."""
    offsets, failed = [], []
    for k, y in enumerate(data):
        try:
            offsets.append(estimate_clock_offset(y[:, n_ref], y[:, :n_ref], fs).offset_s)
        except InputError as exc:
            offsets.append(float("nan"))
            failed.append(f"setup {k + 1}: {exc}; the other setups' median offset used")
    good = [o for o in offsets if np.isfinite(o)]
    if not good:
        raise InputError(f"clock offset: no setup gives one ({failed[0] if failed else 'no setup'})")
    fill = float(np.median(good))
    return [o if np.isfinite(o) else fill for o in offsets], failed


def _unload(modes: list[GlobalMode], estimates: list[ModalEstimate], cut: SetupCut,
            nominal: NominalAtPoints | None, known_mass_kg: float | None = None) -> list[str]:
    """Each merged mode's frequency without the robot (carrier_mass.py): the setups' frequencies
    against the squared merged component at the robot's point (the setup's roving points), one
    robot mass for the modes ``nominal`` assigns, a fit per mode for the others. A known mass (the
    structure file's ``carrier_mass_kg``) is used as it is, for the assigned modes only; 0 corrects
    nothing."""
    if known_mass_kg == 0:
        return ["the carrier's mass is given as 0: no frequency corrected for it"]
    freqs, phi2 = [], []
    for g in modes:
        group = g.members
        peak = max((abs(v) for v in g.shape.values() if np.isfinite(v)), default=np.nan)
        freqs.append(np.array([estimates[k].modes[i].frequency_hz for k, i in group.items()]))
        phi2.append(np.array([sum(g.shape.get(p, np.nan) ** 2 for p in cut.setups[k].points.values())
                              for k in group]) / peak ** 2)
    assigned = nominal.assign([g.frequency_hz for g in modes], [g.shape for g in modes]) if nominal else {}
    u = {j: phi2[j] / nominal.unit_max_modal_mass([k for k, v in modes[j].shape.items() if np.isfinite(v)])[n]
         for j, n in assigned.items()} if nominal else {}
    if known_mass_kg is not None:
        mass: float | None = known_mass_kg
        notes = [f"robot's mass as the structure file gives it: {known_mass_kg:g} kg"]
    else:
        mass = carrier_mass([freqs[j] for j in u], list(u.values()))
        notes = [] if mass is None else [f"robot's mass from the setups of the modes of interest: {mass:.0f} kg"]
    for j, g in enumerate(modes):
        if mass is not None and j in u and np.isfinite(f0 := shifted_median(freqs[j], u[j], mass)):
            g.notes.append(f"frequency without the robot {f0:.4g} Hz (setups' mean {np.mean(freqs[j]):.4g} Hz): "
                           f"the setups' median shifted back by the robot's {mass:.0f} kg")
            g.frequency_hz = f0
        elif known_mass_kg is None and (fit := unloaded_frequency(freqs[j], phi2[j])) is not None:
            g.notes.append(f"frequency without the robot {fit[0]:.4g} Hz (setups' mean {np.mean(freqs[j]):.4g} Hz): "
                           "the setups' frequencies fall with the squared component at the robot's point")
            g.frequency_hz = fit[0]
    return notes
