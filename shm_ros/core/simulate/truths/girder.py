"""Truth model of a girder: a finer, scattered deck under traffic and wind.

Compared with the nominal file: ``refine`` x the elements per span, scattered E and density per span
and bearing stiffness, a rotational restraint at the bearings, sensors misplaced by a few cm to dm,
and modal damping drawn per mode (no Rayleigh law). With ``model_form`` (the default) the deck is
also a Timoshenko beam that bends laterally and twists (:mod:`shm_ros.core.simulate.truths.deck`):
the vertical sensors sit off the centre line and read torsion, their cross-axis sensitivity reads
lateral motion, and two eccentric traffic lanes and the wind's drag and moment excite both. Mode
families: ``vertical`` (in plane), ``lateral``, ``torsion``; the three are uncoupled (a straight,
symmetric deck) and each mode has its own damping ratio, drawn per family.

The response is computed by real-mode superposition of the modes below 0.9 x Nyquist (the
recorder's anti-alias filter); amplitude effects are equivalent-linear per window.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import numpy as np

import shm_ros.core.simulate.excitation as ex
from shm_ros.core.modal import real_shape
from shm_ros.core.models import build_model
from shm_ros.core.models.base import AffineModel
from shm_ros.core.simulate.effects import Conditions, Effect
from shm_ros.core.simulate.linear import ModalSystem, from_real_modes
from shm_ros.core.simulate.truth import FLAT_PRIOR, ModalTruth, TruthModel, TruthOptions, WindowRun, report_modes
from shm_ros.core.simulate.truth_kinds import register
from shm_ros.core.simulate.truths.deck import (
    DeckForm,
    eccentric_mass_terms,
    lateral_model,
    timoshenko_terms,
    torsion_model,
)
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

    modal_damping: np.ndarray | None = None  # truth damping ratio per vertical mode
    load_dofs: np.ndarray | None = None  # DOFs of the load points
    load_x: np.ndarray | None = None
    form: DeckForm | None = None  # None: the deck is the analysis model's kind of beam (model_form off)
    lateral: AffineModel | None = None
    torsion: AffineModel | None = None
    coupling: list[np.ndarray | None] | None = None  # vertical-torsion mass coupling per parameter
    family_damping: dict[str, np.ndarray] | None = None  # lateral / torsion damping ratio per mode
    sensor_offsets: np.ndarray | None = None  # (n_sensors, 2): transverse offset, height over the shear centre

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
        form = DeckForm() if o.model_form else None
        for b in g["bearings"]:
            kv = float(b["k_vertical"]) * float(np.exp(2 * scatter * rng.standard_normal()))
            if soil is not None:  # soil spring in series under the bearing
                kv = 1.0 / (1.0 / kv + 1.0 / float(soil.params["k_soil_n_m"]))
            b["k_vertical"] = kv
            # elastomeric bearings restrain rotation a little (the nominal file says 0); they freeze
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
        info: dict[str, Any] = {"n_truth_modes": o.n_truth_modes, "n_keep": n_keep, "min_modes": o.n_truth_modes,
                                "sensor_x": {s["id"]: s["at"]["x"] for s in d["sensors"]}}
        lat = tors = None
        coupling = None
        fam_damping = None
        offsets = np.zeros((len(sensor_ids), 2))
        names_in = [f"load@{node_x[i]:.2f}" for i in load_nodes]
        if form is not None:
            timoshenko_terms(model, g["spans"], secs, form, groups["EI"], groups["mass"])
            # the bearings' footprint and the backwalls restrain rotation more (and do not freeze)
            k_fixed = []
            for b in g["bearings"]:
                k_fixed.append(form.k_rotation_n_m_rad * float(np.exp(0.3 * rng.standard_normal())))
                node = int(np.argmin(np.abs(node_x - float(b["x"]))))
                model.K0[2 * node + 1, 2 * node + 1] += k_fixed[-1]
            info["k_rotation_fixed"] = k_fixed
            k_lat = [form.k_lateral_n_m * float(np.exp(0.3 * rng.standard_normal())) for _ in g["bearings"]]
            if soil is not None:  # the soil under a pier gives way sideways too
                k_lat = [1.0 / (1.0 / k + 1.0 / float(soil.params["k_soil_n_m"])) for k in k_lat]
            lat = lateral_model(d, k_lat, form)
            tors = torsion_model(model, d, form)
            coupling = eccentric_mass_terms(model, tors, form, d)
            fam_damping = {"lateral": rng.uniform(*form.lateral_damping, size=n_keep),
                           "torsion": np.sort(rng.uniform(*form.torsion_damping, size=n_keep))}
            side = np.where(np.arange(len(sensor_ids)) % 2 == 0, 1.0, -1.0)
            offsets[:, 0] = side * form.sensor_offset_m + o.misplacement_std_m * rng.standard_normal(len(sensor_ids))
            offsets[:, 1] = form.sensor_height_m
            info["sensor_y"] = {sid: float(v) for sid, v in zip(sensor_ids, offsets[:, 0], strict=True)}
            info["k_lateral"] = k_lat
            names_in += [f"lateral@{node_x[i]:.2f}" for i in load_nodes]
            names_in += [f"torque@{node_x[i]:.2f}" for i in load_nodes]
        return cls(nominal=nominal, spec=spec, model=model, groups=groups, sensor_ids=sensor_ids,
                   input_names=names_in, modal_damping=damping,
                   load_dofs=2 * load_nodes, load_x=node_x[load_nodes], info=info,
                   max_frequency_hz=0.9 * o.fs / 2, in_plane_family="vertical", form=form, lateral=lat,
                   torsion=tors, coupling=coupling, family_damping=fam_damping, sensor_offsets=offsets)

    # -- one window ---------------------------------------------------------------------------
    def system(self, factors: dict[str, float], k_scale: np.ndarray | None = None,
               c_scale: np.ndarray | None = None, damping_scale: float = 1.0) -> tuple[ModalSystem, ModalTruth]:
        """Real-mode system of every family; ``damping_scale`` multiplies every modal damping ratio.

        Inputs: vertical loads at the load points, then (model form) lateral loads and torques;
        outputs: x, y, z acceleration at every sensor (x along the deck, y lateral, z vertical)."""
        assert self.modal_damping is not None and self.load_dofs is not None  # set by build
        theta = self.theta(factors)
        n_s, nl = len(self.sensor_ids), self.load_dofs.size
        n_in = nl if self.form is None else 3 * nl
        freqs, damp, fams, outs, parts = [], [], [], [], []
        for fam, f, phi in self._families(theta):
            keep = f <= self.max_frequency_hz
            if fam == "vertical":
                keep[0] = True  # at least one mode whatever the sample rate
            f, phi = f[keep], phi[:, keep]
            if fam == "vertical":
                zs = self.modal_damping
            else:
                assert self.family_damping is not None  # set by build whenever out-of-plane families exist
                zs = self.family_damping[fam]
            out = np.zeros((n_s, 3, f.size))
            P = np.zeros((f.size, n_in))
            if fam == "lateral":
                assert self.lateral is not None
                out[:, 1] = self.lateral.sensor_matrix(self.sensor_ids) @ phi
                P[:, nl:2 * nl] = phi[self.load_dofs, :].T
            else:
                nv = self.model.n_dof
                out[:, 2] = self.model.sensor_matrix(self.sensor_ids) @ phi[:nv]
                P[:, :nl] = phi[self.load_dofs, :].T
                if self.torsion is not None:  # a point at (y, h) from the shear centre moves (0, -h t, y t)
                    assert self.sensor_offsets is not None
                    t = self.torsion.sensor_matrix(self.sensor_ids) @ phi[nv:]
                    out[:, 2] += self.sensor_offsets[:, :1] * t
                    out[:, 1] -= self.sensor_offsets[:, 1:] * t
                    P[:, 2 * nl:] = phi[nv + self.load_dofs // 2, :].T
            # damping ratios by rank within the family
            freqs.append(f)
            damp.append(zs[: f.size])
            fams += [fam] * f.size
            outs.append(out.reshape(3 * n_s, f.size))
            parts.append(P)
        order = np.argsort(np.concatenate(freqs), kind="stable")
        f = np.concatenate(freqs)[order]
        z = np.minimum(np.concatenate(damp)[order] * damping_scale, 0.5)
        fam_all = [fams[j] for j in order]
        sys = from_real_modes(f, z, np.vstack(parts)[order], np.hstack(outs)[:, order])
        pick = report_modes(f, fam_all, "vertical", self.info["n_truth_modes"])
        # shapes along the sensors' direction (z); a lateral mode has none (the sensors see it only
        # through their cross-axis sensitivity), so its shape is the lateral one (y rows)
        shapes = (np.column_stack([real_shape(sys.shapes[1 if fam_all[j] == "lateral" else 2::3, j].real)
                                   for j in pick]) if pick.size else np.zeros((n_s, 0)))
        return sys, ModalTruth(f[pick].copy(), z[pick].copy(), shapes, list(self.sensor_ids),
                               [fam_all[j] for j in pick], "vertical")

    def _families(self, theta: np.ndarray) -> list[tuple[str, np.ndarray, np.ndarray]]:
        """(family, frequencies, mass-normalised shapes) of each family: vertical and torsion from the
        coupled vertical-torsion model (shapes over its DOFs: vertical, then torsion), lateral alone."""
        n_keep = self.info["n_keep"]
        if self.torsion is None:
            sol = self.model.modes(theta, n_modes=n_keep)
            return [("vertical", sol.frequencies_hz, sol.shapes)]
        assert self.lateral is not None and self.coupling is not None
        nv, nt = self.model.n_dof, self.torsion.n_dof
        Mv, Mt = self.model.mass(theta), self.torsion.mass(theta)
        Cvt = sum(t * c for t, c in zip(theta, self.coupling, strict=True) if c is not None)
        K = np.zeros((nv + nt, nv + nt))
        M = np.zeros_like(K)
        K[:nv, :nv], K[nv:, nv:] = self.model.stiffness(theta), self.torsion.stiffness(theta)
        M[:nv, :nv], M[nv:, nv:], M[:nv, nv:] = Mv, Mt, Cvt
        M[nv:, :nv] = M[:nv, nv:].T
        f, phi = _modes_below(K, M, self.max_frequency_hz)
        ev = np.einsum("ij,ij->j", phi[:nv], Mv @ phi[:nv])
        et = np.einsum("ij,ij->j", phi[nv:], Mt @ phi[nv:])
        is_v = ev >= et
        if not np.any(is_v):  # a sample rate below the first vertical mode: keep that mode anyway
            sol = self.model.modes(theta, n_modes=1)
            return [("vertical", sol.frequencies_hz, np.vstack([sol.shapes, np.zeros((nt, 1))]))]
        fl, phil = _modes_below(self.lateral.stiffness(theta), self.lateral.mass(theta), self.max_frequency_hz)
        return [("vertical", f[is_v], phi[:, is_v]), ("torsion", f[~is_v], phi[:, ~is_v]), ("lateral", fl, phil)]

    def loads(self, rng: np.random.Generator, n: int, cond: Conditions, scenario: Any, system: ModalSystem | None,
              event: dict[str, float] | None) -> tuple[np.ndarray, dict | None]:
        """Modal forces (n, m) of ``system``: traffic and wind at the load points, projected
        (without a system: the loads themselves, vertical, then lateral and torques)."""
        assert self.load_x is not None  # set by build
        sc = scenario
        nl = self.load_x.size
        n_in = nl if self.form is None else 3 * nl
        proj = (np.eye(n_in) if system is None or system.participation is None
                else np.asarray(system.participation.T))
        Pv = proj[:nl]
        g = self.nominal.section
        rate = sc.vehicles_per_hour * ex.traffic_profile(cond.local_hour)
        support = np.array([b.x for b in g.bearings])
        wind = sc.wind_rms_n * float(rng.lognormal(0.0, 0.4))
        if self.form is None:
            F, _ = ex.traffic_loads(rng, n, sc.fs, self.load_x, g.length, rate, support_x=support, projection=Pv)
            F += ex.wind_loads(rng, n, sc.fs, nl, wind, projection=Pv)
            return F, None
        fm = self.form
        Pl, Pt = proj[nl:2 * nl], proj[2 * nl:]
        F = np.zeros((n, proj.shape[1]))
        for side in (1.0, -1.0):  # one lane each way, off the centre line: vehicles twist the deck
            Fl, _ = ex.traffic_loads(rng, n, sc.fs, self.load_x, g.length, 0.5 * rate, support_x=support,
                                     projection=Pv + side * fm.lane_offset_m * Pt)
            F += Fl
        # one gust field: lift with its moment, and drag (acting over the shear centre)
        F += ex.wind_loads(rng, n, sc.fs, nl, wind, projection=np.hstack([
            Pv + fm.lift_arm_m * Pt, fm.drag_ratio * (Pl - fm.drag_arm_m * Pt)])).reshape(n, 2, -1).sum(axis=1)
        return F, None

    def respond(self, run: WindowRun) -> tuple[np.ndarray, ModalTruth, dict[str, Any]]:
        if not run.amplitude_effects:
            return run.system.simulate_modal(run.inputs, run.dt), run.modal, {}
        return self._amplitude(run)

    def _amplitude(self, run: WindowRun, passes: int = 4) -> tuple[np.ndarray, ModalTruth, dict[str, Any]]:
        """Amplitude effects, equivalent-linear per window: the deck stiffness factor
        1 / (1 + a / a_ref) and damping factor 1 + a / a_ref follow the window's RMS acceleration a
        (vertical, mean over sensors, after warm-up), found by fixed-point passes over the same loads."""
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
            a = float(np.mean(np.sqrt(np.mean(y[run.n_warm:, 2::3] ** 2, axis=0))))  # vertical
        extra = {"equivalent_linear": {"rms_accel_m_s2": a_used, "stiffness_factor": kf, "damping_factor": zf,
                                       "rms_accel_response_m_s2": a}}
        return y, modal, extra

    def summary(self) -> dict[str, Any]:
        assert self.modal_damping is not None  # set by build
        out: dict[str, Any] = {"modal_damping_ratios": [float(z) for z in self.modal_damping[:12]],
                               "sensor_x_m": self.info["sensor_x"],
                               "elements_per_span": self.spec.section.elements_per_span,
                               "in_plane_family": "vertical"}
        if self.form is not None:
            assert self.family_damping is not None
            out["model_form"] = {
                "deck": {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(self.form).items()},
                "beam": "Timoshenko (shear deformation, rotary inertia)",
                "sensor_y_m": self.info["sensor_y"],
                "k_lateral_n_m": self.info["k_lateral"],
                "k_rotation_fixed_n_m_rad": self.info["k_rotation_fixed"],
                "damping_ratios": {k: [float(z) for z in v[:6]] for k, v in self.family_damping.items()},
            }
        return out


def _modes_below(K: np.ndarray, M: np.ndarray, f_max: float) -> tuple[np.ndarray, np.ndarray]:
    """Modes (frequencies, mass-normalised shapes) up to ``f_max`` only: a window needs no more, and
    the eigenvectors above it are most of a full solve's cost."""
    from scipy.linalg import eigh

    w2, phi = eigh(K, M, subset_by_value=(-np.inf, (2 * np.pi * f_max * 1.001) ** 2))
    return np.sqrt(np.clip(w2, 0.0, None)) / (2 * np.pi), phi
