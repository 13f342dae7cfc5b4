"""GraspScore (DAGRRT paper, Alg. 2): force closure and epsilon quality of a set of contacts.

The grasp wrench space (GWS) is the convex hull of the primitive wrenches of all contacts
(Ferrari & Canny's Q1 / "L1" space: every contact may push with unit *normal* force, total
normal force <= 1). Each Coulomb cone is linearized by ``cone_edges`` edges
``n + mu * (cos a * t1 + sin a * t2)``. Force closure holds when the origin lies strictly inside
the hull; the epsilon quality is the radius of the largest origin-centred ball inside it, i.e. the
smallest wrench (in the normalized units below) that the grasp can resist in its weakest
direction. The hull is computed by Qhull (``scipy.spatial.ConvexHull``).

Choices, and why:
- Edges keep a unit normal component (not unit length), so a wider cone contains the narrower one
  (for an even ``cone_edges``) and epsilon never decreases when mu grows.
- Torques are taken about ``center`` (default: centroid of the contacts) and multiplied by
  ``1 / max |p - center|``. This makes torque and force comparable and epsilon unitless and
  independent of object size, so one ``gs_min`` works for small and large objects. Force closure
  itself does not depend on the reference point; epsilon does (pass the object's centre of mass if
  you know it).
- The cone polygon's orientation about each normal is built from the grasp's own geometry (contact
  offsets, other normals), never from world axes, so scores are exactly invariant to a rigid
  motion of the whole grasp: a grasp pair scores the same wherever the object stands, and callers
  may cache scores per grasp pair.
- ``min_contacts`` defaults to 3: two point contacts with friction can never resist a torque about
  the line joining them (their 6-D GWS is flat), and three non-collinear hard-finger contacts are
  the smallest set that can reach force closure in 3-D (Simox's GraspRrt also asks for 3). The
  hull test would find a flat GWS anyway; the count is a cheap early exit. The DAGRRT paper's per-hand
  minimum (n_contact^L, n_contact^R) is ``min_contacts_per_hand`` in ``dual_grasp_score``.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from humanoid_planner.core.scene.types import GraspSpec

DEFAULT_CONE_EDGES = 4
"""Edges per linearized friction cone (the planner's default too, PlannerOptions.cone_edges): the
inscribed pyramid keeps cos(pi/4) = 71 % of mu, so closure is never overstated, and scores 5x faster
than 8 edges (92 % of mu; Simox uses 8)."""

DEFAULT_MIN_CONTACTS = 3
"""Fewest contacts (both hands together) that can be force closure with hard-finger contacts."""

DEFAULT_MIN_CONTACTS_PER_HAND = 1
"""n_contact of the DAGRRT paper's Alg. 2: a hand that does not touch the object is not grasping it."""

INTERIOR_TOL = 1e-9
"""The origin must be this far inside every hull facet (wrench units ~1) to count as inside."""

RANK_TOL = 1e-9
"""Singular values below RANK_TOL * largest mean the wrenches span fewer than 6 dimensions."""


@dataclass(frozen=True)
class GraspQualityResult:
    """Outcome of a GraspScore evaluation; ``epsilon`` is 0 whenever ``force_closure`` is False."""

    force_closure: bool
    epsilon: float
    num_contacts: int

    @property
    def score(self) -> float:
        """The number DAGRRT compares with gs_min (the epsilon quality)."""
        return self.epsilon


def _as_points(a: object, name: str) -> np.ndarray:
    arr = np.asarray(a, dtype=float)
    if arr.ndim == 1 and arr.size == 0:
        arr = arr.reshape(0, 3)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (k, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return arr


def _validate(contacts, normals, friction, cone_edges, min_contacts, center):
    p = _as_points(contacts, "contacts")
    n = _as_points(normals, "normals")
    if n.shape != p.shape:
        raise ValueError(f"normals shape {n.shape} does not match contacts shape {p.shape}")
    norms = np.linalg.norm(n, axis=1)
    if np.any(norms < 1e-9):
        raise ValueError("normals must be non-zero (inward unit normals)")
    n = n / norms[:, None]
    mu = np.asarray(friction, dtype=float)
    if mu.ndim == 0:
        mu = np.full(len(p), float(mu))
    if mu.shape != (len(p),):
        raise ValueError(f"friction must be a scalar or shape ({len(p)},), got {mu.shape}")
    if not np.all(np.isfinite(mu)) or np.any(mu < 0):
        raise ValueError("friction coefficients must be finite and >= 0")
    if isinstance(cone_edges, bool) or int(cone_edges) != cone_edges or cone_edges < 3:
        raise ValueError(f"cone_edges must be an integer >= 3, got {cone_edges!r}")
    if isinstance(min_contacts, bool) or int(min_contacts) != min_contacts or min_contacts < 0:
        raise ValueError(f"min_contacts must be an integer >= 0, got {min_contacts!r}")
    c = None
    if center is not None:
        c = np.asarray(center, dtype=float)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise ValueError(f"center must be 3 finite numbers, got {np.asarray(center).tolist()}")
    return p, n, mu, int(cone_edges), int(min_contacts), c


def _tangent_bases(offsets: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tangent frames (t1, t2) at each contact, built only from the grasp's own vectors.

    t1 is the first of [own offset, other offsets, other normals] with a clear component in the
    tangent plane, so the frame moves with the grasp under any rigid motion. Only when every
    candidate is parallel to the normal (a grasp symmetric about one axis, never force closure)
    do we fall back to a world axis.
    """
    k = len(normals)
    roll = (np.arange(k)[:, None] + np.arange(k)[None, :]) % k  # row i: i, i+1, ...
    cand = np.concatenate([offsets[roll], normals[roll[:, 1:]]], axis=1)  # (k, C, 3)
    tang = cand - np.einsum("kcj,kj->kc", cand, normals)[..., None] * normals[:, None, :]
    tnorm = np.linalg.norm(tang, axis=2)
    cnorm = np.linalg.norm(cand, axis=2)
    ok = tnorm > 1e-6 * np.maximum(cnorm, 1e-12)
    ok &= cnorm > 1e-9
    first = np.argmax(ok, axis=1)
    has = ok[np.arange(k), first]
    t1 = tang[np.arange(k), first] / np.maximum(tnorm[np.arange(k), first], 1e-300)[:, None]
    if not np.all(has):  # world-axis fallback: the axis least aligned with the normal
        nb = normals[~has]
        axis = np.eye(3)[np.argmin(np.abs(nb), axis=1)]
        fb = np.cross(nb, axis)
        t1[~has] = fb / np.linalg.norm(fb, axis=1)[:, None]
    t2 = np.cross(normals, t1)
    return t1, t2


def primitive_wrenches(
    contacts: np.ndarray,
    normals: np.ndarray,
    friction: np.ndarray,
    center: np.ndarray,
    cone_edges: int = DEFAULT_CONE_EDGES,
) -> np.ndarray:
    """(k * cone_edges, 6) wrenches (force, torque / rho) of every cone edge, about ``center``.

    Inputs must already be validated: unit normals, ``friction`` of shape (k,).
    """
    offsets = contacts - center
    rho = float(np.max(np.linalg.norm(offsets, axis=1))) if len(contacts) else 0.0
    torque_scale = 1.0 / rho if rho > 1e-12 else 0.0
    t1, t2 = _tangent_bases(offsets, normals)
    ang = 2.0 * np.pi * np.arange(cone_edges) / cone_edges
    # (k, m, 3): n + mu (cos a t1 + sin a t2)
    forces = normals[:, None, :] + friction[:, None, None] * (
        np.cos(ang)[None, :, None] * t1[:, None, :] + np.sin(ang)[None, :, None] * t2[:, None, :]
    )
    torques = np.cross(offsets[:, None, :], forces) * torque_scale
    return np.concatenate([forces, torques], axis=2).reshape(-1, 6)


def wrench_space_epsilon(wrenches: np.ndarray) -> float:
    """Radius of the largest origin-centred ball inside conv(wrenches); 0 if the origin is not
    strictly inside or the set is degenerate (spans < 6 dimensions, Qhull cannot build it)."""
    if len(wrenches) < 7:
        return 0.0
    sv = np.linalg.svd(wrenches, compute_uv=False)
    if sv[0] <= 0.0 or sv[-1] < RANK_TOL * sv[0]:
        return 0.0
    try:
        hull = ConvexHull(wrenches)
    except (QhullError, ValueError):
        return 0.0
    # equations: unit outward normal a and offset b, a.x + b <= 0 inside; distance of 0 is -b.
    eps = float(np.min(-hull.equations[:, -1]))
    return eps if eps > INTERIOR_TOL else 0.0


def grasp_score(
    contacts: np.ndarray,
    normals: np.ndarray,
    friction: float | np.ndarray,
    *,
    cone_edges: int = DEFAULT_CONE_EDGES,
    min_contacts: int = DEFAULT_MIN_CONTACTS,
    center: np.ndarray | None = None,
) -> GraspQualityResult:
    """Force closure and epsilon quality of contacts (k, 3) with inward normals (k, 3).

    Frame-agnostic: any frame works as long as contacts, normals and ``center`` share it.
    ``friction`` is one Coulomb coefficient or one per contact. Bad input raises ValueError;
    too few or degenerate contacts give a zero score, never an exception.
    """
    p, n, mu, m, min_k, c = _validate(contacts, normals, friction, cone_edges, min_contacts, center)
    k = len(p)
    if k == 0 or k < min_k:
        return GraspQualityResult(False, 0.0, k)
    if c is None:
        c = p.mean(axis=0)
    eps = wrench_space_epsilon(primitive_wrenches(p, n, mu, c, m))
    return GraspQualityResult(eps > 0.0, eps, k)


def _grasp_in_world(object_pose: np.ndarray, grasp: GraspSpec) -> tuple[np.ndarray, np.ndarray]:
    contacts = _as_points(grasp.contacts, f"grasp {grasp.id!r} contacts")
    normals = _as_points(grasp.normals, f"grasp {grasp.id!r} normals")
    if normals.shape != contacts.shape:
        raise ValueError(f"grasp {grasp.id!r}: {len(normals)} normals for {len(contacts)} contacts")
    R, t = object_pose[:3, :3], object_pose[:3, 3]
    return contacts @ R.T + t, normals @ R.T


def dual_grasp_score(
    object_pose: np.ndarray,
    left_grasp: GraspSpec,
    right_grasp: GraspSpec,
    default_friction: float,
    *,
    cone_edges: int = DEFAULT_CONE_EDGES,
    min_contacts: int = DEFAULT_MIN_CONTACTS,
    min_contacts_per_hand: int = DEFAULT_MIN_CONTACTS_PER_HAND,
    center: np.ndarray | None = None,
) -> GraspQualityResult:
    """The DAGRRT paper's Alg. 2: score the union of both hands' contacts, moved into the world frame.

    ``object_pose`` is T_world_object (4x4); each grasp's contacts and normals are in the object
    frame and its ``friction`` (0 = ``default_friction``) applies to its own contacts. Returns a
    zero score when either hand has fewer than ``min_contacts_per_hand`` contacts. Because the
    score is invariant to rigid motions, it does not depend on ``object_pose`` unless ``center``
    (world frame, default: centroid of all contacts) is given.
    """
    T = np.asarray(object_pose, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError("object_pose must be a finite 4x4 matrix")
    mus = []
    for g in (left_grasp, right_grasp):
        mu = float(g.friction) if g.friction else float(default_friction)
        if not np.isfinite(mu) or mu < 0:
            raise ValueError(f"grasp {g.id!r}: friction must be finite and >= 0, got {mu}")
        mus.append(mu)
    (pl, nl), (pr, nr) = _grasp_in_world(T, left_grasp), _grasp_in_world(T, right_grasp)
    k = len(pl) + len(pr)
    if min(len(pl), len(pr)) < min_contacts_per_hand:
        return GraspQualityResult(False, 0.0, k)
    friction = np.concatenate([np.full(len(pl), mus[0]), np.full(len(pr), mus[1])])
    return grasp_score(
        np.vstack([pl, pr]), np.vstack([nl, nr]), friction,
        cone_edges=cone_edges, min_contacts=min_contacts, center=center,
    )


class DualGraspScorer:
    """Memoized ``dual_grasp_score`` for one plan: one Qhull run per grasp pair.

    A 6-D hull of 2 x 3 contacts x 8 edges takes ~10 ms, and DAGRRT meets the same pair again
    and again. The score does not depend on the object pose (see ``dual_grasp_score``), so the
    grasp pair alone is the key. Keys are the GraspSpec objects' identities (they are frozen and
    the cache keeps them alive); safe to share between DAGRRT's arm threads.
    """

    def __init__(self, default_friction: float, **score_kwargs) -> None:
        if score_kwargs.get("center") is not None:
            raise ValueError("a fixed world-frame center would make the score pose-dependent")
        self._default_friction = float(default_friction)
        self._kwargs = score_kwargs
        self._cache: dict[tuple[int, int], tuple[GraspSpec, GraspSpec, GraspQualityResult]] = {}
        self._lock = threading.Lock()

    def __call__(self, left_grasp: GraspSpec, right_grasp: GraspSpec) -> GraspQualityResult:
        key = (id(left_grasp), id(right_grasp))
        with self._lock:
            hit = self._cache.get(key)
        if hit is not None:
            return hit[2]
        result = dual_grasp_score(
            np.eye(4), left_grasp, right_grasp, self._default_friction, **self._kwargs
        )
        with self._lock:
            self._cache[key] = (left_grasp, right_grasp, result)
        return result
