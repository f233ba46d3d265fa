"""A tf buffer without tf2: a tree of stamped transforms, composed and interpolated in time.

Each edge ``parent -> child`` holds the pose of ``child`` in ``parent`` (``p_parent = R p_child + t``,
the meaning of a ``geometry_msgs/TransformStamped`` with ``header.frame_id = parent``). Dynamic edges
(``/tf``) keep a bounded history (``cache_s``, the newest stamp minus that many seconds; ``None``
keeps everything, as offline); static edges (``/tf_static``) hold one value for all time. A look-up
at many times at once composes the edges along the tree from the common ancestor, each edge
interpolated between its two stamps around the time: linear for the translation, slerp for the
rotation (``scipy.spatial.transform.Slerp``).

A dynamic edge is **missing** at a time before its first stamp, after its last, or inside a gap
between two stamps longer than ``max(0.5 s, 5 x`` its median period``)``: there the look-up gives no
transform (``valid`` False) and :meth:`TransformBuffer.gaps` says which frames, from when to when.
Nothing is ever filled with a default or extrapolated.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from shm_ros.errors import InputError

__all__ = ["TransformError", "Gap", "Lookup", "TransformBuffer", "MIN_GAP_S", "GAP_PERIODS"]

MIN_GAP_S = 0.5  # a gap shorter than this is never missing
GAP_PERIODS = 5.0  # ... nor one shorter than this many median periods of the edge


class TransformError(InputError):
    """No transform between two frames at some time; the message names the frames and the stretch."""


@dataclass(frozen=True)
class Gap:
    """A stretch [start_ns, end_ns] where the edge ``parent -> child`` has no transform."""

    parent: str
    child: str
    start_ns: int
    end_ns: int

    def describe(self) -> str:
        return (f"no transform {self.parent} -> {self.child} from t = {self.start_ns * 1e-9:.3f} s to "
                f"{self.end_ns * 1e-9:.3f} s")


@dataclass
class Lookup:
    """Transforms ``target <- source`` at each time: ``p_target = rotation.apply(p_source) + translation``.
    Where ``valid`` is False the values are NaN."""

    translation: np.ndarray  # (n, 3)
    rotation: np.ndarray  # (n, 4) quaternions (x, y, z, w)
    valid: np.ndarray  # (n,) bool

    def rotate(self, vectors: np.ndarray) -> np.ndarray:
        """Vectors (n, 3) given in the source frame, expressed in the target frame (NaN where invalid)."""
        out = np.full(np.shape(vectors), np.nan)
        if self.valid.any():
            out[self.valid] = Rotation.from_quat(self.rotation[self.valid]).apply(np.asarray(vectors)[self.valid])
        return out


@dataclass
class _Edge:
    parent: str
    static: bool
    stamps: list[int] = field(default_factory=list)
    translations: list[np.ndarray] = field(default_factory=list)
    rotations: list[np.ndarray] = field(default_factory=list)

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return (np.asarray(self.stamps, dtype=np.int64), np.asarray(self.translations, dtype=float),
                np.asarray(self.rotations, dtype=float))

    def period_ns(self) -> float:
        t = np.asarray(self.stamps, dtype=np.int64)
        return float(np.median(np.diff(t))) if t.size > 1 else 0.0

    def max_gap_ns(self) -> float:
        return max(MIN_GAP_S * 1e9, GAP_PERIODS * self.period_ns())


class TransformBuffer:
    """Transforms of a frame tree over time (see module doc). ``cache_s``: the history each dynamic
    edge keeps behind its newest stamp (None: all)."""

    def __init__(self, cache_s: float | None = 10.0):
        self.cache_ns = None if cache_s is None else int(cache_s * 1e9)
        self._edges: dict[str, _Edge] = {}  # keyed by child frame: a tree has one parent per child

    # -- filling ---------------------------------------------------------------------------------
    def set_transform(self, parent: str, child: str, stamp_ns: int, translation, rotation,
                      static: bool = False) -> None:
        """Add one transform (a ``TransformStamped``'s content). A frame whose parent changes starts a
        new history (tf's re-parenting)."""
        if not parent or not child or parent == child:
            raise InputError(f"transform {parent!r} -> {child!r}: needs two different, non-empty frame ids")
        t = np.asarray(translation, dtype=float).reshape(3)
        q = np.asarray(rotation, dtype=float).reshape(4)
        norm = float(np.linalg.norm(q))
        if not (np.all(np.isfinite(t)) and np.isfinite(norm)) or abs(norm - 1.0) > 1e-3:
            raise InputError(f"transform {parent} -> {child} at {stamp_ns * 1e-9:.3f} s: not a finite translation "
                             f"and unit quaternion (|q| = {norm:.6g})")
        edge = self._edges.get(child)
        if edge is None or edge.parent != parent or edge.static != static:
            edge = self._edges[child] = _Edge(parent, static)
        if static:
            edge.stamps, edge.translations, edge.rotations = [int(stamp_ns)], [t], [q / norm]
            return
        k = bisect.bisect_left(edge.stamps, int(stamp_ns))
        if k < len(edge.stamps) and edge.stamps[k] == int(stamp_ns):
            edge.translations[k], edge.rotations[k] = t, q / norm
        else:
            edge.stamps.insert(k, int(stamp_ns))
            edge.translations.insert(k, t)
            edge.rotations.insert(k, q / norm)
        if self.cache_ns is not None:
            drop = bisect.bisect_left(edge.stamps, edge.stamps[-1] - self.cache_ns)
            if drop:
                del edge.stamps[:drop], edge.translations[:drop], edge.rotations[:drop]

    # -- questions -------------------------------------------------------------------------------
    @property
    def frames(self) -> set[str]:
        return set(self._edges) | {e.parent for e in self._edges.values()}

    def parent(self, frame: str) -> str | None:
        e = self._edges.get(frame)
        return None if e is None else e.parent

    def is_static(self, child: str) -> bool:
        e = self._edges.get(child)
        return e is not None and e.static

    def _ancestors(self, frame: str) -> list[str]:
        out = [frame]
        while out[-1] in self._edges:
            nxt = self._edges[out[-1]].parent
            if nxt in out:
                raise InputError(f"the tf tree has a loop through {nxt!r}")
            out.append(nxt)
        return out

    def chain(self, target: str, source: str) -> tuple[list[str], list[str]]:
        """Frames from ``source`` up to the common ancestor and from ``target`` up to it (the edges
        a look-up composes); a :class:`TransformError` naming both frames when they are not connected."""
        up_s, up_t = self._ancestors(source), self._ancestors(target)
        common = next((f for f in up_s if f in up_t), None)
        if common is None:
            known = sorted(self.frames)
            raise TransformError(f"no chain of transforms from {target!r} to {source!r} (tree roots: "
                                 f"{up_t[-1]!r} and {up_s[-1]!r}; known frames: {', '.join(known) or 'none'})")
        return up_s[: up_s.index(common) + 1], up_t[: up_t.index(common) + 1]

    def lookup(self, target: str, source: str, times_ns) -> Lookup:
        """``target <- source`` at each of ``times_ns`` (see :class:`Lookup`)."""
        times = np.atleast_1d(np.asarray(times_ns, dtype=np.int64))
        up_s, up_t = self.chain(target, source)
        if times.size == 0:
            return Lookup(np.zeros((0, 3)), np.zeros((0, 4)), np.zeros(0, bool))
        t_s, q_s, ok_s = self._to_ancestor(up_s, times)
        t_t, q_t, ok_t = self._to_ancestor(up_t, times)
        # p_anc = R_s p_src + t_s = R_t p_tgt + t_t  ->  p_tgt = R_t^-1 (R_s p_src + t_s - t_t)
        valid = ok_s & ok_t
        n = times.size
        trans, quat = np.full((n, 3), np.nan), np.full((n, 4), np.nan)
        if valid.any():
            r_t_inv = Rotation.from_quat(q_t[valid]).inv()
            quat[valid] = (r_t_inv * Rotation.from_quat(q_s[valid])).as_quat()
            trans[valid] = r_t_inv.apply(t_s[valid] - t_t[valid])
        return Lookup(trans, quat, valid)

    def _to_ancestor(self, frames: list[str], times: np.ndarray):
        """Pose of ``frames[0]`` in ``frames[-1]`` at each time, composed edge by edge."""
        n = times.size
        trans = np.zeros((n, 3))
        rot = Rotation.from_quat(np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)))
        valid = np.ones(n, bool)
        for child in frames[:-1]:
            t_e, q_e, ok = self._edge_at(child, times)
            valid &= ok
            q_e = np.where(ok[:, None], q_e, [0.0, 0.0, 0.0, 1.0])
            r_e = Rotation.from_quat(q_e)
            # pose in the parent = edge o (pose in the child)
            trans = r_e.apply(trans) + np.where(ok[:, None], t_e, 0.0)
            rot = r_e * rot
        return trans, rot.as_quat().reshape(n, 4), valid

    def _edge_at(self, child: str, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        e = self._edges[child]
        stamps, tr, q = e.arrays()
        n = times.size
        if e.static:
            return np.tile(tr[0], (n, 1)), np.tile(q[0], (n, 1)), np.ones(n, bool)
        valid = (times >= stamps[0]) & (times <= stamps[-1])
        if stamps.size > 1:
            k = np.clip(np.searchsorted(stamps, times, side="right"), 1, stamps.size - 1)
            valid &= (stamps[k] - stamps[k - 1]) <= e.max_gap_ns()
        out_t, out_q = np.full((n, 3), np.nan), np.full((n, 4), np.nan)
        if not valid.any():
            return out_t, out_q, valid
        tq = times[valid]
        if stamps.size == 1:
            out_t[valid], out_q[valid] = tr[0], q[0]
            return out_t, out_q, valid
        x = (stamps - stamps[0]).astype(float)
        xq = (tq - stamps[0]).astype(float)
        out_t[valid] = np.column_stack([np.interp(xq, x, tr[:, j]) for j in range(3)])
        out_q[valid] = Slerp(x, Rotation.from_quat(q))(xq).as_quat()
        return out_t, out_q, valid

    def period_s(self, target: str, source: str) -> float:
        """The longest median period of the chain's dynamic edges (s; 0 for a static chain): how
        finely in time the chain's position is known."""
        up_s, up_t = self.chain(target, source)
        edges = [self._edges[c] for c in up_s[:-1] + up_t[:-1]]
        return max([e.period_ns() * 1e-9 for e in edges if not e.static], default=0.0)

    def gaps(self, target: str, source: str, start_ns: int, end_ns: int) -> list[Gap]:
        """Every stretch inside [start_ns, end_ns] where an edge of the chain ``target <- source`` has
        no transform (before its first stamp, after its last, or a gap longer than the limit)."""
        up_s, up_t = self.chain(target, source)
        out: list[Gap] = []
        for child in up_s[:-1] + up_t[:-1]:
            e = self._edges[child]
            if e.static:
                continue
            stamps = np.asarray(e.stamps, dtype=np.int64)
            if stamps[0] > start_ns:
                out.append(Gap(e.parent, child, int(start_ns), int(min(stamps[0], end_ns))))
            d = np.diff(stamps)
            for k in np.flatnonzero(d > e.max_gap_ns()):
                a, b = int(stamps[k]), int(stamps[k + 1])
                if b > start_ns and a < end_ns:
                    out.append(Gap(e.parent, child, max(a, int(start_ns)), min(b, int(end_ns))))
            if stamps[-1] < end_ns:
                out.append(Gap(e.parent, child, int(max(stamps[-1], start_ns)), int(end_ns)))
        return sorted(out, key=lambda g: g.start_ns)
