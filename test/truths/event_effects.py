"""The physics an event campaign carries, one small class per effect (all share :class:`EventEffect`).

An effect sees the campaign (building, event times and PGAs, a linear calibration run of the
strongest event) in ``prepare`` and then gives the state of the building for each event. Magnitudes
are drawn from ranges chosen so that the in-vocabulary effects move the first frequency by at least
three times the event-to-event nuisance scatter (0.3 % stiffness, see ``event_campaign.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .building import Building
from .story_state import Soil, Spring, StoryState
from .transient import EventResponse, Softening


@dataclass
class Context:
    building: Building
    times_s: np.ndarray            # event times, s after the campaign start
    pga: np.ndarray                # m/s^2, x component
    strong: int                    # index of the strongest event
    linear_strong: EventResponse   # linear response of the clean building to the strongest event
    rng: np.random.Generator


@dataclass
class EventEffect:
    """No effect: the clean campaign (only nuisance). Subclasses override what they change."""

    name: str = "clean"
    expected: str = "none"
    acceptable: tuple[str, ...] = ()
    magnitudes: dict = field(default_factory=dict)
    change_event: int | None = None      # first event that shows a change at a moment
    wants_strong_in_middle: bool = False

    def prepare(self, ctx: Context) -> None:
        self.n = ctx.building.n

    def state(self, i: int) -> StoryState:
        return StoryState.clean(self.n)

    def softening(self, i: int, ctx: Context, k_start: np.ndarray) -> Softening | None:
        return None

    def designed(self) -> tuple[np.ndarray, np.ndarray]:
        """Devices the engineer's nominal model includes: added story stiffness and dashpots (n,)."""
        return np.zeros(self.n), np.zeros(self.n)

    def after_event(self, i: int, response: EventResponse) -> None:
        """Hook for effects with memory (what the event did to the building)."""

    def truth(self) -> dict:
        out = {"name": self.name, "magnitudes": self.magnitudes}
        if self.change_event is not None:
            out["change_event"] = self.change_event
        return out


class StiffnessLoss(EventEffect):
    """Damage in the strongest event: 15-30 % of the stiffness of one or two low stories is lost."""

    def __init__(self) -> None:
        super().__init__(name="stiffness_loss", expected="stiffness_change_at_time", wants_strong_in_middle=True)

    def prepare(self, ctx: Context) -> None:
        super().prepare(ctx)
        n = ctx.building.n
        self.stories = sorted(ctx.rng.choice(np.arange(min(n, 2)), size=int(ctx.rng.integers(1, min(n, 2) + 1)),
                                             replace=False).tolist())
        self.loss = float(ctx.rng.uniform(0.15, 0.30))
        self.change_event = ctx.strong + 1
        self.magnitudes = {"stories": self.stories, "stiffness_loss": self.loss, "damage_event": ctx.strong}

    def state(self, i: int) -> StoryState:
        s = StoryState.clean(self.n)
        if self.change_event is not None and i >= self.change_event:
            s.k_factor[self.stories] *= 1.0 - self.loss
        return s


class Hysteretic(EventEffect):
    """Steel02 story springs: yield at a third to a fifth of the strongest event's linear drift, so weak
    events stay elastic and strong ones soften
    unloading is at the initial stiffness (no lasting loss)."""

    def __init__(self) -> None:
        super().__init__(name="hysteretic", expected="amplitude_dependent_stiffness",
                         acceptable=("amplitude_dependent_damping",))

    def prepare(self, ctx: Context) -> None:
        super().prepare(ctx)
        self.ratio = float(ctx.rng.uniform(3.0, 5.0))
        self.share = float(ctx.rng.uniform(0.5, 0.7))
        self.yield_drift = ctx.linear_strong.peak_drift / self.ratio
        self.magnitudes = {"yield_drift_m": self.yield_drift.tolist(), "hysteretic_share": self.share,
                           "strong_linear_drift_over_yield": self.ratio}

    def state(self, i: int) -> StoryState:
        return StoryState(k_factor=np.ones(self.n), spring=Spring.STEEL02, yield_drift=self.yield_drift,
                          nonlinear_share=self.share, nonlinear_stories=list(range(self.n)))


