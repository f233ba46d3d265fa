"""What a real girder deck has and a 2-D Euler-Bernoulli analysis model does not.

* shear deformation and rotary inertia of the deep box section (Timoshenko beam): a few per cent off
  the higher vertical modes, more the shorter their half wave;
* lateral bending of the deck on the bearings' lateral restraint (elastomeric bearings and piers):
  the first lateral modes are a sway of the deck on its bearings, a few Hz;
* St-Venant torsion of the deck, restrained at each support by the pair of bearings under it;
* a footway on one side: the deck's mass centre sits off its shear centre, so vertical bending and
  torsion couple (every vertical mode twists a little, every torsion mode heaves a little).

Sensors sit off the centre line, so a vertical sensor at transverse offset ``y`` reads ``w + y theta``
and its cross-axis sensitivity reads the lateral motion ``v - h theta`` (``h`` its height over the
shear centre). Lateral and torsion models share the vertical model's mesh and parameter names, so a
window's effect factors act on all three (span ``E`` scales ``G`` too, span mass scales the mass
moment of inertia, bearing springs scale the lateral and torsional restraint).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import numpy as np

from shm_ros.core.models import build_model
from shm_ros.core.models.base import AffineModel
from shm_ros.core.structure import structure_from_dict


@dataclass(frozen=True)
class DeckForm:
    """Magnitudes of a concrete single-cell box-girder deck 11 m wide (the named girder's section:
    A = 5.2 m^2, I = 2.1 m^4, about 2.2 m deep). Ratios are to the nominal vertical ``I``."""

    lateral_i_ratio: float = 19.0  # I_lateral ~ 40 m^4 (11 m top slab, 5 m bottom slab, two webs)
    torsion_j_ratio: float = 2.6  # St-Venant J ~ 5.5 m^4 (closed cell, cracking-reduced)
    mass_radius2_m2: float = 11.5  # polar mass moment / mass per length (deck, surfacing, barriers)
    mass_eccentricity_m: float = 0.3  # footway (1 t/m at 4.5 m) on one side of a 14.5 t/m deck
    shear_area_ratio: float = 0.6  # shear area / A (webs and part of the slabs)
    poisson: float = 0.2
    k_lateral_n_m: float = 1.5e8  # lateral restraint per support (elastomeric bearings on piers)
    # partial rotational restraint per support beyond the elastomer's (nominal file: 0): the bearings'
    # footprint (a 1 m long pair under 5 GN/m gives k_v l^2 / 12 ~ 4e8), backwalls; ~ EI / (3 L)
    k_rotation_n_m_rad: float = 1.0e9
    bearing_spacing_m: float = 5.0  # two bearings per support: torsional restraint k_v s^2 / 4
    sensor_offset_m: float = 3.0  # vertical sensors alternate +-offset from the centre line
    sensor_height_m: float = 1.0  # over the shear centre (reads torsion laterally)
    lane_offset_m: float = 1.9  # two lanes, +-offset (traffic twists the deck)
    lift_arm_m: float = 2.75  # aerodynamic moment arm of the vertical gust load (B / 4)
    drag_ratio: float = 3.0  # lateral gust force RMS / vertical gust force RMS
    drag_arm_m: float = 0.8  # drag acts this far over the shear centre
    lateral_damping: tuple[float, float] = (0.02, 0.04)  # elastomeric bearings dissipate in shear
    torsion_damping: tuple[float, float] = (0.008, 0.018)


def timoshenko_terms(model: AffineModel, spans: list[float], secs: list[dict[str, Any]], form: DeckForm,
                     ei_params: list[int], mass_params: list[int]) -> None:
    """Turn the span terms of an Euler-Bernoulli girder ``model`` into Timoshenko ones (shear
    flexibility, rotary inertia), in place. ``G = E / 2(1 + nu)`` follows ``E``, so the shear
    parameter ``phi = 12 E I / (kappa G A L^2)`` does not depend on ``E`` and the model stays affine
    in the span factors."""
    assert model.node_x is not None  # a girder model
    x = np.asarray(model.node_x)
    ends = np.concatenate([[0.0], np.cumsum(spans)])
    span_of = np.clip(np.searchsorted(ends, 0.5 * (x[:-1] + x[1:]), side="right") - 1, 0, len(spans) - 1)
    n = model.n_dof
    for k, (pk, pm) in enumerate(zip(ei_params, mass_params, strict=True)):
        s = secs[k]
        EI, rhoI = float(s["E"]) * float(s["I"]), float(s["rho"]) * float(s["I"])
        Kk, Mr = np.zeros((n, n)), np.zeros((n, n))
        for e in np.nonzero(span_of == k)[0]:
            L = float(x[e + 1] - x[e])
            phi = 24.0 * (1.0 + form.poisson) * float(s["I"]) / (form.shear_area_ratio * float(s["A"]) * L * L)
            sl = slice(2 * e, 2 * e + 4)
            Kk[sl, sl] += (EI / ((1 + phi) * L**3)) * np.array([
                [12.0, 6 * L, -12.0, 6 * L],
                [6 * L, (4 + phi) * L * L, -6 * L, (2 - phi) * L * L],
                [-12.0, -6 * L, 12.0, -6 * L],
                [6 * L, (2 - phi) * L * L, -6 * L, (4 + phi) * L * L]])
            Mr[sl, sl] += (rhoI / (30.0 * L)) * np.array([
                [36.0, 3 * L, -36.0, 3 * L],
                [3 * L, 4 * L * L, -3 * L, -L * L],
                [-36.0, -3 * L, 36.0, -3 * L],
                [3 * L, -L * L, -3 * L, 4 * L * L]])
        model.K_terms[pk] = Kk
        Mk = model.M_terms[pm]
        model.M_terms[pm] = Mr if Mk is None else Mk + Mr


def lateral_model(truth_structure: dict[str, Any], k_lateral: list[float], form: DeckForm) -> AffineModel:
    """Lateral bending of the deck: the vertical truth structure with the lateral second moment of
    area and the bearings' lateral springs (no yaw restraint); same mesh and parameter names."""
    d = copy.deepcopy(truth_structure)
    g = d["girder"]
    for s in g["section"]:
        s["I"] = float(s["I"]) * form.lateral_i_ratio
    for b, k in zip(g["bearings"], k_lateral, strict=True):
        b["k_vertical"], b["k_rotation"] = float(k), 0.0
    return build_model(structure_from_dict(d, source="<truth lateral>"), sensor_nodes=False)


