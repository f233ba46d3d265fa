"""The truth model: the structure as "reality" has it, built with the project's own model builders.

It differs from the nominal structure file the way a real structure differs from its design model:

* girder: ``refine`` x the elements per span, scattered E and density per span and bearing
  stiffness, a small rotational restraint at the bearings, sensors misplaced by a few cm to dm;
* building: scattered floor masses and story stiffnesses, stiffness-proportional story dashpots plus
  a little mass-proportional damping (not the nominal Rayleigh ratios);
* both: modal damping that is not what the file says;

plus the hidden effects the scenario switches on (:mod:`shm_ros.core.simulate.effects`). Every
per-window property change is a multiplicative factor on a parameter of the truth model's affine
form ``K = K0 + sum theta_i K_i`` (parameters the truth spec declares for itself, e.g. one per span).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shm_ros.core.models import build_model
from shm_ros.core.models.base import AffineModel
from shm_ros.core.simulate.effects import Effect, EffectError
from shm_ros.core.simulate.linear import ModalSystem, from_real_modes, from_state_space, real_shape
from shm_ros.core.structure import StructureSpec, structure_from_dict

_FLAT = {"dist": "uniform", "low": 0.0, "high": 10.0}


@dataclass
class ModalTruth:
    """True modal properties of one window (lowest modes, ascending frequency)."""

    frequencies_hz: np.ndarray
    damping_ratios: np.ndarray
    shapes: np.ndarray  # (n_sensors, n_modes) real, largest |.| = +1 per mode
    sensor_ids: list[str]


@dataclass
class TruthModel:
    """Truth structure of a scenario; :meth:`system` gives the simulation model of one window."""

    kind: str
    nominal: StructureSpec
    spec: StructureSpec
    model: AffineModel
    groups: dict[str, list[int]]  # effect group -> parameter indices of ``model``
    sensor_ids: list[str]  # output channels, in order
    input_names: list[str]
    modal_damping: np.ndarray | None = None  # girder: truth damping ratio per mode
    load_dofs: np.ndarray | None = None  # girder: DOFs of the load points
    load_x: np.ndarray | None = None
    rayleigh: tuple[float, float] = (0.0, 0.0)  # building: C = a0 M + a1 K_story
    dampers: dict[str, Any] = field(default_factory=dict)
    soil: dict[str, float] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)
    max_frequency_hz: float = 45.0

    # -- per-window parameters ----------------------------------------------------------------
    def theta(self, factors: dict[str, float]) -> np.ndarray:
        th = np.ones(self.model.n_parameters)
        for group, f in factors.items():
            if group == "damper":
                continue
            if group not in self.groups:
                raise EffectError(f"effect group {group!r} does not exist in a {self.kind} truth model")
            th[self.groups[group]] *= f
        return th

    # -- girder -------------------------------------------------------------------------------
    def _girder_system(self, theta: np.ndarray, n_keep: int, damping_scale: float = 1.0
                       ) -> tuple[ModalSystem, np.ndarray, np.ndarray]:
        sol = self.model.modes(theta, n_modes=n_keep)
        f = sol.frequencies_hz
        # the recorder's anti-alias filter: modes above 0.9 x Nyquist are neither recorded nor truth
        keep = f <= self.max_frequency_hz
        keep[0] = True
        f, phi = f[keep], sol.shapes[:, keep]
        z = np.minimum(self.modal_damping[: f.size] * damping_scale, 0.5)
        S = self.model.sensor_matrix(self.sensor_ids)
        P = phi[self.load_dofs, :].T  # (m, n_loads): phi_j at each load point
        sys = from_real_modes(f, z, P, S @ phi)
        return sys, f, z

    # -- building -----------------------------------------------------------------------------
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
                          k_scale: np.ndarray | None = None, c_scale: np.ndarray | None = None) -> dict[str, np.ndarray]:
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

    def _building_state_space(self, mats: dict[str, np.ndarray]) -> ModalSystem:
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
        Sel = self._building_selection(n)
        Cacc = Sel @ A[n:2 * n, :]
        D = Sel @ B[n:2 * n, :]
        D[:, 0] += 1.0  # absolute acceleration = relative + ground
        Cdisp = np.zeros((Sel.shape[0], ns))
        Cdisp[:, :n] = Sel
        return from_state_space(A, B, Cacc, D, Cdisp=Cdisp)

    def _building_selection(self, n: int) -> np.ndarray:
        Sel = np.zeros((len(self.sensor_ids), n))
        for r, sid in enumerate(self.sensor_ids):
            dof = self.info["sensor_dof"][sid]
            if dof is not None:
                Sel[r, dof] = 1.0
        return Sel

    # -- both ---------------------------------------------------------------------------------
    def system(self, factors: dict[str, float], k_scale: np.ndarray | None = None,
               c_scale: np.ndarray | None = None, damping_scale: float = 1.0) -> tuple[ModalSystem, ModalTruth]:
        """Simulation model and true modal properties under the effect ``factors`` of a window.

        Building: ``k_scale``/``c_scale`` per story (equivalent-linear amplitude effects); girder:
        ``damping_scale`` multiplies every modal damping ratio."""
        theta = self.theta(factors)
        n_truth = self.info["n_truth_modes"]
        if self.kind == "girder":
            sys, f, z = self._girder_system(theta, self.info["n_keep"], damping_scale)
            n_truth = min(n_truth, f.size)
            shapes = np.column_stack([real_shape(sys.shapes[:, j]) for j in range(n_truth)])
            return sys, ModalTruth(f[:n_truth].copy(), z[:n_truth].copy(), shapes, list(self.sensor_ids))
        mats = self.building_matrices(theta, factors, k_scale, c_scale)
        sys = self._building_state_space(mats)
        osc = np.nonzero(sys.conjugate)[0]
        order = osc[np.argsort(sys.frequencies_hz()[osc])][:n_truth]
        shapes = np.column_stack([real_shape(sys.shapes[:, j]) for j in order]) if order.size else np.zeros((len(self.sensor_ids), 0))
        return sys, ModalTruth(sys.frequencies_hz()[order], sys.damping_ratios()[order], shapes,
                               list(self.sensor_ids))


# ------------------------------------------------------------------------------------------------
def build_truth(structure: dict[str, Any], effects: list[Effect], rng: np.random.Generator, *,
                refine: int = 4, scatter: float = 0.03, misplacement_std_m: float = 0.15,
                damping_range: tuple[float, float] = (0.012, 0.025), n_truth_modes: int = 6,
                fs: float = 100.0) -> TruthModel:
    """Truth model of the nominal ``structure`` mapping (see module doc); ``rng`` draws the scatter."""
    nominal = structure_from_dict(copy.deepcopy(structure), source="<nominal>")
    if nominal.kind == "girder":
        return _girder_truth(nominal, structure, effects, rng, refine, scatter, misplacement_std_m,
                             damping_range, n_truth_modes, fs)
    if nominal.kind == "shear_building":
        return _building_truth(nominal, structure, effects, rng, scatter, damping_range, n_truth_modes)
    raise EffectError(f"cannot simulate a structure of kind {nominal.kind!r} (girder or shear_building)")


def _girder_truth(nominal, structure, effects, rng, refine, scatter, mis_std, damping_range, n_truth, fs):
    d = copy.deepcopy(structure)
    g = d["girder"]
    n_spans = len(g["spans"])
    sec = g["section"]
    secs = [dict(s) for s in sec] if isinstance(sec, list) else [dict(sec) for _ in range(n_spans)]
    for s in secs:
        s["E"] = float(s["E"]) * float(1 + scatter * rng.standard_normal())
        s["rho"] = float(s["rho"]) * float(1 + scatter * rng.standard_normal())
    g["section"] = secs
    g["elements_per_span"] = int(g["elements_per_span"]) * int(refine)
    soil = next((e for e in effects if e.key == "support_flexibility"), None)
    for b in g["bearings"]:
        kv = float(b["k_vertical"]) * float(np.exp(2 * scatter * rng.standard_normal()))
        if soil is not None:  # soil spring in series under the bearing
            kv = 1.0 / (1.0 / kv + 1.0 / float(soil.params["k_soil_n_m"]))
        b["k_vertical"] = kv
        # elastomeric bearings restrain rotation a little (the nominal file says 0)
        b["k_rotation"] = float(b.get("k_rotation", 0.0)) + 2.0e7 * float(np.exp(0.3 * rng.standard_normal()))
    length = float(sum(g["spans"]))
    sensor_ids = [s["id"] for s in d["sensors"]]
    for s in d["sensors"]:
        x = float(s["at"]["x"]) + mis_std * float(rng.standard_normal())
        s["at"] = {"x": float(np.clip(x, 0.05, length - 0.05))}
    params = []
    for k in range(n_spans):
        params.append({"name": f"span{k + 1}_EI", "applies_to": f"girder.section[{k}].E", "prior": _FLAT})
        params.append({"name": f"span{k + 1}_mass", "applies_to": f"girder.section[{k}].rho", "prior": _FLAT})
    for i in range(len(g["bearings"])):
        params.append({"name": f"bearing{i + 1}_kv", "applies_to": f"girder.bearings[{i}].k_vertical", "prior": _FLAT})
        params.append({"name": f"bearing{i + 1}_kr", "applies_to": f"girder.bearings[{i}].k_rotation", "prior": _FLAT})
    d["parameters"] = params
    d.pop("input", None)
    spec = structure_from_dict(d, source="<truth>")
    # a regular fine mesh; misplaced sensors read through the beam's shape functions (a node at a
    # sensor a few mm from a mesh node would make a tiny, ill-conditioning element)
    model = build_model(spec, sensor_nodes=False)
    names = model.parameter_names
    groups: dict[str, list[int]] = {
        "EI": [names.index(f"span{k + 1}_EI") for k in range(n_spans)],
        "mass": [names.index(f"span{k + 1}_mass") for k in range(n_spans)],
        "bearings": [i for i, n in enumerate(names) if n.startswith("bearing")],
    }
    for k in range(n_spans):
        groups[f"EI:{k + 1}"] = [names.index(f"span{k + 1}_EI")]
    # load points: every node of the deck that is not a support, at most ~1 m apart
    node_x = np.asarray(model.node_x)
    bearing_x = np.array([b["x"] for b in g["bearings"]])
    cand, last = [], -np.inf
    for i, x in enumerate(node_x):
        if x - last >= 0.9 and np.min(np.abs(bearing_x - x)) > 1e-6:
            cand.append(i)
            last = x
    load_nodes = np.array(cand, dtype=int)
    # enough modes for the band below 0.9 x Nyquist (or at least the truth modes)
    n_keep = min(model.n_dof, 60)
    damping = np.sort(rng.uniform(*damping_range, size=n_keep))
    # damping grows with mode number but not smoothly (no Rayleigh law)
    info = {"n_truth_modes": n_truth, "n_keep": n_keep, "min_modes": n_truth,
            "sensor_x": {s["id"]: s["at"]["x"] for s in d["sensors"]}}
    return TruthModel(kind="girder", nominal=nominal, spec=spec, model=model, groups=groups,
                      sensor_ids=sensor_ids, input_names=[f"load@{node_x[i]:.2f}" for i in load_nodes],
                      modal_damping=damping, load_dofs=2 * load_nodes, load_x=node_x[load_nodes],
                      info=info, max_frequency_hz=0.9 * fs / 2)


def _building_truth(nominal, structure, effects, rng, scatter, damping_range, n_truth):
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
        found = {"mass": soil.params["mass_rel"] * total, "stiffness": soil.params["k_soil_rel"] * floors[0]["stiffness"]}
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
        [{"name": f"story{i + 1}", "applies_to": f"shear_building.floors[{i}].stiffness", "prior": _FLAT}
         for i in range(len(floors))]
        + [{"name": f"floor{i + 1}_mass", "applies_to": f"shear_building.floors[{i}].mass", "prior": _FLAT}
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
    a0, a1 = np.linalg.solve(np.array([[1 / (2 * w[0]), w[0] / 2], [1 / (2 * w[2]), w[2] / 2]]), [z1, z3])
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
    tm = TruthModel(kind="shear_building", nominal=nominal, spec=spec, model=model, groups=groups,
                    sensor_ids=sensor_ids, input_names=["ground"] + [f"wind@floor{i + 1}" for i in range(n)],
                    rayleigh=(float(a0), float(a1)), dampers=dampers, soil=soil_info, info=info)
    return tm