class AmplitudeDamping(EventEffect):
    """Orifice (quadratic viscous) dampers in every story, F = c v|v|: equivalent damping grows in
    proportion to the velocity amplitude; 3-6 % added to mode 1 at half the strongest event's peak."""

    def __init__(self) -> None:
        super().__init__(name="amplitude_damping", expected="amplitude_dependent_damping")

    def prepare(self, ctx: Context) -> None:
        super().prepare(ctx)
        b = ctx.building
        self.added = float(ctx.rng.uniform(0.03, 0.06))
        w1 = 2 * np.pi * ctx.linear_strong.f0_hz[0]
        v_ref = 0.5 * np.maximum(ctx.linear_strong.peak_drift_vel, 1e-6)
        c_eq = 2 * self.added * b.k_x / w1                       # stiffness-proportional equivalent
        self.quad_c = c_eq / (8.0 / (3.0 * np.pi) * v_ref)       # equal energy per cycle at v_ref
        self.magnitudes = {"added_damping_at_reference": self.added, "reference_velocity_m_s": v_ref.tolist(),
                           "quadratic_c": self.quad_c.tolist()}

    def state(self, i: int) -> StoryState:
        return StoryState(k_factor=np.ones(self.n), quad_c=self.quad_c)


class SoilFoundation(EventEffect):
    """The building stands on footings on softening soil springs (sway in x and y, Hysteretic backbone);
    the ground sensor is on the free field. The flexibility is sized from the sway-rocking estimate
    1/w^2 = 1/w_fix^2 + 1/w_sway^2 + 1/w_rock^2 for an 8-20 % drop of the first frequency, with the
    rocking share carried by the sway springs (no rocking DOF, see README)
    it softens further when
    strong (knee at a half to a quarter of the strongest event's base shear)."""

    def __init__(self) -> None:
        super().__init__(name="soil", expected="support_flexibility", acceptable=("amplitude_dependent_stiffness",))

    def prepare(self, ctx: Context) -> None:
        super().prepare(ctx)
        b = ctx.building
        drop = float(ctx.rng.uniform(0.08, 0.20))
        w = 2 * np.pi * ctx.linear_strong.f0_hz[0]
        extra = 1.0 / (1.0 - drop) ** 2 - 1.0                   # 1/w_ssi^2 = (1 + extra) / w_fix^2
        m_f = float(b.masses[0] * ctx.rng.uniform(0.5, 1.0))
        k_sway = (b.masses.sum() + m_f) * w**2 / extra
        v_base = float(b.k_x[0] * ctx.linear_strong.peak_drift[0])
        knee = float(ctx.rng.uniform(2.0, 4.0))
        self.soil = Soil(mass=m_f, k_sway=k_sway, yield_sway=v_base / k_sway / knee)
        self.magnitudes = {"target_small_amplitude_drop": drop, "k_sway_N_m": k_sway,
                           "foundation_mass_kg": m_f, "strong_base_shear_over_knee": knee}

    def state(self, i: int) -> StoryState:
        return StoryState(k_factor=np.ones(self.n), soil=self.soil)


