"""Truth model of a shear building: scattered floors under wind, microtremor and earthquakes.

Compared with the nominal file: scattered floor masses and story stiffnesses, stiffness-proportional
story dashpots plus a little mass-proportional damping (not the nominal Rayleigh ratios); hidden
effects may add a foundation on soil (sway) and damper braces (Kelvin-Voigt or Maxwell). The
response is exact for the linear model (complex modes of the state space) or by Newmark with Newton
iterations when story springs and dashpots depend on the amplitude
(:mod:`shm_ros.core.simulate.newmark`).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import shm_ros.core.simulate.excitation as ex
from shm_ros.core.modal import real_shape
from shm_ros.core.models import build_model
from shm_ros.core.models.damping import rayleigh_coefficients
from shm_ros.core.simulate.effects import Conditions, Effect, EffectError
from shm_ros.core.simulate.linear import ModalSystem, from_state_space
from shm_ros.core.simulate.newmark import simulate_building_nonlinear
from shm_ros.core.simulate.truth import FLAT_PRIOR, ModalTruth, TruthModel, TruthOptions, WindowRun
from shm_ros.core.simulate.truth_kinds import register
from shm_ros.core.structure import StructureSpec, structure_from_dict


@register("shear_building")
@dataclass
class BuildingTruth(TruthModel):
    supports_earthquakes = True
    effect_defaults = {
        "temperature_linear": {"where": "stories", "alpha_per_c": -0.003, "t_ref_c": 15.0},
        "temperature_bilinear": {"where": "stories", "alpha_per_c": -0.002, "t_ref_c": 15.0, "knee_c": 0.0,
                                 "below_per_c": -0.03},
        "damage": {"at": "48h", "factor": 0.85, "where": "story1"},
        "repair": {"at": "96h", "factor": 1.10, "where": "story1"},
        "added_mass": {"fraction": 0.08, "when": "always"},
        "support_flexibility": {"k_soil_rel": 3.0, "mass_rel": 0.15, "soil_damping_ratio": 0.10},
        "amplitude_stiffness": {"drift_ref_m": 0.01},
        "amplitude_damping": {"velocity_ref_m_s": 0.02},
        "damper": {"model": "kelvin_voigt", "k_rel": 0.30, "c_rel_s": 0.02, "stories": "all",
                   "fail_at": None, "fail_factor": 0.0},
    }
    effect_forms = {
        "support_flexibility": "foundation sway: soil spring and dashpot under a foundation mass",
        "amplitude_stiffness": "softening story springs f = k d / (1 + |d| / d_ref)",
        "amplitude_damping": "story dashpots f = c v (1 + |v| / v_ref)",
    }
    effect_where = {"support_flexibility": "foundation", "added_mass": "floors", "*": "stories"}

    rayleigh: tuple[float, float] = (0.0, 0.0)  # C = a0 M + a1 K_story
    dampers: dict[str, Any] = field(default_factory=dict)
    soil: dict[str, float] = field(default_factory=dict)

    @classmethod
    def build(cls, nominal: StructureSpec, structure: dict[str, Any], effects: list[Effect],
              rng: np.random.Generator, options: TruthOptions) -> BuildingTruth:
        scatter, damping_range, n_truth = options.scatter, options.damping_range, options.n_truth_modes
        d = copy.deepcopy(structure)
        floors = d["shear_building"]["floors"]
        for f in floors:
            f["mass"] = float(f["mass"]) * float(1 + scatter * rng.standard_normal())
            f["stiffness"] = float(f["stiffness"]) * float(1 + 1.5 * scatter * rng.standard_normal())
        soil = next((e for e in effects if e.key == "support_flexibility"), None)
        shift = 0
        soil_info: dict[str, float] = {}
        if soil is not None:
            total = sum(f["mass"] for f in floors)
            found = {"mass": soil.params["mass_rel"] * total,
                     "stiffness": soil.params["k_soil_rel"] * floors[0]["stiffness"]}
            floors.insert(0, found)
            shift = 1
            soil_info = dict(found)
        sensor_ids = [s["id"] for s in d["sensors"]]
        sensor_dof: dict[str, int | None] = {}
        for s in d["sensors"]:
            fl = int(s["at"]["floor"])
            # with a foundation, the ground sensor sits on the foundation slab (truth floor 1)
            sensor_dof[s["id"]] = (fl - 1 + shift) if (fl + shift) >= 1 else None
            s["at"] = {"floor": fl + shift}
        d["parameters"] = (
            [{"name": f"story{i + 1}", "applies_to": f"shear_building.floors[{i}].stiffness", "prior": FLAT_PRIOR}
             for i in range(len(floors))]
            + [{"name": f"floor{i + 1}_mass", "applies_to": f"shear_building.floors[{i}].mass", "prior": FLAT_PRIOR}
               for i in range(len(floors))]
        )
        d.pop("input", None)
        spec = structure_from_dict(d, source="<truth>")
        model = build_model(spec, direction="x")
        n = model.n_dof
        names = model.parameter_names
        groups: dict[str, list[int]] = {"EI": [names.index(f"story{i + 1 + shift}") for i in range(n - shift)],
                                        "mass": [names.index(f"floor{i + 1 + shift}_mass") for i in range(n - shift)]}
        # story k of effects = story k of the nominal file = truth story k + shift (a foundation, if any,
        # is truth story 1 and never scaled by an effect)
        for i in range(n - shift):
            groups[f"EI:{i + 1}"] = [names.index(f"story{i + 1 + shift}")]
        k_story = np.array([f["stiffness"] for f in floors])
        # truth damping: C = a0 M + a1 K_story, ratios damping_range at modes 1 and 3
        w = 2 * np.pi * model.modes(n_modes=3).frequencies_hz
        z1, z3 = damping_range
        a0, a1 = rayleigh_coefficients(w[0], w[2], z1, z3)
        a0, a1 = max(a0, 0.0), max(a1, 0.0)
        dampers: dict[str, Any] = {}
        dmp = next((e for e in effects if e.key == "damper"), None)
        if dmp is not None:
            p = dmp.params
            sel = np.zeros(n, bool)
            stories = p["stories"]
            if stories == "all":
                sel[shift:] = True
            else:
                for s in (stories if isinstance(stories, list) else [int(v) for v in str(stories).split("+")]):
                    sel[int(s) - 1 + shift] = True
            if p["model"] not in ("kelvin_voigt", "maxwell"):
                raise EffectError(f"effect damper: model={p['model']!r} (kelvin_voigt or maxwell)")
            kd = np.where(sel, float(p["k_rel"]) * k_story, 0.0)
            dampers = {"model": p["model"], "k_d": kd, "c_d": np.where(sel, float(p["c_rel_s"]) * kd, 0.0)}
        if soil is not None:
            # soil dashpot: damping ratio of the foundation on its spring alone
            c_s = 2 * soil.params["soil_damping_ratio"] * np.sqrt(soil_info["stiffness"] * soil_info["mass"])
            soil_info["dashpot"] = float(c_s)
        info = {"n_truth_modes": n_truth, "k_story": k_story, "sensor_dof": sensor_dof, "shift": shift,
                "story_params": np.array([names.index(f"story{i + 1}") for i in range(n)])}
        return cls(nominal=nominal, spec=spec, model=model, groups=groups, sensor_ids=sensor_ids,
                   input_names=["ground"] + [f"wind@floor{i + 1}" for i in range(n)],
                   rayleigh=(float(a0), float(a1)), dampers=dampers, soil=soil_info, info=info)

    # -- one window ---------------------------------------------------------------------------
    def system(self, factors: dict[str, float], k_scale: np.ndarray | None = None,
               c_scale: np.ndarray | None = None, damping_scale: float = 1.0) -> tuple[ModalSystem, ModalTruth]:
        """State-space system; ``k_scale``/``c_scale`` per story (equivalent-linear amplitude effects)."""
        theta = self.theta(factors)
        mats = self.building_matrices(theta, factors, k_scale, c_scale)
        sys = self._state_space(mats)
        osc = np.nonzero(sys.conjugate)[0]
        order = osc[np.argsort(sys.frequencies_hz()[osc])][: self.info["n_truth_modes"]]
        shapes = (np.column_stack([real_shape(sys.shapes[:, j]) for j in order]) if order.size
                  else np.zeros((len(self.sensor_ids), 0)))
        return sys, ModalTruth(sys.frequencies_hz()[order], sys.damping_ratios()[order], shapes,
                               list(self.sensor_ids))

    def loads(self, rng: np.random.Generator, n: int, cond: Conditions, scenario: Any, system: ModalSystem | None,
              event: dict[str, float] | None) -> tuple[np.ndarray, dict | None]:
        """(n, 1 + n_dof): ground acceleration (microtremor, earthquake), then wind on every floor."""
        sc = scenario
        fs = sc.fs
        n_dof = self.model.n_dof
        shift = self.info["shift"]
        u = np.zeros((n, 1 + n_dof))
        u[:, 0] = ex.microtremor(rng, n, fs, sc.microtremor_rms_m_s2 * float(rng.lognormal(0.0, 0.3)))
        heights = np.arange(1, n_dof - shift + 1) / (n_dof - shift)
        wind = sc.wind_rms_n * float(rng.lognormal(0.0, 0.4))
        u[:, 1 + shift:] = ex.wind_loads(rng, n, fs, n_dof - shift, wind) * heights ** 0.3
        if event is not None:
            n_warm = n - int(round(sc.window_s * fs))
            u[:, 0] += ex.earthquake(rng, n, fs, n_warm / fs + event["onset_s"], event["pga_m_s2"])
            event = dict(event)
        return u, event

    def respond(self, run: WindowRun) -> tuple[np.ndarray, ModalTruth, dict[str, Any]]:
        if not run.amplitude_effects:
            return run.system.simulate(run.inputs, run.dt), run.modal, {}
        y, eq = simulate_building_nonlinear(self, run.factors, run.amplitude_effects, run.inputs, run.dt,
                                            run.n_warm)
        _, modal = self.system(run.factors, k_scale=eq["k_scale"], c_scale=eq["c_scale"])
        extra = {"equivalent_linear": {"story_drift_rms_m": eq["drift_rms"].tolist(),
                                       "story_velocity_rms_m_s": eq["velocity_rms"].tolist(),
                                       "stiffness_factor": eq["k_scale"].tolist(),
                                       "damping_factor": eq["c_scale"].tolist()}}
        return y, modal, extra

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {"rayleigh_a0_a1": list(self.rayleigh)}
        if self.dampers:
            out["dampers"] = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.dampers.items()}
        if self.soil:
            out["foundation"] = self.soil
        return out

    # -- matrices -----------------------------------------------------------------------------
    def story_vectors(self) -> np.ndarray:
        """(n_stories, n_dof): drift of story i = e_i . u (floor i minus floor i-1)."""
        n = self.model.n_dof
        E = np.zeros((n, n))
        for i in range(n):
            E[i, i] = 1.0
            if i > 0:
                E[i, i - 1] = -1.0
        return E

    def building_matrices(self, theta: np.ndarray, factors: dict[str, float],
                          k_scale: np.ndarray | None = None,
                          c_scale: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """M, K, C (linear parts) and damper data of one window; ``k_scale``/``c_scale`` are per-story
        equivalent-linear factors of amplitude-dependent springs/dashpots."""
        m = self.model
        E = self.story_vectors()
        k_story = self.info["k_story"] * theta[self.info["story_params"]]
        if k_scale is not None:
            k_story = k_story * k_scale
        K = E.T @ (k_story[:, None] * E)
        M = m.mass(theta)
        a0, a1 = self.rayleigh
        c_story = a1 * self.info["k_story"] * (c_scale if c_scale is not None else 1.0)
        C = a0 * M + E.T @ (c_story[:, None] * E)
        if self.soil:
            C[0, 0] += self.soil["dashpot"]  # radiation damping of the soil under the foundation
        out = {"M": M, "K": K, "C": C, "E": E, "k_story": k_story, "c_story": c_story}
        if self.dampers:
            fac = factors.get("damper", 1.0)
            kd = self.dampers["k_d"] * fac
            cd = self.dampers["c_d"] * fac
            out["kd"], out["cd"] = kd, cd
            if self.dampers["model"] == "kelvin_voigt":
                out["K"] = K + E.T @ (kd[:, None] * E)
                out["C"] = out["C"] + E.T @ (cd[:, None] * E)
        return out

    def _state_space(self, mats: dict[str, np.ndarray]) -> ModalSystem:
        M, K, C, E = mats["M"], mats["K"], mats["C"], mats["E"]
        n = M.shape[0]
        Minv = np.linalg.inv(M)
        r = np.ones(n)
        maxwell = bool(self.dampers) and self.dampers["model"] == "maxwell"
        act = np.nonzero(mats.get("kd", np.zeros(0)) > 0)[0] if maxwell else np.zeros(0, int)
        nd = act.size
        ns = 2 * n + nd
        A = np.zeros((ns, ns))
        A[:n, n:2 * n] = np.eye(n)
        A[n:2 * n, :n] = -Minv @ K
        A[n:2 * n, n:2 * n] = -Minv @ C
        if nd:
            Ed = E[act]  # (nd, n)
            A[n:2 * n, 2 * n:] = -Minv @ Ed.T
            kd, cd = mats["kd"][act], mats["cd"][act]
            A[2 * n:, n:2 * n] = kd[:, None] * Ed
            A[2 * n:, 2 * n:] = -np.diag(kd / cd)
        # inputs: base acceleration, then one wind force per floor
        B = np.zeros((ns, 1 + n))
        B[n:2 * n, 0] = -r
        B[n:2 * n, 1:] = Minv
        Sel = self.sensor_selection(n)
        Cacc = Sel @ A[n:2 * n, :]
        D = Sel @ B[n:2 * n, :]
        D[:, 0] += 1.0  # absolute acceleration = relative + ground
        Cdisp = np.zeros((Sel.shape[0], ns))
        Cdisp[:, :n] = Sel
        return from_state_space(A, B, Cacc, D, Cdisp=Cdisp)

    def sensor_selection(self, n: int) -> np.ndarray:
        Sel = np.zeros((len(self.sensor_ids), n))
        for r, sid in enumerate(self.sensor_ids):
            dof = self.info["sensor_dof"][sid]
            if dof is not None:
                Sel[r, dof] = 1.0
        return Sel