def torsion_model(vertical: AffineModel, truth_structure: dict[str, Any], form: DeckForm) -> AffineModel:
    """St-Venant torsion rod on the vertical model's nodes (linear elements): span ``G J`` and mass
    moment ``rho A r^2`` per span parameter, bearing pairs ``k_v s^2 / 4`` per bearing parameter."""
    assert vertical.node_x is not None  # a girder model
    g = truth_structure["girder"]
    x = np.asarray(vertical.node_x)
    n = x.size
    ends = np.concatenate([[0.0], np.cumsum(g["spans"])])
    span_of = np.clip(np.searchsorted(ends, 0.5 * (x[:-1] + x[1:]), side="right") - 1, 0, len(g["spans"]) - 1)
    names = vertical.parameter_names
    K_terms: list[np.ndarray | None] = [None] * len(names)
    M_terms: list[np.ndarray | None] = [None] * len(names)
    for k, s in enumerate(g["section"]):
        GJ = float(s["E"]) / (2 * (1 + form.poisson)) * float(s["I"]) * form.torsion_j_ratio
        Im = float(s["rho"]) * float(s["A"]) * form.mass_radius2_m2
        Kk, Mk = np.zeros((n, n)), np.zeros((n, n))
        for e in np.nonzero(span_of == k)[0]:
            L = float(x[e + 1] - x[e])
            sl = slice(e, e + 2)
            Kk[sl, sl] += (GJ / L) * np.array([[1.0, -1.0], [-1.0, 1.0]])
            Mk[sl, sl] += (Im * L / 6.0) * np.array([[2.0, 1.0], [1.0, 2.0]])
        K_terms[names.index(f"span{k + 1}_EI")] = Kk
        M_terms[names.index(f"span{k + 1}_mass")] = Mk
    for i, b in enumerate(g["bearings"]):
        node = int(np.argmin(np.abs(x - float(b["x"]))))
        Kb = np.zeros((n, n))
        Kb[node, node] = float(b["k_vertical"]) * form.bearing_spacing_m ** 2 / 4.0
        K_terms[names.index(f"bearing{i + 1}_kv")] = Kb
    rows = {}
    for sid, sx in ((s["id"], float(s["at"]["x"])) for s in truth_structure["sensors"]):
        el = int(np.clip(np.searchsorted(x, sx) - 1, 0, n - 2))
        a = (sx - x[el]) / (x[el + 1] - x[el])
        r = np.zeros(n)
        r[el], r[el + 1] = 1 - a, a
        rows[sid] = r
    return AffineModel(name="deck torsion", parameter_names=list(names), K0=np.zeros((n, n)), M0=np.zeros((n, n)),
                       K_terms=K_terms, M_terms=M_terms, dof_labels=[f"t@{v:.6g}" for v in x], sensor_rows=rows,
                       kind="girder", direction="torsion", node_x=x.copy())


def eccentric_mass_terms(vertical: AffineModel, torsion: AffineModel, form: DeckForm,
                         truth_structure: dict[str, Any]) -> list[np.ndarray | None]:
    """Per parameter, the vertical-torsion mass coupling ``e m`` (lumped at the nodes: the kinetic
    energy of the deck is ``m (w' + e theta')^2 / 2`` per length), shape (n_vertical_dof, n_torsion_dof)."""
    assert vertical.node_x is not None  # a girder model
    g = truth_structure["girder"]
    x = np.asarray(vertical.node_x)
    ends = np.concatenate([[0.0], np.cumsum(g["spans"])])
    span_of = np.clip(np.searchsorted(ends, 0.5 * (x[:-1] + x[1:]), side="right") - 1, 0, len(g["spans"]) - 1)
    names = vertical.parameter_names
    out: list[np.ndarray | None] = [None] * len(names)
    for k, s in enumerate(g["section"]):
        C = np.zeros((vertical.n_dof, torsion.n_dof))
        m = float(s["rho"]) * float(s["A"]) * form.mass_eccentricity_m
        for e in np.nonzero(span_of == k)[0]:
            half = 0.5 * m * float(x[e + 1] - x[e])
            C[2 * e, e] += half
            C[2 * e + 2, e + 1] += half
        out[names.index(f"span{k + 1}_mass")] = C
    return out
