"""GraspScore: textbook force-closure cases, monotonicity, invariance, degenerate and bad input."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from humanoid_planner.core.grasp.quality import (
    DualGraspScorer,
    GraspQualityResult,
    dual_grasp_score,
    grasp_score,
)
from humanoid_planner.core.scene.types import GraspSpec

A, B = 0.05, 0.03  # box half sizes (x, y)
X_NEG = np.array([-1.0, 0.0, 0.0])
X_POS = np.array([1.0, 0.0, 0.0])


def box_pinch():
    """Two fingers on the +x face, two on the -x face: a two-hand squeeze of a box."""
    p = np.array([[A, B, 0], [A, -B, 0], [-A, B, 0], [-A, -B, 0]], dtype=float)
    n = np.array([X_NEG, X_NEG, X_POS, X_POS])
    return p, n


def tripod():
    """Three contacts 120 degrees apart on a sphere's equator, pushing to the centre."""
    ang = np.deg2rad([0.0, 120.0, 240.0])
    p = 0.04 * np.stack([np.cos(ang), np.sin(ang), np.zeros(3)], axis=1)
    return p, -p / 0.04


def random_rigid(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    return Rotation.random(random_state=rng).as_matrix(), rng.uniform(-2, 2, 3)


# --- textbook cases ---------------------------------------------------------------------------

@pytest.mark.parametrize("grasp", [box_pinch, tripod])
def test_force_closure_with_friction(grasp):
    p, n = grasp()
    r = grasp_score(p, n, 0.5)
    assert r.force_closure and r.epsilon > 0.05
    assert r.num_contacts == len(p) and r.score == r.epsilon


def test_three_contacts_on_opposite_box_faces_is_closure():
    p = np.array([[A, B, 0], [A, -B, 0], [-A, 0, 0]], dtype=float)
    n = np.array([X_NEG, X_NEG, X_POS])
    assert grasp_score(p, n, 0.5).force_closure


def test_contacts_on_one_face_pushing_the_same_way_are_not_closure():
    p = np.array([[A, B, 0], [A, -B, 0], [A, 0, B], [A, 0, -B]], dtype=float)
    r = grasp_score(p, np.tile(X_NEG, (4, 1)), 1.0)
    assert r == GraspQualityResult(False, 0.0, 4)


def test_frictionless_contacts_are_not_closure():
    p, n = box_pinch()
    assert not grasp_score(p, n, 0.0).force_closure
    two = np.array([[A, 0, 0], [-A, 0, 0]], dtype=float)
    assert not grasp_score(two, np.array([X_NEG, X_POS]), 0.0, min_contacts=0).force_closure


def test_two_opposing_contacts_cannot_resist_torque_about_their_axis():
    two = np.array([[A, 0, 0], [-A, 0, 0]], dtype=float)
    r = grasp_score(two, np.array([X_NEG, X_POS]), 1.0, min_contacts=0)
    assert r == GraspQualityResult(False, 0.0, 2)


def test_epsilon_grows_with_friction():
    p, n = box_pinch()
    eps = [grasp_score(p, n, mu).epsilon for mu in (0.1, 0.2, 0.35, 0.5, 0.8, 1.2)]
    assert all(b > a for a, b in zip(eps, eps[1:])), eps


def test_per_contact_friction_and_center():
    p, n = box_pinch()
    uniform = grasp_score(p, n, 0.5)
    assert grasp_score(p, n, np.full(4, 0.5)).epsilon == pytest.approx(uniform.epsilon)
    weaker = grasp_score(p, n, np.array([0.5, 0.5, 0.5, 0.1]))
    assert 0 < weaker.epsilon < uniform.epsilon
    # force closure does not depend on the torque reference point; epsilon may
    assert grasp_score(p, n, 0.5, center=[0.0, 0.0, 0.02]).force_closure


def test_non_unit_normals_are_normalized():
    p, n = box_pinch()
    assert grasp_score(p, 3.0 * n, 0.5).epsilon == pytest.approx(grasp_score(p, n, 0.5).epsilon)


# --- invariance --------------------------------------------------------------------------------

@pytest.mark.parametrize("grasp", [box_pinch, tripod])
def test_rigid_transform_invariance(grasp):
    p, n = grasp()
    ref = grasp_score(p, n, 0.4)
    rng = np.random.default_rng(7)
    for _ in range(5):
        R, t = random_rigid(rng)
        r = grasp_score(p @ R.T + t, n @ R.T, 0.4)
        assert r.force_closure == ref.force_closure
        assert r.epsilon == pytest.approx(ref.epsilon, rel=1e-6, abs=1e-9)


def test_uniform_scaling_invariance():
    p, n = tripod()
    assert grasp_score(10 * p, n, 0.5).epsilon == pytest.approx(grasp_score(p, n, 0.5).epsilon)


contacts_strategy = st.integers(min_value=3, max_value=6).flatmap(
    lambda k: st.tuples(
        st.lists(st.floats(-1, 1), min_size=3 * k, max_size=3 * k),
        st.lists(st.floats(-1, 1), min_size=3 * k, max_size=3 * k),
    )
)


@settings(max_examples=25, deadline=None)
@given(
    data=contacts_strategy,
    mu=st.floats(0.05, 1.0),
    seed=st.integers(0, 2**32 - 1),
)
def test_property_rigid_motion_keeps_force_closure_and_epsilon(data, mu, seed):
    p = np.asarray(data[0]).reshape(-1, 3)
    n = -p + 0.3 * np.asarray(data[1]).reshape(-1, 3)  # roughly inward, perturbed
    if np.any(np.linalg.norm(n, axis=1) < 1e-3):
        return
    ref = grasp_score(p, n, mu)
    R, t = random_rigid(np.random.default_rng(seed))
    r = grasp_score(p @ R.T + t, n @ R.T, mu)
    assert r.epsilon == pytest.approx(ref.epsilon, rel=1e-5, abs=1e-7)
    if min(r.epsilon, ref.epsilon) > 1e-6 or max(r.epsilon, ref.epsilon) == 0.0:
        assert r.force_closure == ref.force_closure


# --- degenerate inputs: score 0, no exception ----------------------------------------------------

@pytest.mark.parametrize(
    "p, n",
    [
        (np.zeros((0, 3)), np.zeros((0, 3))),  # no contacts
        (np.array([[A, 0, 0]]), np.array([X_NEG])),  # one
        (np.array([[A, 0, 0], [-A, 0, 0]]), np.array([X_NEG, X_POS])),  # below min_contacts
        (np.array([[A, 0, 0], [-A, 0, 0], [2 * A, 0, 0]]), np.array([X_NEG, X_POS, X_NEG])),  # collinear
        (np.tile([A, 0, 0], (4, 1)), np.tile(X_NEG, (4, 1))),  # coincident
        (np.zeros((4, 3)), np.array([X_NEG, X_POS, X_NEG, X_POS])),  # all at the centre
    ],
)
def test_degenerate_sets_score_zero(p, n):
    r = grasp_score(p, n, 0.8)
    assert r.force_closure is False and r.epsilon == 0.0 and r.num_contacts == len(p)


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(contacts=np.full((3, 3), np.nan), normals=np.ones((3, 3)), friction=0.5),
        dict(contacts=np.ones((3, 2)), normals=np.ones((3, 2)), friction=0.5),
        dict(contacts=np.ones((3, 3)), normals=np.ones((2, 3)), friction=0.5),
        dict(contacts=np.ones((3, 3)), normals=np.zeros((3, 3)), friction=0.5),
        dict(contacts=np.ones((3, 3)), normals=np.ones((3, 3)), friction=-0.1),
        dict(contacts=np.ones((3, 3)), normals=np.ones((3, 3)), friction=np.ones(2)),
        dict(contacts=np.ones((3, 3)), normals=np.ones((3, 3)), friction=np.inf),
        dict(contacts=np.ones((3, 3)), normals=np.ones((3, 3)), friction=0.5, cone_edges=2),
        dict(contacts=np.ones((3, 3)), normals=np.ones((3, 3)), friction=0.5, center=[0, np.nan, 0]),
    ],
)
def test_bad_input_raises_value_error(kwargs):
    with pytest.raises(ValueError):
        grasp_score(**kwargs)


