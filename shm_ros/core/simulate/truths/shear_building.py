"""Truth model of a shear building: scattered floors under wind, microtremor and earthquakes.

Compared with the nominal file: scattered floor masses and story stiffnesses, stiffness-proportional
story dashpots plus a little mass-proportional damping (not the nominal Rayleigh ratios); hidden
effects may add a foundation on soil (sway) and damper braces (Kelvin-Voigt or Maxwell).

With ``model_form`` (the default) the building is also what a planar shear model cannot be
(:class:`PlanForm`): every floor moves in x, y and twists (theta) about the stiffness centre, the
floor masses sit a few per cent of the plan off it (so x and y sway couple with torsion), the
sensors sit off the centre (an x sensor at plan offset y reads ``u_x - y theta``), the story dashpots
are not proportional to the story springs (dissipation in partitions and cladding is uneven over the
height: complex modes) and the ground also moves in y (unmeasured). Mode families: ``x``, ``y``,
``torsion`` (by the largest share of kinetic energy); the in-plane family is the nominal sensors'
direction.

The response is exact for the linear model (complex modes of the state space) or by Newmark with
Newton iterations when story springs and dashpots depend on the amplitude
(:mod:`shm_ros.core.simulate.newmark`, run in coordinates where a ground acceleration in x moves
every coordinate alike, :class:`_NewmarkView`).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import shm_ros.core.simulate.excitation as ex
from shm_ros.core.modal import real_shape
from shm_ros.core.models.base import AffineModel
from shm_ros.core.models.damping import rayleigh_coefficients
from shm_ros.core.simulate.effects import Conditions, Effect, EffectError
from shm_ros.core.simulate.linear import ModalSystem, from_state_space
from shm_ros.core.simulate.newmark import simulate_building_nonlinear
from shm_ros.core.simulate.truth import FLAT_PRIOR, ModalTruth, TruthModel, TruthOptions, WindowRun, report_modes
from shm_ros.core.simulate.truth_kinds import register
from shm_ros.core.structure import StructureSpec, structure_from_dict

COMPONENTS = ("x", "y", "torsion")
HISTORIES = "response_histories"  # key of respond()'s extra with ``keep_histories``


@dataclass(frozen=True)
class PlanForm:
    """Magnitudes of a regular office building 30 m x 20 m in plan with frames in both directions."""

    plan_m: tuple[float, float] = (30.0, 20.0)  # along x, along y
    ky_ratio: float = 0.85  # y story stiffness / x story stiffness (fewer, shorter frames across)
    torsion_share: float = 0.5  # k_theta = share (k_x (Ly/2)^2 + k_y (Lx/2)^2): frames spread over the plan
    # |mass centre offset| / plan dimension, drawn in this range per direction: a regular plan's uneven
    # live load, partitions and cladding (below the 5 % accidental eccentricity codes add as an envelope)
    eccentricity: tuple[float, float] = (0.01, 0.02)
    sensor_xy_m: tuple[float, float] = (8.0, 6.0)  # sensors on a stair core, off the stiffness centre
    damping_spread: float = 0.5  # lognormal sigma of the story dashpots around the stiffness-proportional law
    wind_y_ratio: float = 1.5  # wind on the long face
    wind_arm: float = 0.08  # wind resultant off the stiffness centre, fraction of the face width
    story_height_m: float = 3.5
    flexure_alpha: float = 40.0  # H sqrt(GA / EI): a moment frame whose columns stretch a little (bends)

    @property
    def radius2(self) -> float:
        lx, ly = self.plan_m
        return (lx * lx + ly * ly) / 12.0


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

    rayleigh: tuple[float, float] = (0.0, 0.0)  # C = a0 M + a1 K_story (times the story weights)
    dampers: dict[str, Any] = field(default_factory=dict)
    soil: dict[str, float] = field(default_factory=dict)
    form: PlanForm | None = None  # None: a planar shear building (model_form off)
    # respond() also returns the story drift / drift-velocity histories (large arrays, kept out of
    # truth.json; ``equivalent_linear.simulate_event`` sets it on its own copy of the truth)
    keep_histories: bool = False

    @property
    def dpf(self) -> int:
        """DOFs per floor: x, y, theta (model form) or x."""
        return 1 if self.form is None else 3

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
        sensor_floor: dict[str, int | None] = {}
        for s in d["sensors"]:
            fl = int(s["at"]["floor"])
            # with a foundation, the ground sensor sits on the foundation slab (truth floor 1)
            sensor_floor[s["id"]] = (fl - 1 + shift) if (fl + shift) >= 1 else None
            s["at"] = {"floor": fl + shift}
        d["parameters"] = (
            [{"name": f"story{i + 1}", "applies_to": f"shear_building.floors[{i}].stiffness", "prior": FLAT_PRIOR}
             for i in range(len(floors))]
            + [{"name": f"floor{i + 1}_mass", "applies_to": f"shear_building.floors[{i}].mass", "prior": FLAT_PRIOR}
               for i in range(len(floors))]
        )
        d.pop("input", None)
        spec = structure_from_dict(d, source="<truth>")
        nf = len(floors)
        m_floor = np.array([f["mass"] for f in floors])
        kx = np.array([f["stiffness"] for f in floors])
        direction = "x" if any(s.direction == "x" for s in nominal.sensors) or not nominal.sensors else "y"
        # the planar x model (this file's floors, Rayleigh law fitted on its modes 1 and 3)
        E1 = _story_vectors(nf, 1)
        w2 = np.sort(np.linalg.eigvals(np.linalg.solve(np.diag(m_floor), E1.T @ (kx[:, None] * E1))).real)
        w = np.sqrt(w2[: min(3, nf)])
        z1, z3 = damping_range
        a0, a1 = rayleigh_coefficients(w[0], w[min(2, nf - 1)], z1, z3)
        a0, a1 = max(a0, 0.0), max(a1, 0.0)

        form = None
        if options.model_form:
            form = PlanForm() if options.eccentricity is None else PlanForm(eccentricity=options.eccentricity)
        dpf = 1 if form is None else 3
        weights = np.ones(nf)
        ecc = np.zeros((nf, 2))
        k_rows = kx.copy()
        sensor_xy = np.zeros((len(sensor_ids), 2))
        if form is not None:
            lx, ly = form.plan_m
            signs = rng.choice([-1.0, 1.0], size=2)
            e = signs * rng.uniform(*form.eccentricity, size=2) * np.array([lx, ly])
            ecc = e[None, :] * (1.0 + 0.2 * rng.standard_normal((nf, 2)))
            ky = kx * form.ky_ratio * (1.0 + 1.5 * scatter * rng.standard_normal(nf))
            kt = form.torsion_share * (kx * (ly / 2) ** 2 + ky * (lx / 2) ** 2)
            weights = np.exp(form.damping_spread * rng.standard_normal(nf))
            weights /= weights.mean()
            if shift:  # the foundation: soil springs alike in x and y, rocking about the vertical axis
                ky[0], kt[0], ecc[0] = kx[0], kx[0] * form.radius2, 0.0
                weights[0] = 1.0
            k_rows = np.column_stack([kx, ky, kt]).ravel()
            sensor_xy[:] = form.sensor_xy_m
            sensor_xy += 0.3 * rng.standard_normal(sensor_xy.shape)
            # a base sensor (floor 0) sits near the foundation's centre, as base instruments usually do
            on_base = np.array([int(s["at"]["floor"]) == shift for s in d["sensors"]], bool)
            sensor_xy[on_base] -= np.asarray(form.sensor_xy_m)
        n = dpf * nf
        E = _story_vectors(nf, dpf)
        K_terms: list[np.ndarray | None] = []
        M_terms: list[np.ndarray | None] = []
        for i in range(nf):
            rows = slice(dpf * i, dpf * (i + 1))
            ki = np.zeros(n)
            ki[rows] = k_rows[rows]
            K_terms.append(E.T @ (ki[:, None] * E))
        for i in range(nf):
            Mi = np.zeros((n, n))
            Mi[dpf * i:dpf * (i + 1), dpf * i:dpf * (i + 1)] = _floor_mass(m_floor[i], ecc[i], form)
            M_terms.append(Mi)
        names = [p["name"] for p in d["parameters"]]
        K_terms += [None] * nf
        M_terms[:0] = [None] * nf
        if form is not None:  # a flexural cantilever beside the shear frame (one factor: the EI group)
            names.append("flexure")
            K_terms.append(_flexure(kx[shift:], form, nf, shift))
            M_terms.append(None)
        comp = COMPONENTS[:dpf] if form is not None else (direction,)
        model = AffineModel(name=spec.name, parameter_names=names, K0=np.zeros((n, n)), M0=np.zeros((n, n)),
                            K_terms=K_terms, M_terms=M_terms,
                            dof_labels=[f"floor{i + 1}.{c}" for i in range(nf) for c in comp],
                            kind="shear_building", direction=direction)
        groups: dict[str, list[int]] = {"EI": [names.index(f"story{i + 1 + shift}") for i in range(nf - shift)],
                                        "mass": [names.index(f"floor{i + 1 + shift}_mass") for i in range(nf - shift)]}
        # story k of effects = story k of the nominal file = truth story k + shift (a foundation, if any,
        # is truth story 1 and never scaled by an effect)
        for i in range(nf - shift):
            groups[f"EI:{i + 1}"] = [names.index(f"story{i + 1 + shift}")]
        if form is not None:
            groups["EI"].append(names.index("flexure"))
        dampers: dict[str, Any] = {}
        dmp = next((e for e in effects if e.key == "damper"), None)
        if dmp is not None:
            p = dmp.params
            sel = np.zeros(nf, bool)
            stories = p["stories"]
            if stories == "all":
                sel[shift:] = True
            else:
                for s in (stories if isinstance(stories, list) else [int(v) for v in str(stories).split("+")]):
                    sel[int(s) - 1 + shift] = True
            if p["model"] not in ("kelvin_voigt", "maxwell"):
                raise EffectError(f"effect damper: model={p['model']!r} (kelvin_voigt or maxwell)")
            # braces in both directions, laid out like the frames (same share of every row's stiffness)
            kd = np.where(np.repeat(sel, dpf), float(p["k_rel"]) * k_rows, 0.0)
            cd = np.where(np.repeat(sel, dpf), float(p["c_rel_s"]) * kd, 0.0)
            dampers = {"model": p["model"], "k_d": kd, "c_d": cd}
        if soil is not None:
            # soil dashpot: damping ratio of the foundation on its spring alone
            c_s = 2 * soil.params["soil_damping_ratio"] * np.sqrt(soil_info["stiffness"] * soil_info["mass"])
            soil_info["dashpot"] = float(c_s)
        in_plane = "x" if form is None else direction
        info = {"n_truth_modes": n_truth, "k_story": k_rows, "sensor_floor": sensor_floor, "shift": dpf * shift,
                "floor_shift": shift, "story_params": np.repeat([names.index(f"story{i + 1}") for i in range(nf)], dpf),
                "story_weights": np.repeat(weights, dpf), "eccentricity_m": ecc, "sensor_xy_m": sensor_xy,
                "sensor_axis": [s.direction if s.direction in ("x", "y") else "x" for s in nominal.sensors]}
        n_in_names = ["ground", "ground_y"] + [f"{c}@floor{i + 1}" for i in range(nf) for c in
                                               (("wind_x", "wind_y", "torque") if form else ("wind",))]
        return cls(nominal=nominal, spec=spec, model=model, groups=groups, sensor_ids=sensor_ids,
                   input_names=n_in_names, rayleigh=(float(a0), float(a1)), dampers=dampers, soil=soil_info,
                   info=info, in_plane_family=in_plane, form=form)

    # -- one window ---------------------------------------------------------------------------
    def system(self, factors: dict[str, float], k_scale: np.ndarray | None = None,
               c_scale: np.ndarray | None = None, damping_scale: float = 1.0) -> tuple[ModalSystem, ModalTruth]:
        """State-space system; ``k_scale``/``c_scale`` per story row (equivalent-linear amplitude
        effects). Inputs: ground x, ground y, then the force on every DOF; outputs: x, y, z
        acceleration at every sensor."""
        theta = self.theta(factors)
        mats = self.building_matrices(theta, factors, k_scale, c_scale)
        sys, dof_shapes = self._state_space(mats)
        osc = np.nonzero(sys.conjugate)[0]
        osc = osc[np.argsort(sys.frequencies_hz()[osc])]
        fams = [self._family(dof_shapes[:, j], mats["M"]) for j in osc]
        pick = osc[report_modes(sys.frequencies_hz()[osc], fams, self.in_plane_family, self.info["n_truth_modes"])]
        fam_of = dict(zip(osc.tolist(), fams, strict=True))
        rows = self.signal_rows()
        shapes = (np.column_stack([real_shape(sys.shapes[rows, j]) for j in pick]) if pick.size
                  else np.zeros((len(self.sensor_ids), 0)))
        return sys, ModalTruth(sys.frequencies_hz()[pick], sys.damping_ratios()[pick], shapes,
                               list(self.sensor_ids), [fam_of[int(j)] for j in pick], self.in_plane_family)

    def signal_rows(self) -> np.ndarray:
        """Output row of each sensor's measured direction."""
        return np.array([3 * c + (1 if a == "y" else 0) for c, a in enumerate(self.info["sensor_axis"])], dtype=int)

    def _family(self, v: np.ndarray, M: np.ndarray) -> str:
        if self.form is None:
            return self.in_plane_family
        e = np.abs(v) ** 2 * np.diag(M)  # kinetic energy share of each DOF (the coupling terms aside)
        return COMPONENTS[int(np.argmax([e[c::3].sum() for c in range(3)]))]

    def loads(self, rng: np.random.Generator, n: int, cond: Conditions, scenario: Any, system: ModalSystem | None,
              event: dict[str, float] | None) -> tuple[np.ndarray, dict | None]:
        """(n, 2 + n_dof): ground acceleration in x (microtremor, earthquake) and y (microtremor,
        model form only), then wind on every DOF above the foundation (x, y and torque per floor)."""
        sc = scenario
        fs = sc.fs
        dpf = self.dpf
        n_dof = self.model.n_dof
        shift = self.info["floor_shift"]
        nf = n_dof // dpf
        u = np.zeros((n, 2 + n_dof))
        u[:, 0] = ex.microtremor(rng, n, fs, sc.microtremor_rms_m_s2 * float(rng.lognormal(0.0, 0.3)))
        heights = np.arange(1, nf - shift + 1) / (nf - shift)
        wind = sc.wind_rms_n * float(rng.lognormal(0.0, 0.4))
        nw = nf - shift
        if self.form is None:
            fx = ex.wind_loads(rng, n, fs, nw, wind) * heights ** 0.3
        else:  # one gust field loads both faces (wind across a diagonal), the long one more
            h = np.diag(heights ** 0.3)
            fxy = ex.wind_loads(rng, n, fs, nw, wind, projection=np.hstack([h, self.form.wind_y_ratio * h]))
            fx, fy = fxy[:, :nw], fxy[:, nw:]
        u[:, 2 + dpf * shift::dpf] = fx
        if event is not None:
            n_warm = n - int(round(sc.window_s * fs))
            u[:, 0] += ex.earthquake(rng, n, fs, n_warm / fs + event["onset_s"], event["pga_m_s2"])
            event = dict(event)
        if self.form is not None:
            lx, ly = self.form.plan_m
            u[:, 1] = ex.microtremor(rng, n, fs, sc.microtremor_rms_m_s2 * float(rng.lognormal(0.0, 0.3)))
            u[:, 3 + 3 * shift::3] = fy
            u[:, 4 + 3 * shift::3] = self.form.wind_arm * (lx * fy - ly * fx)
        return u, event

    def respond(self, run: WindowRun) -> tuple[np.ndarray, ModalTruth, dict[str, Any]]:
        if not run.amplitude_effects:
            return run.system.simulate(run.inputs, run.dt), run.modal, {}
        y, eq = self.nonlinear_response(run.factors, run.amplitude_effects, run.inputs, run.dt, run.n_warm)
        _, modal = self.system(run.factors, k_scale=eq["k_scale"], c_scale=eq["c_scale"])
        extra = {"equivalent_linear": {"story_drift_rms_m": eq["drift_rms"].tolist(),
                                       "story_velocity_rms_m_s": eq["velocity_rms"].tolist(),
                                       "stiffness_factor": eq["k_scale"].tolist(),
                                       "damping_factor": eq["c_scale"].tolist()}}
        if self.keep_histories:
            extra[HISTORIES] = {k: eq[k] for k in ("story_drift", "story_velocity", "stiffness_nonlinear",
                                                   "damping_nonlinear", "drift_ref_m", "velocity_ref_m_s")}
        return y, modal, extra

    def nonlinear_response(self, factors: dict[str, float], effects: list[Effect], u: np.ndarray, dt: float,
                           n_warm: int) -> tuple[np.ndarray, dict[str, Any]]:
        """Outputs (n, 3 n_sensors) for inputs ``u`` (:meth:`loads`) with amplitude-dependent story
        springs and dashpots (:func:`simulate_building_nonlinear`), and its equivalent-linear factors."""
        view = _NewmarkView(self, factors)
        y, eq = simulate_building_nonlinear(view, factors, effects, view.inputs(u), dt, n_warm)
        return view.outputs(y, u), eq

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {"rayleigh_a0_a1": list(self.rayleigh), "in_plane_family": self.in_plane_family}
        if self.dampers:
            out["dampers"] = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.dampers.items()}
        if self.soil:
            out["foundation"] = self.soil
        if self.form is not None:
            out["model_form"] = {
                "plan": {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(self.form).items()},
                "dofs_per_floor": ["x", "y", "theta"],
                "mass_eccentricity_m": np.round(self.info["eccentricity_m"], 4).tolist(),
                "sensor_plan_xy_m": {s: [float(v) for v in xy] for s, xy in
                                     zip(self.sensor_ids, self.info["sensor_xy_m"], strict=True)},
                "story_dashpot_weights": [float(v) for v in self.info["story_weights"][::3]],
            }
        return out

    # -- matrices -----------------------------------------------------------------------------
    def story_vectors(self) -> np.ndarray:
        """(n_dof, n_dof): row j is the drift of DOF j's story (that DOF minus the same DOF below)."""
        return _story_vectors(self.model.n_dof // self.dpf, self.dpf)

    def influence(self) -> tuple[np.ndarray, np.ndarray]:
        """DOFs moved by a unit ground displacement in x, and in y."""
        n = self.model.n_dof
        rx, ry = np.zeros(n), np.zeros(n)
        rx[0::self.dpf] = 1.0
        if self.dpf == 3:
            ry[1::3] = 1.0
        return rx, ry

    def building_matrices(self, theta: np.ndarray, factors: dict[str, float],
                          k_scale: np.ndarray | None = None,
                          c_scale: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """M, K, C (linear parts) and damper data of one window; ``k_scale``/``c_scale`` are per-row
        equivalent-linear factors of amplitude-dependent springs/dashpots."""
        m = self.model
        E = self.story_vectors()
        k_story = self.info["k_story"] * theta[self.info["story_params"]]
        if k_scale is not None:
            k_story = k_story * k_scale
        K = E.T @ (k_story[:, None] * E)
        if "flexure" in m.parameter_names:
            j = m.parameter_names.index("flexure")
            Kf = m.K_terms[j]
            assert Kf is not None  # set by build
            K = K + theta[j] * Kf
        M = m.mass(theta)
        a0, a1 = self.rayleigh
        c_story = a1 * self.info["k_story"] * self.info["story_weights"] * (c_scale if c_scale is not None else 1.0)
        C = a0 * M + E.T @ (c_story[:, None] * E)
        if self.soil:  # radiation damping of the soil under the foundation
            C[0, 0] += self.soil["dashpot"]
            if self.form is not None:
                C[1, 1] += self.soil["dashpot"]
                C[2, 2] += self.soil["dashpot"] * self.form.radius2
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

    def _state_space(self, mats: dict[str, np.ndarray]) -> tuple[ModalSystem, np.ndarray]:
        """The window's system and its modes' DOF shapes (n_dof, n_poles)."""
        M, K, C, E = mats["M"], mats["K"], mats["C"], mats["E"]
        n = M.shape[0]
        Minv = np.linalg.inv(M)
        rx, ry = self.influence()
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
        # inputs: base acceleration in x and y, then one force per DOF
        B = np.zeros((ns, 2 + n))
        B[n:2 * n, 0] = -rx
        B[n:2 * n, 1] = -ry
        B[n:2 * n, 2:] = Minv
        Sel = self.sensor_selection(n)
        Cacc = Sel @ A[n:2 * n, :]
        D = Sel @ B[n:2 * n, :]
        D[0::3, 0] += 1.0  # absolute acceleration = relative + ground
        D[1::3, 1] += 1.0
        no = Sel.shape[0]
        Cdisp = np.zeros((no + n, ns))
        Cdisp[:no, :n] = Sel
        Cdisp[no:, :n] = np.eye(n)
        sys = from_state_space(A, B, Cacc, D, Cdisp=Cdisp)
        dof_shapes = sys.shapes[no:]
        sys.shapes = sys.shapes[:no]
        return sys, dof_shapes

    def sensor_selection(self, n: int) -> np.ndarray:
        """(3 n_sensors, n_dof): relative x, y, z displacement at every sensor (an x sensor at plan
        offset (x_s, y_s) from the stiffness centre reads ``u_x - y_s theta``, a y sensor
        ``u_y + x_s theta``)."""
        Sel = np.zeros((3 * len(self.sensor_ids), n))
        dpf = self.dpf
        for r, sid in enumerate(self.sensor_ids):
            fl = self.info["sensor_floor"][sid]
            if fl is None:
                continue
            Sel[3 * r, dpf * fl] = 1.0
            if dpf == 3:
                xs, ys = self.info["sensor_xy_m"][r]
                Sel[3 * r, 3 * fl + 2] = -ys
                Sel[3 * r + 1, 3 * fl + 1] = 1.0
                Sel[3 * r + 1, 3 * fl + 2] = xs
        return Sel


def _story_vectors(n_floors: int, dpf: int) -> np.ndarray:
    n = n_floors * dpf
    E = np.eye(n)
    for j in range(dpf, n):
        E[j, j - dpf] = -1.0
    return E


def _flexure(k_story: np.ndarray, form: PlanForm, nf: int, shift: int) -> np.ndarray:
    """Condensed lateral stiffness (x and y DOFs) of a cantilever Euler-Bernoulli beam over the
    stories, clamped at the base (the foundation, if any), ``EI = k h H^2 / alpha^2`` (Miranda's
    coupled shear-flexural building with the mean story stiffness ``k``)."""
    from shm_ros.core.models.beam import beam_stiffness

    ns = k_story.size
    h = form.story_height_m
    H = ns * h
    out = np.zeros((3 * nf, 3 * nf))
    for comp, ratio in ((0, 1.0), (1, form.ky_ratio)):
        EI = ratio * float(np.mean(k_story)) * h * H * H / form.flexure_alpha ** 2
        Kb = np.zeros((2 * (ns + 1), 2 * (ns + 1)))  # (u, psi) per node, node 0 at the base
        for e in range(ns):
            Kb[2 * e:2 * e + 4, 2 * e:2 * e + 4] += beam_stiffness(EI, h)
        u = [2 * i for i in range(ns + 1)]
        psi = [2 * i + 1 for i in range(1, ns + 1)]  # the base is clamped: psi_0 = 0
        Kc = Kb[np.ix_(u, u)] - Kb[np.ix_(u, psi)] @ np.linalg.solve(Kb[np.ix_(psi, psi)], Kb[np.ix_(psi, u)])
        nodes = list(range(ns + 1)) if shift else list(range(1, ns + 1))  # without a foundation u_0 = 0
        dofs = [3 * (i - 1 + shift) + comp for i in nodes]
        out[np.ix_(dofs, dofs)] += Kc[np.ix_(nodes, nodes)]
    return out


def _floor_mass(m: float, ecc: np.ndarray, form: PlanForm | None) -> np.ndarray:
    """Mass block of a floor about the stiffness centre: mass centre at ``ecc`` = (e_x, e_y)."""
    if form is None:
        return np.array([[m]])
    ex_, ey = float(ecc[0]), float(ecc[1])
    J = m * (form.radius2 + ex_ * ex_ + ey * ey)
    return np.array([[m, 0.0, -m * ey], [0.0, m, m * ex_], [-m * ey, m * ex_, J]])


class _NewmarkView:
    """The building in coordinates ``p = T^-1 q`` where a ground acceleration in x enters every
    coordinate alike (the form :func:`simulate_building_nonlinear` integrates): ``q_y = p_y - p_x1``
    and ``q_theta = p_theta - p_x1``, so ``T 1 = r_x``. Drifts ``E q = (E T) p`` are the physical ones."""

    def __init__(self, tm: BuildingTruth, factors: dict[str, float]) -> None:
        self.tm = tm
        n = tm.model.n_dof
        rx, ry = tm.influence()
        self.T = np.eye(n)
        self.T[rx == 0, 0] -= 1.0
        self.info = tm.info
        self.ry = ry
        self.M_phys = tm.building_matrices(tm.theta(factors), factors)["M"]

    def theta(self, factors: dict[str, float]) -> np.ndarray:
        return self.tm.theta(factors)

    def building_matrices(self, theta: np.ndarray, factors: dict[str, float]) -> dict[str, np.ndarray]:
        T = self.T
        out = dict(self.tm.building_matrices(theta, factors))
        for k in ("M", "K", "C"):
            out[k] = T.T @ out[k] @ T
        out["E"] = out["E"] @ T
        return out

    def sensor_selection(self, n: int) -> np.ndarray:
        return self.tm.sensor_selection(n) @ self.T

    def inputs(self, u: np.ndarray) -> np.ndarray:
        """(n, 1 + n_dof): ground x, then forces in ``p`` (the ground y acceleration as forces)."""
        F = u[:, 2:] - np.outer(u[:, 1], self.M_phys @ self.ry)
        return np.column_stack([u[:, 0], F @ self.T])

    def outputs(self, y: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Newmark adds the ground x acceleration to every output: keep it on x rows only, and add
        the ground y acceleration to the y rows."""
        y = y.copy()
        y[:, 1::3] += u[:, 1:2] - u[:, :1]
        y[:, 2::3] -= u[:, :1]
        return y
