"""Truth model of a girder: a finer, scattered beam under traffic and wind.

Compared with the nominal file: ``refine`` x the elements per span, scattered E and density per span
and bearing stiffness, a small rotational restraint at the bearings, sensors misplaced by a few cm
to dm, and modal damping drawn per mode (no Rayleigh law). The response is computed by real-mode
superposition of the modes below 0.9 x Nyquist (the recorder's anti-alias filter); amplitude effects
are equivalent-linear per window.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import numpy as np

import shm_ros.core.simulate.excitation as ex
from shm_ros.core.modal import real_shape
from shm_ros.core.models import build_model
from shm_ros.core.simulate.effects import Conditions, Effect
from shm_ros.core.simulate.linear import ModalSystem, from_real_modes
from shm_ros.core.simulate.truth import FLAT_PRIOR, ModalTruth, TruthModel, TruthOptions, WindowRun
from shm_ros.core.simulate.truth_kinds import register
from shm_ros.core.structure import StructureSpec, structure_from_dict


@register("girder")
@dataclass
class GirderTruth(TruthModel):
    effect_defaults = {
        "temperature_linear": {"where": "deck", "alpha_per_c": -0.004, "t_ref_c": 10.0},
        "temperature_bilinear": {"where": "deck", "alpha_per_c": -0.002, "t_ref_c": 10.0, "knee_c": 0.0,
                                 "below_per_c": -0.05},
        "damage": {"at": "48h", "factor": 0.85, "where": "span2"},
        "repair": {"at": "96h", "factor": 1.10, "where": "span2"},
        "added_mass": {"fraction": 0.06, "when": "rush_hours"},
        "support_flexibility": {"k_soil_n_m": 2.0e9},
        "amplitude_stiffness": {"accel_ref_m_s2": 1.0},
        "amplitude_damping": {"accel_ref_m_s2": 0.2},
    }
    effect_forms = {
        "support_flexibility": "series soil spring under every bearing",
        "amplitude_stiffness": "deck stiffness x 1 / (1 + a / a_ref), a = the window's RMS acceleration "
                               "(equivalent linear)",
        "amplitude_damping": "modal damping x (1 + a / a_ref), a = the window's RMS acceleration (equivalent linear)",
    }
    effect_where = {"support_flexibility": "bearings", "damper": "stories", "*": "deck"}
    stiffness_wheres = {"bearings": "bearings"}

    modal_damping: np.ndarray | None = None  # truth damping ratio per mode
    load_dofs: np.ndarray | None = None  # DOFs of the load points
    load_x: np.ndarray | None = None

    @classmethod
    def build(cls, nominal: StructureSpec, structure: dict[str, Any], effects: list[Effect],
              rng: np.random.Generator, options: TruthOptions) -> GirderTruth:
        o = options
        scatter = o.scatter
        d = copy.deepcopy(structure)
        g = d["girder"]
        n_spans = len(g["spans"])
        sec = g["section"]
        secs = [dict(s) for s in sec] if isinstance(sec, list) else [dict(sec) for _ in range(n_spans)]
        for s in secs:
            s["E"] = float(s["E"]) * float(1 + scatter * rng.standard_normal())
            s["rho"] = float(s["rho"]) * float(1 + scatter * rng.standard_normal())
        g["section"] = secs
        g["elements_per_span"] = int(g["elements_per_span"]) * int(o.refine)
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
            x = float(s["at"]["x"]) + o.misplacement_std_m * float(rng.standard_normal())
            s["at"] = {"x": float(np.clip(x, 0.05, length - 0.05))}
        params = []
        for k in range(n_spans):
            params.append({"name": f"span{k + 1}_EI", "applies_to": f"girder.section[{k}].E", "prior": FLAT_PRIOR})
            params.append({"name": f"span{k + 1}_mass", "applies_to": f"girder.section[{k}].rho",
                           "prior": FLAT_PRIOR})
        for i in range(len(g["bearings"])):
            params.append({"name": f"bearing{i + 1}_kv", "applies_to": f"girder.bearings[{i}].k_vertical",
                           "prior": FLAT_PRIOR})
            params.append({"name": f"bearing{i + 1}_kr", "applies_to": f"girder.bearings[{i}].k_rotation",
                           "prior": FLAT_PRIOR})
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
        # damping grows with mode number but not smoothly (no Rayleigh law)
        damping = np.sort(rng.uniform(*o.damping_range, size=n_keep))
        info = {"n_truth_modes": o.n_truth_modes, "n_keep": n_keep, "min_modes": o.n_truth_modes,
                "sensor_x": {s["id"]: s["at"]["x"] for s in d["sensors"]}}
        return cls(nominal=nominal, spec=spec, model=model, groups=groups, sensor_ids=sensor_ids,
                   input_names=[f"load@{node_x[i]:.2f}" for i in load_nodes], modal_damping=damping,
                   load_dofs=2 * load_nodes, load_x=node_x[load_nodes], info=info,
                   max_frequency_hz=0.9 * o.fs / 2)

    # -- one window ---------------------------------------------------------------------------
    def system(self, factors: dict[str, float], k_scale: np.ndarray | None = None,
               c_scale: np.ndarray | None = None, damping_scale: float = 1.0) -> tuple[ModalSystem, ModalTruth]:
        """Real-mode system; ``damping_scale`` multiplies every modal damping ratio."""
        assert self.modal_damping is not None and self.load_dofs is not None  # set by build
        theta = self.theta(factors)
        sol = self.model.modes(theta, n_modes=self.info["n_keep"])
        f = sol.frequencies_hz
        # the recorder's anti-alias filter: modes above 0.9 x Nyquist are neither recorded nor truth
        keep = f <= self.max_frequency_hz
        keep[0] = True
        f, phi = f[keep], sol.shapes[:, keep]
        z = np.minimum(self.modal_damping[: f.size] * damping_scale, 0.5)
        S = self.model.sensor_matrix(self.sensor_ids)
        P = phi[self.load_dofs, :].T  # (m, n_loads): phi_j at each load point
        sys = from_real_modes(f, z, P, S @ phi)
        n_truth = min(self.info["n_truth_modes"], f.size)
        shapes = np.column_stack([real_shape(sys.shapes[:, j]) for j in range(n_truth)])
        return sys, ModalTruth(f[:n_truth].copy(), z[:n_truth].copy(), shapes, list(self.sensor_ids))

    def loads(self, rng: np.random.Generator, n: int, cond: Conditions, scenario: Any, system: ModalSystem | None,
              event: dict[str, float] | None) -> tuple[np.ndarray, dict | None]:
        """Modal forces (n, m) of ``system``: traffic and wind at the load points, projected."""
        assert self.load_x is not None  # set by build
        sc = scenario
        proj = None if system is None or system.participation is None else system.participation.T
        g = self.nominal.section
        rate = sc.vehicles_per_hour * ex.traffic_profile(cond.local_hour)
        F, _ = ex.traffic_loads(rng, n, sc.fs, self.load_x, g.length, rate,
                                support_x=np.array([b.x for b in g.bearings]), projection=proj)
        wind = sc.wind_rms_n * float(rng.lognormal(0.0, 0.4))
        F += ex.wind_loads(rng, n, sc.fs, self.load_x.size, wind, projection=proj)
        return F, None

    def respond(self, run: WindowRun) -> tuple[np.ndarray, ModalTruth, dict[str, Any]]:
        if not run.amplitude_effects:
            return run.system.simulate_modal(run.inputs, run.dt), run.modal, {}
        return self._amplitude(run)

    def _amplitude(self, run: WindowRun, passes: int = 4) -> tuple[np.ndarray, ModalTruth, dict[str, Any]]:
        """Amplitude effects, equivalent-linear per window: the deck stiffness factor
        1 / (1 + a / a_ref) and damping factor 1 + a / a_ref follow the window's RMS acceleration a
        (mean over sensors, after warm-up), found by fixed-point passes over the same loads."""
        keys = {e.key: e for e in run.amplitude_effects}
        k_ref = keys["amplitude_stiffness"].params["accel_ref_m_s2"] if "amplitude_stiffness" in keys else None
        z_ref = keys["amplitude_damping"].params["accel_ref_m_s2"] if "amplitude_damping" in keys else None
        a = a_used = kf = zf = 0.0
        for _ in range(passes):
            a_used = a
            kf = 1.0 / (1.0 + a_used / k_ref) if k_ref else 1.0
            zf = 1.0 + a_used / z_ref if z_ref else 1.0
            fac = dict(run.factors)
            fac["EI"] = fac.get("EI", 1.0) * kf
            sys, modal = self.system(fac, damping_scale=zf)
            y = sys.simulate_modal(run.inputs_for(sys), run.dt)
            a = float(np.mean(np.sqrt(np.mean(y[run.n_warm:] ** 2, axis=0))))
        extra = {"equivalent_linear": {"rms_accel_m_s2": a_used, "stiffness_factor": kf, "damping_factor": zf,
                                       "rms_accel_response_m_s2": a}}
        return y, modal, extra

    def summary(self) -> dict[str, Any]:
        assert self.modal_damping is not None  # set by build
        return {"modal_damping_ratios": [float(z) for z in self.modal_damping[:12]],
                "sensor_x_m": self.info["sensor_x"],
                "elements_per_span": self.spec.section.elements_per_span}