# --- dual-hand helper ----------------------------------------------------------------------------

def hand(side: float, friction: float = 0.0, gid: str = "") -> GraspSpec:
    """Three fingertips of one hand on the box face x = side * A, normals pointing into the box."""
    p = np.array([[A, B, 0.01], [A, -B, 0.01], [A, 0.0, -0.02]]) * [side, 1, 1]
    return GraspSpec(gid or f"h{side}", "", np.eye(4), p, np.tile([-side, 0.0, 0.0], (3, 1)), friction)


def pose(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def test_dual_grasp_of_a_box_is_closure_wherever_the_box_is():
    left, right = hand(1.0), hand(-1.0)
    at_origin = dual_grasp_score(np.eye(4), left, right, 0.35)
    assert at_origin.force_closure and at_origin.num_contacts == 6
    R, t = random_rigid(np.random.default_rng(3))
    moved = dual_grasp_score(pose(R, t), left, right, 0.35)
    assert moved.epsilon == pytest.approx(at_origin.epsilon, rel=1e-9)


def test_dual_grasp_uses_each_hands_friction_then_default():
    base = dual_grasp_score(np.eye(4), hand(1.0), hand(-1.0), 0.35).epsilon
    own = dual_grasp_score(np.eye(4), hand(1.0, 0.8), hand(-1.0, 0.8), 0.35).epsilon
    assert own > base > 0


def test_dual_grasp_needs_contacts_from_both_hands():
    empty = GraspSpec("none", "", np.eye(4))
    r = dual_grasp_score(np.eye(4), hand(1.0), empty, 0.5)
    assert r == GraspQualityResult(False, 0.0, 3)
    # with the per-hand minimum relaxed the right hand alone (one face) is still not closure
    assert not dual_grasp_score(np.eye(4), hand(1.0), empty, 0.5, min_contacts_per_hand=0).force_closure


def test_dual_grasp_bad_input():
    bad = GraspSpec("bad", "", np.eye(4), np.ones((3, 3)), np.ones((2, 3)))
    with pytest.raises(ValueError):
        dual_grasp_score(np.eye(4), hand(1.0), bad, 0.5)
    with pytest.raises(ValueError):
        dual_grasp_score(np.full((4, 4), np.nan), hand(1.0), hand(-1.0), 0.5)
    with pytest.raises(ValueError):
        dual_grasp_score(np.eye(4), hand(1.0), hand(-1.0), -1.0)


def test_scorer_caches_per_grasp_pair():
    scorer = DualGraspScorer(0.35)
    left, right = hand(1.0), hand(-1.0)
    first = scorer(left, right)
    assert scorer(left, right) is first
    assert first.epsilon == dual_grasp_score(np.eye(4), left, right, 0.35).epsilon
    assert not scorer(left, GraspSpec("none", "", np.eye(4))).force_closure