class DamperLoss(EventEffect):
    """Damper braces (a spring in parallel with a dashpot) in one or two stories are lost between two
    events (disconnected after a moderate event): stiffness and damping of those stories drop."""

    def __init__(self) -> None:
        super().__init__(name="damper_loss", expected="damper_stiffness",
                         acceptable=("stiffness_change_at_time",))

    def prepare(self, ctx: Context) -> None:
        super().prepare(ctx)
        b, rng = ctx.building, ctx.rng
        m = ctx.times_s.size
        count = min(b.n, int(rng.integers(1, 3)))
        self.stories = sorted(rng.choice(np.arange(b.n), size=count, replace=False).tolist())
        self.brace_k = np.zeros(b.n)
        self.brace_c = np.zeros(b.n)
        w1 = 2 * np.pi * ctx.linear_strong.f0_hz[0]
        ratio = float(rng.uniform(0.2, 0.35))
        self.brace_k[self.stories] = ratio * b.k_x[self.stories]
        self.brace_c[self.stories] = 2 * float(rng.uniform(0.03, 0.05)) * b.k_x[self.stories] / w1
        self.change_event = int(rng.integers(max(2, m // 3), max(3, m - 1)))
        self.magnitudes = {"stories": self.stories, "brace_stiffness_over_story": ratio,
                           "brace_k_N_m": self.brace_k.tolist(), "brace_c_N_s_m": self.brace_c.tolist()}

    def designed(self) -> tuple[np.ndarray, np.ndarray]:
        return self.brace_k.copy(), self.brace_c.copy()

    def state(self, i: int) -> StoryState:
        lost = self.change_event is not None and i >= self.change_event
        return StoryState(k_factor=np.ones(self.n), brace_k=None if lost else self.brace_k,
                          brace_c=None if lost else self.brace_c)


class BreathingCrack(EventEffect):
    """A crack in the lowest story closed by gravity pre-compression: it opens beyond a drift of a
    quarter to a half of the strongest event's, and the story is 40-70 % softer while it is open
    (bilinear elastic, asymmetric: positive drift only
    no hysteresis, no lasting change)."""

    def __init__(self) -> None:
        super().__init__(name="breathing_crack", expected="amplitude_dependent_stiffness")

    def prepare(self, ctx: Context) -> None:
        super().prepare(ctx)
        self.loss = float(ctx.rng.uniform(0.4, 0.7))
        self.opening = ctx.linear_strong.peak_drift * float(ctx.rng.uniform(0.1, 0.25))
        self.magnitudes = {"story": 0, "stiffness_loss_when_open": self.loss, "opening_drift_m": float(self.opening[0])}

    def state(self, i: int) -> StoryState:
        return StoryState(k_factor=np.ones(self.n), spring=Spring.CRACK, yield_drift=self.opening,
                          nonlinear_share=self.loss, nonlinear_stories=[0])


class TransientSoftening(EventEffect):
    """Stiffness drops during strong shaking in proportion to the peak drift reached (up to 8-15 % at
    the strongest event's) and recovers slowly afterwards, linearly in log time over 2-10 days (slow
    dynamics of cracked concrete and soil). Aftershocks hours after the strong event see the deficit."""

    def __init__(self) -> None:
        super().__init__(name="transient_softening", expected="amplitude_dependent_stiffness",
                         acceptable=("stiffness_change_at_time",), wants_strong_in_middle=True)

    def prepare(self, ctx: Context) -> None:
        super().prepare(ctx)
        self.drop = float(ctx.rng.uniform(0.08, 0.15))
        self.d_ref = np.maximum(ctx.linear_strong.peak_drift, 1e-9)
        self.t_full = float(ctx.rng.uniform(2.0, 10.0)) * 86400.0
        self.tau0 = 60.0
        self.times = ctx.times_s
        self.deficit, self.deficit_time = np.zeros(ctx.building.n), -np.inf
        self.magnitudes = {"max_drop": self.drop, "recovery_days": self.t_full / 86400.0,
                           "reference_drift_m": self.d_ref.tolist(), "deficit_after_event": []}

    def _residual(self, t: float) -> np.ndarray:
        tau = t - self.deficit_time
        if not np.isfinite(tau):
            return np.zeros_like(self.deficit)
        left = max(0.0, 1.0 - np.log1p(tau / self.tau0) / np.log1p(self.t_full / self.tau0))
        return self.deficit * left

    def state(self, i: int) -> StoryState:
        return StoryState(k_factor=1.0 - self._residual(float(self.times[i])))

    def softening(self, i: int, ctx: Context, k_start: np.ndarray) -> Softening:
        drop, d_ref = self.drop, self.d_ref

        def factor(t: float, peak: np.ndarray) -> np.ndarray:
            return np.minimum(k_start, 1.0 - drop * np.minimum(1.0, peak / d_ref))
        return factor

    def after_event(self, i: int, response: EventResponse) -> None:
        self.deficit = 1.0 - response.k_end
        self.deficit_time = float(self.times[i])
        self.magnitudes["deficit_after_event"].append(self.deficit.tolist())


EFFECTS: dict[str, type[EventEffect]] = {
    "event_stiffness_loss": StiffnessLoss, "event_hysteretic": Hysteretic,
    "event_amplitude_damping": AmplitudeDamping, "event_soil": SoilFoundation,
    "event_damper_loss": DamperLoss, "event_breathing_crack": BreathingCrack,
    "event_transient_softening": TransientSoftening, "event_clean": EventEffect,
}
