"""One call from a :class:`Window` to a :class:`ModalEstimate`.

``identify_window(window, config)`` = pre-processing -> SSI (cov / data / input-output) -> poles
of every model order from one factorisation -> stability, two-A, MPC and physical filters ->
automatic clustering -> real mode shapes labelled by sensor id (docs/interfaces.md §3).
``identify_window_detailed`` returns the same plus the stabilization diagram.

The default method ``auto`` is input-output SSI when the window has a usable input channel (the
structure file's ``input: {sensor: ...}``, docs/interfaces.md §2) and covariance-driven SSI
otherwise; the estimate's ``method`` says which one ran, never ``auto``.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import scipy.linalg as sla
import scipy.signal as sig

from shm_ros.core import ssi
from shm_ros.core.band import BandChoice, BandSource, band_from_model, band_from_spectrum, choose_resolution
from shm_ros.core.config import check_choice, option
from shm_ros.core.ingest.covariates import window_covariates
from shm_ros.core.modal import mac_matrix
from shm_ros.core.preprocess import Prepared, PreprocessConfig, decimate, preprocess
from shm_ros.core.stabilization import (
    Diagram,
    FilterReport,
    PickedMode,
    PickingConfig,
    PoleFlags,
    StabilityConfig,
    TwoAScope,
    classify,
    cluster_candidates,
    pick_modes_reported,
    real_mode_shape,
    standard_error,
    two_a_by_column,
    two_a_flags,
)
from shm_ros.core.types import ModalEstimate, Mode, Window

__all__ = ["Method", "Weighting", "LQ", "IdentifyConfig", "IdentificationResult", "identify_window",
           "identify_window_detailed", "identify_prepared", "identify_array", "diagram_picks",
           "METHODS"]


class Method(enum.StrEnum):
    # With a measured input, output-only SSI takes the input's colour for the structure's: on the
    # simulated building under earthquakes its modes 1-4 were 0.8-1.1 % off on average (4 % worst;
    # 2.9-3.3 % off the fixed-base modes with the input sensor on a foundation on soil), input-output
    # SSI's 0.005-0.02 % (0.16 % worst; test/test_identify_defaults.py). Hence ``auto``.
    AUTO = "auto"  # ssi-io when the window has a usable input channel, else ssi-cov
    SSI_COV = "ssi-cov"  # covariance-driven stochastic subspace identification
    SSI_DATA = "ssi-data"  # data-driven
    SSI_IO = "ssi-io"  # input-output (needs an input channel)


class Weighting(enum.StrEnum):  # SSI-data weighting (see ssi.ssi_data)
    PC = "pc"
    UPC = "upc"  # unweighted
    CVA = "cva"


class LQ(enum.StrEnum):  # LQ factorisation of SSI-data / SSI-io
    AUTO = "auto"
    GRAM = "gram"
    QR = "qr"


METHODS = tuple(m.value for m in Method)
# automatic block rows: periods of the lowest mode of interest (IdentifyConfig.block_periods)
BLOCK_PERIODS = 2.0
IO_BLOCK_PERIODS = 4.0
# largest model order when unset. Input-output SSI reports a column's frequency as the mean over
# its orders, and the orders too low to hold every mode the outputs see pull it aside; on the
# peers bench's earthquake windows (eight-story building, 4 outputs, 50 Hz) the mean frequency
# errors of modes 1, 3 and 4 are 14-42 % smaller at 120 orders than at 60 (docs/identify.md).
# One output sees fewer of the modes than four (on the top floor's sensor alone, 99 orders were no
# better than 60 on three of those windows): ssi-io takes IO_ORDERS_PER_OUTPUT orders per output,
# at least MAX_ORDER, at most IO_MAX_ORDER.
MAX_ORDER = 60
IO_MAX_ORDER = 120
IO_ORDERS_PER_OUTPUT = 30


@dataclass
class IdentifyConfig:
    method: str = option(Method.AUTO.value, "identification method: auto (input-output SSI when the "
                         "window has a usable input channel, else covariance-driven), covariance-driven, "
                         "data-driven or input-output SSI (ssi-io needs an input sensor)", choices=Method)
    block_rows: int | None = option(None, "block rows of the Hankel matrix (unset: chosen with the band, "
                                    "see band; without a band max(20, ceil(max_order / references) + 2))")
    # A 0.5 Hz mode at 100 Hz needs about 400 samples of Hankel span; 20 block rows hold 20. The
    # band of interest sets the decimation and the block rows (core/band.py); explicit
    # block_rows and preprocess.target_rate_hz win.
    band: str = option(BandSource.AUTO.value, "band of interest that sets decimation and block rows: auto "
                       "(the structure's nominal model when known, else the prominent peaks of the output "
                       "spectrum), model, spectrum or off (no decimation, order-based block rows)",
                       choices=BandSource)
    band_modes: int = option(6, "modes of interest: the nominal model's lowest N frequencies set the band")
    band_margin: float = option(1.3, "top of the band = highest mode of interest x this")
    # Input-output SSI's state is a finite-horizon estimate from the past inputs and outputs: a
    # weakly excited mode in a short record needs a longer past than the correlations of
    # output-only SSI. On the CSMIP bridge record (docs/benchmarks.md) 2 periods of the first mode
    # found the second mode at 3 of 7 decimation factors (4-10), 4 periods at all 7.
    block_periods: float | None = option(None, "automatic block rows span at least this many periods "
                                         "of the lowest mode of interest (unset: 4 for ssi-io, 2 for "
                                         "the output-only methods)")
    max_block_rows: int = option(100, "largest automatic number of block rows (cost)")
    max_order: int | None = option(None, "largest model order (unset: 60; for ssi-io 30 per output, "
                                   "60 to 120, at most outputs x (block rows - 1))")
    min_order: int = option(2, "smallest model order")
    order_step: int = option(1, "model order step")
    reference_channels: list[str] | None = option(None, "reference sensor ids of SSI-cov / SSI-data "
                                                  "(unset: all channels)")
    input_channel: str | None = option(None, "input sensor id of SSI-io (unset: the structure "
                                       "file's input sensor)")
    lq: str = option(LQ.AUTO.value, "LQ factorisation of SSI-data / SSI-io", choices=LQ)
    weighting: str = option(Weighting.PC.value, "SSI-data weighting: pc, upc (unweighted) or cva",
                            choices=Weighting)
    # nested configurations: their options are "preprocess.<name>" etc.
    preprocess: PreprocessConfig = field(default_factory=PreprocessConfig)
    stability: StabilityConfig = field(default_factory=StabilityConfig)
    picking: PickingConfig = field(default_factory=PickingConfig)
    use_filters: bool = option(True, "two-A and MPC filters of spurious poles (false: plain "
                               "stabilization diagram)")
    exclude_input: bool = option(True, "output-only methods (ssi-cov, ssi-data, auto without a usable "
                                 "input) leave the window's input channel out")
    # The jackknife costs about 0.3-0.45 CPU-s per 10-minute window (the SSI itself about 0.2 s):
    # worth it for the standard deviations every estimate carries, live as well as offline.
    uncertainty: bool = option(True, "jackknife standard deviations of frequency and damping over "
                               "data blocks (SSI-cov, SSI-data)")
    uncertainty_blocks: int = option(10, "data blocks of the jackknife")
    # the structure's nominal natural frequencies (set from the structure file by the command)
    nominal_frequencies_hz: list[float] | None = None
    spectrum: bool = option(False, "keep the mean output spectrum in the diagram (set by the "
                            "command's --plots)", ros=False, cli=False)

    def to_dict(self) -> dict:
        return asdict(self)

    def validate(self) -> IdentifyConfig:
        """Raise ``ValueError`` naming the option when a choice is unknown."""
        check_choice("identify", "method", self.method, Method)
        check_choice("identify", "weighting", self.weighting, Weighting)
        check_choice("identify", "lq", self.lq, LQ)
        check_choice("identify", "band", self.band, BandSource)
        check_choice("identify", "stability.two_a_scope", self.stability.two_a_scope, TwoAScope)
        self.preprocess.validate()
        return self

    @classmethod
    def from_dict(cls, d: dict) -> IdentifyConfig:
        d = dict(d)
        sub: dict[str, type[PreprocessConfig | StabilityConfig | PickingConfig]] = {
            "preprocess": PreprocessConfig, "stability": StabilityConfig, "picking": PickingConfig}
        for key, typ in sub.items():
            if key in d and isinstance(d[key], dict):
                unknown = set(d[key]) - set(typ.__dataclass_fields__)
                if unknown:
                    raise ValueError(f"identify.{key}: unknown option(s) {sorted(unknown)}")
                d[key] = typ(**d[key])
        unknown = set(d) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f"identify: unknown option(s) {sorted(unknown)}")
        return cls(**d)


@dataclass
class IdentificationResult:
    estimate: ModalEstimate
    diagram: Diagram
    sample_rate_hz: float
    channel_names: list[str]
    notes: list[str]
    band: BandChoice | None = None  # what the automatic band chose (identify_window_detailed)
    filters: FilterReport | None = None  # poles each filter removed


def max_order_of(cfg: IdentifyConfig, method: Method | str, n_outputs: int | None = None,
                 block_rows: int | None = None) -> int:
    """The configured largest model order, or the method's default when unset: ``MAX_ORDER``;
    for ``ssi-io`` 30 per output between ``MAX_ORDER`` and ``IO_MAX_ORDER``, at most what its
    block rows hold (outputs x (rows - 1)), so that the unset order never asks for more block
    rows than ``MAX_ORDER`` does."""
    if cfg.max_order is not None:
        return int(cfg.max_order)
    if Method(method) != Method.SSI_IO or not n_outputs:
        return MAX_ORDER
    n = min(IO_MAX_ORDER, max(MAX_ORDER, IO_ORDERS_PER_OUTPUT * n_outputs))
    return min(n, n_outputs * (block_rows - 1)) if block_rows else n


def _block_rows(cfg: IdentifyConfig, n_refs: int) -> int:
    """Block rows when the band does not set them: enough for the configured order (``MAX_ORDER``
    when unset)."""
    if cfg.block_rows is not None:
        return int(cfg.block_rows)
    return max(20, int(np.ceil((cfg.max_order or MAX_ORDER) / n_refs)) + 2)


def identify_window(window: Window, config: IdentifyConfig | None = None) -> ModalEstimate:
    """Modal estimate of one window (modes sorted by frequency, shapes real, max |.| = +1)."""
    return identify_window_detailed(window, config).estimate


def identify_window_detailed(window: Window, config: IdentifyConfig | None = None
                             ) -> IdentificationResult:
    cfg = config or IdentifyConfig()
    cfg.validate()
    pcfg = cfg.preprocess
    name = cfg.input_channel or window.input_channel
    present = name if name in window.channel_names else None
    # under auto, input-output when the input is there (confirmed after the channel checks below)
    method = Method(cfg.method) if cfg.method != Method.AUTO else (
        Method.SSI_IO if present else Method.SSI_COV)
    if method != Method.SSI_IO and cfg.exclude_input and pcfg.channels is None and present:
        pcfg = replace(pcfg, channels=[c for c in window.channel_names if c != present])
    prep = preprocess(window.samples, window.sample_rate_hz, window.channel_names, pcfg,
                      window.channel_status)
    notes: list[str] = []
    if cfg.method == Method.AUTO and name is not None and name not in prep.channel_names:
        where = "among the usable channels" if present else "in the window"
        notes.append(f"method auto: input channel {name} is not {where}: output-only ssi-cov")
        method = Method.SSI_COV
    inp = None
    if method == Method.SSI_IO:
        if name is None:
            raise ValueError("ssi-io needs an input channel (structure file 'input: {sensor: ...}' "
                             "or IdentifyConfig.input_channel)")
        if name not in prep.channel_names:
            raise ValueError(f"ssi-io input channel {name!r} is not among the usable channels "
                             f"{prep.channel_names}")
        inp = name
    result = identify_prepared(prep, replace(cfg, method=method.value), [inp] if inp else None, notes)
    est = result.estimate
    est.window_id = window.window_id
    est.start_ns = window.start_ns
    est.end_ns = window.end_ns
    est.temperature_c = window.temperature_c
    est.covariates.update(window_covariates(window))
    return result


def identify_prepared(prep: Prepared, cfg: IdentifyConfig, input_channels: Sequence[str] | None = None,
                      notes: list[str] | None = None) -> IdentificationResult:
    """Band of interest, decimation and block rows chosen automatically (unless configured), then
    :func:`identify_array`: what :func:`identify_window_detailed` does after pre-processing.
    ``input_channels``: the measured inputs of ``ssi-io`` (one or several; ``auto`` runs ``ssi-io``
    when given). ``notes`` go after the pre-processing's in the result's notes."""
    inputs = list(input_channels or [])
    method = Method(cfg.method)
    if method == Method.AUTO:
        method = Method.SSI_IO if inputs else Method.SSI_COV
    prep, band = _resolution(prep, cfg, inputs if method == Method.SSI_IO else [], method)
    result = identify_array(prep, replace(cfg, method=method.value, block_rows=band.block_rows),
                            input_channel=inputs or None)
    result.band = band
    result.notes = list(prep.notes) + list(notes or []) + [band.describe()] + result.notes
    return result


def _resolution(prep: Prepared, cfg: IdentifyConfig, inputs: list[str], method: Method
                ) -> tuple[Prepared, BandChoice]:
    """Band of interest -> decimation and block rows (core/band.py); explicit options win."""
    outputs = [k for k, c in enumerate(prep.channel_names) if c not in inputs]
    n_refs = len(cfg.reference_channels) if cfg.reference_channels and not inputs \
        else max(1, len(outputs))
    default_rows = _block_rows(replace(cfg, block_rows=None), n_refs)
    source = BandSource(cfg.band)
    band = None
    if source in (BandSource.AUTO, BandSource.MODEL) and cfg.nominal_frequencies_hz:
        band = band_from_model(cfg.nominal_frequencies_hz, cfg.band_modes, cfg.band_margin)
        source = BandSource.MODEL
    elif source == BandSource.MODEL:
        source = BandSource.SPECTRUM  # no nominal model given: the spectrum instead
    if source in (BandSource.AUTO, BandSource.SPECTRUM) and band is None:
        source = BandSource.SPECTRUM
        band = band_from_spectrum(prep.data[:, outputs], prep.sample_rate_hz, cfg.band_margin)
    periods = cfg.block_periods if cfg.block_periods is not None else \
        IO_BLOCK_PERIODS if method == Method.SSI_IO else BLOCK_PERIODS
    choice = choose_resolution(prep.sample_rate_hz, band, source.value, default_rows=default_rows,
                               rows=cfg.block_rows, decimate=cfg.preprocess.target_rate_hz is None,
                               periods=periods, max_block_rows=cfg.max_block_rows)
    if cfg.band == BandSource.MODEL and not cfg.nominal_frequencies_hz:
        choice.reasons.insert(0, "band: model asked for, but no nominal model given: spectrum")
    return decimate(prep, choice.decimation, "band of interest"), choice


def identify_array(prep: Prepared, cfg: IdentifyConfig, input_channel: str | Sequence[str] | None = None
                   ) -> IdentificationResult:
    """Identification of already pre-processed data at the configured block rows (also used by
    the benchmarks). Under ``auto`` it is input-output SSI when ``input_channel`` (one name or
    several) is given, else covariance-driven."""
    names = list(prep.channel_names)
    data = prep.data
    fs = prep.sample_rate_hz
    notes: list[str] = []
    method = Method(cfg.method)
    if method == Method.AUTO:
        method = Method.SSI_IO if input_channel is not None else Method.SSI_COV
    if method == Method.SSI_IO:
        if not input_channel:
            raise ValueError("ssi-io needs input_channel")
        ins = [input_channel] if isinstance(input_channel, str) else list(input_channel)
        missing = [c for c in ins if c not in names]
        if missing:
            raise ValueError(f"ssi-io input channel(s) {missing} not among {names}")
        ks = [names.index(c) for c in ins]
        u = data[:, ks]
        out_idx = [j for j in range(len(names)) if j not in ks]
        y = data[:, out_idx]
        out_names = [names[j] for j in out_idx]
        if not out_names:
            raise ValueError(f"ssi-io: no output channel besides the input(s) {ins}")
        i = _block_rows(cfg, len(out_names))
        nmax = max_order_of(cfg, method, len(out_names), i)
        model = ssi.ssi_io(y, u, fs, i, nmax, lq=cfg.lq)
        refs = None
    else:
        y = data
        out_names = names
        if cfg.reference_channels:
            missing = [c for c in cfg.reference_channels if c not in names]
            if missing:
                raise ValueError(f"identify.reference_channels: unknown channel(s) {missing}")
            refs = np.array([names.index(c) for c in cfg.reference_channels])
        else:
            refs = np.arange(len(names))
        nmax = max_order_of(cfg, method)
        i = _block_rows(cfg, refs.size)
        if method == Method.SSI_COV:
            model = ssi.ssi_cov(y, fs, i, nmax, refs)
        else:
            model = ssi.ssi_data(y, fs, i, nmax, refs, lq=cfg.lq, weighting=cfg.weighting)
    orders = np.arange(max(1, cfg.min_order), model.observability.shape[1] + 1, cfg.order_step)
    poles, flags, picked, report = diagram_picks(model, orders, cfg, data.shape[0] / fs)
    std_f = np.full(len(picked), np.nan)
    std_z = np.full(len(picked), np.nan)
    if cfg.uncertainty and picked and method in (Method.SSI_COV, Method.SSI_DATA):
        nb, nmax = cfg.uncertainty_blocks, model.observability.shape[1]
        assert refs is not None  # only ssi-io leaves the references unset
        try:
            reps = (_cov_replicates(y, refs, i, nmax, nb) if method == Method.SSI_COV else
                    (m.observability for m in ssi.ssi_data_leave_one_out(
                        y, fs, i, nmax, refs, cfg.weighting, nb)))
            std_f, std_z = _jackknife(reps, nb, y.shape[1], fs, picked)
        except (ValueError, np.linalg.LinAlgError) as exc:  # too little data per block
            notes.append(f"uncertainty skipped: {exc}")
    modes = [Mode(frequency_hz=p.frequency_hz, damping_ratio=p.damping_ratio,
                  mode_shape=real_mode_shape(p.mode_shape_complex), mpc=p.mpc,
                  frequency_std_hz=float(sf), damping_std=float(sz), n_poles=p.n_poles,
                  frequency_spread_hz=p.frequency_spread_hz, damping_spread=p.damping_spread)
             for p, sf, sz in zip(picked, std_f, std_z, strict=True)]
    est = ModalEstimate(window_id="", start_ns=0, end_ns=int(round(data.shape[0] / fs * 1e9)),
                        sensor_ids=out_names, modes=modes, method=method.value)
    diagram = Diagram(poles=poles, flags=flags, picked=picked, singular_values=model.singular_values,
                      report=report)
    if cfg.spectrum:
        f_sp, p_sp = sig.welch(y, fs=fs, nperseg=min(4096, y.shape[0]), axis=0)
        diagram.spectrum_hz, diagram.spectrum = f_sp, p_sp.mean(axis=1)
    return IdentificationResult(est, diagram, fs, out_names, notes, filters=report)


def diagram_picks(model: ssi.SubspaceModel, orders: np.ndarray, cfg: IdentifyConfig, duration_s: float
                  ) -> tuple[ssi.PoleSet, PoleFlags, list[PickedMode], FilterReport]:
    """Poles of every order, their flags, the picked modes and the filter report.

    The two-A check validates the poles ``stability.two_a_scope`` says: every pole of every
    order; the stable, physical candidates at the orders where they occur
    (:func:`shm_ros.core.ssi.two_a_partners`); or (default) each stable column at as few of its
    orders as settle its verdict (:func:`shm_ros.core.stabilization.two_a_by_column`). Picking
    judges a column by the share of its orders that pass, so each column gets the same verdict
    either way, and the picks are the same."""
    st = cfg.stability
    scope = TwoAScope(st.two_a_scope)
    every = st.two_a and scope == TwoAScope.ALL
    match = (st.two_a_freq_tol, st.two_a_damping_tol, st.two_a_mac_min)
    std_scale = max(st.damping_sigmas, st.two_a_sigmas) / np.sqrt(duration_s)
    poles = ssi.poles_all_orders(model, orders, two_a=every, match_scale=match,
                                 shapes_for=(st.freq_tol, st.damping_tol), std_scale=std_scale)
    flags = classify(poles, st, model.sample_rate_hz, duration_s=duration_s)
    clusters = cluster_candidates(poles, flags, cfg.picking)  # the two-A check does not change them
    if st.two_a and scope == TwoAScope.STABLE:
        poles = ssi.two_a_partners(model, poles, flags.stable & flags.physical_ok, match, std_scale)
        sigma = standard_error(poles.frequency_hz, poles.damping_ratio, duration_s)
        flags.two_a_ok = two_a_flags(poles, st, sigma)
    elif st.two_a and scope == TwoAScope.COLUMNS and len(poles):
        check = ssi.BackwardCheck(model, int(poles.order.max()), match, std_scale)
        sigma = standard_error(poles.frequency_hz, poles.damping_ratio, duration_s)

        def validate(idx: np.ndarray) -> np.ndarray:
            check.partners(poles, idx)
            return two_a_flags(poles.subset(idx), st, sigma[idx])

        flags.two_a_ok, flags.two_a_checked = two_a_by_column(poles, flags, cfg.picking, validate, clusters)
    picked, report = pick_modes_reported(poles, flags, cfg.picking, use_filters=cfg.use_filters,
                                         clusters=clusters)
    return poles, flags, picked, report


def _cov_replicates(y: np.ndarray, refs: np.ndarray, i: int, max_order: int, n_blocks: int):
    """SSI-cov jackknife replicates: the correlation Hankel matrix is the mean of per-block
    matrices; each replicate drops one block and redoes the SVD (yields observability matrices)."""
    n = y.shape[0] // n_blocks
    if n_blocks < 3 or n < 8 * i:
        raise ValueError(f"{n_blocks} blocks of {n} samples are too short for {i} block rows")
    hs = np.stack([ssi.block_hankel_of_correlations(
        ssi.correlations(y[b * n:(b + 1) * n], refs, 2 * i), i) for b in range(n_blocks)])
    total = hs.sum(axis=0)
    for b in range(n_blocks):
        yield ssi.observability_from((total - hs[b]) / (n_blocks - 1), max_order)[0]


def _jackknife(replicates, n_blocks: int, n_out: int, fs: float, picked: list[PickedMode]
               ) -> tuple[np.ndarray, np.ndarray]:
    """Leave-one-block-out jackknife standard deviations of frequency and damping: each replicate
    observability matrix is evaluated at every picked mode's representative order and the pole
    nearest the mode (frequency and MAC) is taken."""
    fr = np.full((n_blocks, len(picked)), np.nan)
    zr = np.full((n_blocks, len(picked)), np.nan)
    for b, o in enumerate(replicates):
        orders = sorted({min(p.representative_order, o.shape[1]) for p in picked})
        # every order's least-squares A from one QR: with up = QR, the A of the leading n columns
        # is R_n^-1 (Q^T dn)_n, the leading block (what a lstsq per order gives, to rounding)
        q, r = sla.qr(o[:-n_out, :orders[-1]], mode="economic", check_finite=False)
        qtd = q.T @ o[n_out:, :orders[-1]]
        for nord in orders:
            a = sla.solve_triangular(r[:nord, :nord], qtd[:nord, :nord], check_finite=False)
            mu, psi = sla.eig(a, check_finite=False)
            sel = mu.imag > 0
            if not np.any(sel):
                continue
            lam = np.log(mu[sel]) * fs
            f = np.abs(lam) / (2 * np.pi)
            z = -lam.real / np.abs(lam)
            phi = o[:n_out, :nord] @ psi[:, sel]
            phi /= np.linalg.norm(phi, axis=0)
            for k, p in enumerate(picked):
                if min(p.representative_order, o.shape[1]) != nord:
                    continue
                mac = mac_matrix(p.mode_shape_complex[None], phi.T)[0]
                score = np.abs(f - p.frequency_hz) / p.frequency_hz + (1 - mac)
                j = int(np.argmin(score))
                if score[j] < 0.1:
                    fr[b, k], zr[b, k] = f[j], z[j]
    ok = np.sum(np.isfinite(fr), axis=0)

    def jk(v: np.ndarray) -> np.ndarray:
        # a mode found in no replicate has no mean (NaN, then no std) rather than a warning
        n = np.sum(np.isfinite(v), axis=0)
        mean = np.nansum(v, axis=0) / np.where(n > 0, n, np.nan)
        var = (ok - 1) / np.maximum(ok, 1) * np.nansum((v - mean) ** 2, axis=0)
        return np.where(ok >= max(3, n_blocks - 2), np.sqrt(var), np.nan)

    with np.errstate(invalid="ignore"):
        return jk(fr), jk(zr)
