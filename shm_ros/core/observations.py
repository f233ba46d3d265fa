"""Modal data as the updating core sees it: one row per tracked window (docs/interfaces.md §4)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ModalObservations:
    """Tracked modal data of many windows.

    ``frequencies_hz[w, k]`` is tracked mode ``mode_numbers[k]`` in window ``w`` (NaN = not found).
    ``shapes[w, k, s]`` are real shape components at ``sensor_ids[s]`` (NaN = missing), or ``None``
    when the table has no shapes. ``covariates`` holds every other column (one value per window).
    """

    times: np.ndarray  # (n_windows,) seconds (POSIX seconds when the table had ISO 8601 stamps)
    mode_numbers: list[int]
    frequencies_hz: np.ndarray  # (n_windows, n_modes)
    shapes: np.ndarray | None = None  # (n_windows, n_modes, n_sensors)
    sensor_ids: list[str] = field(default_factory=list)
    damping: np.ndarray | None = None  # (n_windows, n_modes)
    covariates: dict[str, np.ndarray] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    time_kind: str = "seconds"  # "seconds" | "iso" (how the table wrote its time column)
    # identified modes that paired with no model mode when the data were built from per-window
    # estimates (``pairing.observations_from_estimates``): dicts as in posterior.json
    # ``unmodelled_modes`` (docs/interfaces.md §6)
    unmodelled_modes: list[dict] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.times = np.asarray(self.times, dtype=float)
        self.frequencies_hz = np.atleast_2d(np.asarray(self.frequencies_hz, dtype=float))
        n_w, n_m = self.frequencies_hz.shape
        if self.times.shape != (n_w,):
            raise ValueError(f"times has {self.times.size} entries for {n_w} windows")
        if len(self.mode_numbers) != n_m:
            raise ValueError(f"{len(self.mode_numbers)} mode numbers for {n_m} frequency columns")
        if self.shapes is not None:
            self.shapes = np.asarray(self.shapes, dtype=float)
            if self.shapes.shape != (n_w, n_m, len(self.sensor_ids)):
                raise ValueError(f"shapes must be (windows, modes, sensors) = "
                                 f"{(n_w, n_m, len(self.sensor_ids))}, got {self.shapes.shape}")
            if np.all(np.isnan(self.shapes)):
                self.shapes = None

    @property
    def n_windows(self) -> int:
        return int(self.frequencies_hz.shape[0])

    @property
    def n_modes(self) -> int:
        return int(self.frequencies_hz.shape[1])

    @property
    def has_shapes(self) -> bool:
        return self.shapes is not None and len(self.sensor_ids) > 0

    def subset(self, windows: np.ndarray | slice) -> ModalObservations:
        """The same data restricted to some windows (e.g. a held-out split)."""
        return ModalObservations(
            times=self.times[windows], mode_numbers=list(self.mode_numbers),
            frequencies_hz=self.frequencies_hz[windows],
            shapes=None if self.shapes is None else self.shapes[windows],
            sensor_ids=list(self.sensor_ids),
            damping=None if self.damping is None else self.damping[windows],
            covariates={k: v[windows] for k, v in self.covariates.items()},
            notes=list(self.notes), time_kind=self.time_kind,
            unmodelled_modes=list(self.unmodelled_modes))

    def without_empty_modes(self) -> tuple[ModalObservations, list[int]]:
        """The same data without modes that have no frequency in any window (and their numbers)."""
        present = np.any(np.isfinite(self.frequencies_hz) & (self.frequencies_hz > 0), axis=0)
        if present.all():
            return self, []
        dropped = [self.mode_numbers[k] for k in np.flatnonzero(~present)]
        keep = np.flatnonzero(present)
        return ModalObservations(
            times=self.times, mode_numbers=[self.mode_numbers[k] for k in keep],
            frequencies_hz=self.frequencies_hz[:, keep],
            shapes=None if self.shapes is None else self.shapes[:, keep],
            sensor_ids=list(self.sensor_ids),
            damping=None if self.damping is None else self.damping[:, keep],
            covariates=dict(self.covariates), notes=list(self.notes), time_kind=self.time_kind,
            unmodelled_modes=list(self.unmodelled_modes)), dropped

    def mean_frequencies(self) -> np.ndarray:
        return np.nanmean(self.frequencies_hz, axis=0)

    def reference_shapes(self) -> np.ndarray | None:
        """Per-mode average shape (n_modes, n_sensors), signs aligned to the first window's shape.

        Used to pair data modes with model modes by MAC; NaN components are ignored.
        """
        if not self.has_shapes:
            return None
        assert self.shapes is not None
        out = np.full((self.n_modes, len(self.sensor_ids)), np.nan)
        for k in range(self.n_modes):
            rows = self.shapes[:, k, :]
            ok = ~np.all(np.isnan(rows), axis=1)
            if not ok.any():
                continue
            rows = rows[ok]
            ref = np.nan_to_num(rows[np.argmax(np.sum(~np.isnan(rows), axis=1))])
            signs = np.sign(np.nansum(rows * ref, axis=1))
            signs[signs == 0] = 1.0
            out[k] = np.nanmean(rows * signs[:, None], axis=0)
        return out

    def referred_to(self, covariate: str, reference: float | None = None) -> ModalObservations:
        """Frequencies with a linear dependence on ``covariate`` removed, referred to ``reference``.

        Per mode, ``f = a + b (c - reference)`` is fitted by least squares over the windows where
        both are present and ``b (c - reference)`` is subtracted; windows without the covariate are
        dropped. Use before updating when e.g. temperature moves all frequencies together, so that
        the windows are closer to independent given theta (docs/updating.md). ``reference``
        defaults to the covariate's mean.
        """
        if covariate not in self.covariates:
            raise ValueError(f"no covariate column {covariate!r} (have: {sorted(self.covariates)})")
        c = np.asarray(self.covariates[covariate], dtype=float)
        keep = np.isfinite(c)
        if keep.sum() < 3:
            raise ValueError(f"covariate {covariate!r} is present in fewer than 3 windows")
        out = self.subset(np.flatnonzero(keep))
        c = c[keep]
        ref = float(np.mean(c)) if reference is None else float(reference)
        f = out.frequencies_hz.copy()
        slopes = []
        for k in range(out.n_modes):
            ok = np.isfinite(f[:, k])
            if ok.sum() < 3:
                slopes.append(0.0)
                continue
            b = np.polyfit(c[ok] - ref, f[ok, k], 1)[0]
            f[ok, k] -= b * (c[ok] - ref)
            slopes.append(float(b))
        out.frequencies_hz = f
        out.notes = list(out.notes) + [
            f"frequencies referred to {covariate} = {ref:.3g} (slopes per mode: "
            + ", ".join(f"{s:.3g}" for s in slopes) + " Hz per unit)"]
        return out

