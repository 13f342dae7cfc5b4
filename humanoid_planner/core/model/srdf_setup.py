"""A MoveIt SRDF for a robot that ships none (or one without groups), written as MoveIt Setup Assistant
would: the `planner_setup` command (docs/ROBOTS.md).

- Arms: from given shoulder and hand links, or detected (a robot without a mirrored pair gets one arm:
  the longest unbranched chain of >= 4 joints, groups `arm` / `hand` / `arm_torso`, as Panda's SRDF names them). Detection looks for the mirrored pair of
  limbs (the same number of joints, first links on opposite sides of the parent link) that
  branch off highest above the root at the reference pose: the legs branch off the pelvis, the arms
  off the torso. Left is what the two limbs' names say (left/right, L/R, l_/r_ at a word start), else
  the side of the robot's left as its named limb pairs give it, else the root frame's +y (REP 103); a
  root frame need not face forward (iCub's faces backwards). An arm runs from its first link down its serial chain until the chain branches into
  fingers or ends (the hand); its TCP is a tool frame at the hand when there is one (a link without
  geometry or children named like tcp / tool / grasp / gripper / hand / palm), else the hand link.
- Groups `left_arm` / `right_arm` (chain from the torso to the TCP), `torso` and `*_arm_torso` (from
  the link below the first waist joint) when joints lie between the root and the arms, `left_hand` /
  `right_hand` (the hand's links), `whole_body` (every joint, for the `home` state).
- End effectors `left_hand` / `right_hand` (MoveIt's convention: named like their link group).
- `home`: the input SRDF's reference pose (`--home-state`, else its `home`, else `half_sitting`, else
  its first group_state), else the zero pose clipped to the limits.
- disable_collisions as Setup Assistant computes them (moveit_setup_srdf_plugins'
  compute_default_collisions): Adjacent (parent-child links with geometry; links without geometry
  connect their neighbours), Default (colliding at home), then over `samples` random configurations
  Always (colliding in >= 95 %) and Never (never colliding); plus every pair the input SRDF disables.
  Exact FCL on the collision geometry decides; a bounding-sphere test per link pair skips FCL where
  the spheres are apart, and a pair stops being checked once it has been seen both colliding and
  (often enough) free.
Everything else in the input SRDF (its groups, end effectors, states, virtual joints) is kept; a
generated element replaces an input one of the same name.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import fcl
import numpy as np
from lxml import etree

from humanoid_planner.core.collision.geometry import RobotCollisionModel, fcl_transform
from humanoid_planner.core.model.robot import RobotModel

ALWAYS_FRACTION = 0.95  # Setup Assistant's min_collision_fraction: colliding this often = always
DEFAULT_SAMPLES = 10000  # Setup Assistant's default sampling density
TCP_NAME = re.compile(r"tcp|tool|grasp|gripper|hand|palm", re.IGNORECASE)
MIN_ARM_JOINTS = 4  # an arm reaching a pose needs several joints; shorter mirrored chains are grippers or heads
SIDES = ("left", "right")
HOME_STATE_NAMES = ("home", "half_sitting")


class SetupError(ValueError):
    """The robot's arms cannot be found or the given links do not make arms."""


@dataclass(frozen=True)
class Arm:
    """One arm: chain base (the torso link it hangs from), first moving link and TCP (the hand)."""

    side: str
    base_link: str
    shoulder_link: str
    tcp_link: str


@dataclass
class SetupResult:
    """What planner_setup found and wrote (the SRDF text plus a summary of its decisions)."""

    srdf: str
    arms: tuple[Arm, ...]
    waist_base: str | None
    home_source: str
    disabled: dict[str, int] = field(default_factory=dict)  # reason -> pairs


# ---------------------------------------------------------------------------------------- arms
def _substantive(robot: RobotModel, link: str) -> bool:
    """Does the subtree below `link` (included) hold a joint or collision geometry?"""
    return any(l in robot.collision_geometry or any(j.index >= 0 for j in robot.child_joints(l))
               for l in robot.subtree_links(link))


def _branches(robot: RobotModel, link: str) -> list[str]:
    return [j.child for j in robot.child_joints(link) if _substantive(robot, j.child)]


def _hand_root(robot: RobotModel, shoulder: str) -> tuple[str, int]:
    """Walk down from the arm's first link while the chain does not branch: (hand link, arm joints)."""
    link, joints = shoulder, int(robot.parent_joint(shoulder).index >= 0)
    while True:
        nxt = _branches(robot, link)
        if len(nxt) > 1:
            # rigid side branches (Baxter's *_visual links, sensors) do not end the arm when the one moving
            # branch goes on for >= 2 joints; fingers (several moving branches, or a one-joint one) do
            moving = [c for c in nxt if any(j.index >= 0 for l in robot.subtree_links(c)
                                            for j in ([robot.parent_joint(l)] if l == c else robot.child_joints(l)))]
            if len(moving) == 1 and _hand_root(robot, moving[0])[1] >= 2:
                nxt = moving
        if len(nxt) != 1:
            return link, joints
        link = nxt[0]
        joints += int(robot.parent_joint(link).index >= 0)


def _tcp(robot: RobotModel, hand: str) -> str:
    """A tool frame attached to the hand (no geometry, no children, a TCP-like name), else the hand."""
    frames = [j.child for j in robot.child_joints(hand) if j.index < 0 and j.child not in robot.collision_geometry
              and not robot.child_joints(j.child) and TCP_NAME.search(j.child)]
    return frames[0] if frames else hand


def _arm(robot: RobotModel, side: str, shoulder: str, hand: str | None) -> Arm:
    for name in (shoulder, hand):
        if name is not None and name not in robot.link_names:
            raise SetupError(f"{side} arm: no link {name!r} in the URDF")
    parent = robot.parent_joint(shoulder)
    if parent is None:
        raise SetupError(f"{side} arm: shoulder link {shoulder!r} is the root")
    if hand is None:
        hand = _tcp(robot, _hand_root(robot, shoulder)[0])
    if hand != shoulder and shoulder not in robot.ancestors(hand):
        raise SetupError(f"{side} arm: hand link {hand!r} is not below shoulder link {shoulder!r}")
    base = parent.parent
    if not any(j.index >= 0 for j in robot.chain_joints(base, hand)):
        raise SetupError(f"{side} arm: no joint moves between {base!r} and {hand!r}")
    return Arm(side, base, shoulder, hand)


def _is_word_start(name: str, i: int) -> bool:
    """Does a word start at name[i] (after a separator or a digit, or a camelCase capital)?"""
    return i == 0 or not name[i - 1].isalpha() or (name[i].isupper() and name[i - 1].islower())


def _left_by_name(a: str, b: str) -> bool | None:
    """True when `a` is `b` with a right-side marker turned left (left/right, L/R, l_/r_ at a word start),
    False for the reverse, None when the names do not say."""
    la, lb = a.lower(), b.lower()
    if len(la) - len(lb) not in (-1, 0, 1):
        return None
    for x, y, verdict in (("left", "right", True), ("right", "left", False), ("l", "r", True), ("r", "l", False)):
        for i in range(len(la)):
            if la.startswith(x, i) and _is_word_start(a, i) and la[:i] + y + la[i + len(x):] == lb:
                return verdict
    return None


def _named_left(robot: RobotModel, a: str, b: str) -> str | None:
    """The limb (first link a or b) whose names mark it left against the other's right, if they do.
    The first links are compared, then their parent joints, then the links down the two chains."""
    names = [(a, b), (robot.parent_joint(a).name, robot.parent_joint(b).name)]
    la, lb = a, b
    while True:
        ca, cb = _branches(robot, la), _branches(robot, lb)
        if len(ca) != 1 or len(cb) != 1:
            break
        la, lb = ca[0], cb[0]
        names.append((la, lb))
    for na, nb in names:
        verdict = _left_by_name(na, nb)
        if verdict is not None:
            return a if verdict else b
    return None


def detect_arms(robot: RobotModel, q_ref: np.ndarray) -> dict[str, str]:
    """{side: first link of that arm}: the mirrored limb pair that branches off highest (see module doc).
    Left is what the pair's names say (left/right, L/R, l_/r_), else the side of the robot's left axis: the
    right-to-left direction of the limb pairs whose names say it (an iCub's root frame faces backwards),
    else the root frame's +y (REP 103)."""
    links = list(robot.link_names)
    P = robot.link_poses(q_ref, links)
    pos = {l: P[i, :3, 3] for i, l in enumerate(links)}
    pairs = []
    for branch in links:
        limbs = []
        for child in _branches(robot, branch):
            hand, n = _hand_root(robot, child)
            if n >= MIN_ARM_JOINTS:
                limbs.append((child, n))
        for i, (a, na) in enumerate(limbs):
            for b, nb in limbs[i + 1:]:
                ya, yb = pos[a][1] - pos[branch][1], pos[b][1] - pos[branch][1]
                if na == nb and ya * yb < 0:
                    pairs.append((pos[branch][2], branch, a, b, _named_left(robot, a, b)))
    if not pairs:
        raise SetupError(f"no pair of mirrored limbs with >= {MIN_ARM_JOINTS} joints found in {robot.name!r}; "
                         "give the arms' shoulder and hand links")
    _, _, a, b, named = max(pairs, key=lambda p: p[:4])
    if named is None:
        axes = [pos[l] - pos[q if l == p else p] for *_, p, q, l in pairs if l is not None]
        left_axis = np.sum(axes, axis=0) if axes else np.array([0.0, 1.0, 0.0])
        named = a if (pos[a] - pos[b]) @ left_axis > 0 else b
    return {"left": named, "right": b if named == a else a}


def detect_single_arm(robot: RobotModel) -> str:
    """First link of the one arm of a robot without a mirrored pair (Panda, UR, Kinova, TIAGo): the start of
    the longest unbranched chain of >= MIN_ARM_JOINTS joints (the highest such start when chains tie)."""
    best: tuple[int, int, str] | None = None
    for link in robot.link_names:
        parent = robot.parent_joint(link)
        if parent is None or parent.index < 0:
            continue
        _, n = _hand_root(robot, link)
        if n >= MIN_ARM_JOINTS and (best is None or (n, -len(robot.ancestors(link))) > best[:2]):
            best = (n, -len(robot.ancestors(link)), link)
    if best is None:
        raise SetupError(f"no arm found in {robot.name!r}: neither a pair of mirrored limbs nor one unbranched "
                         f"chain of >= {MIN_ARM_JOINTS} joints; give the arms' shoulder and hand links")
    return best[2]


def _group_name(arm: Arm, what: str) -> str:
    """'left_arm' / 'right_hand' for a pair of arms; 'arm' / 'hand' for a single arm (MoveIt's Panda names)."""
    return f"{arm.side}_{what}" if arm.side else what


def _waist_base(robot: RobotModel, arms: tuple[Arm, ...]) -> str | None:
    """The link just above the first joint between the root and the arms' common base (None: no waist)."""
    base = arms[0].base_link
    if any(a.base_link != base for a in arms):
        return None
    joints = [j for j in robot.chain_joints(robot.root_link, base) if j.index >= 0] if base != robot.root_link else []
    return joints[0].parent if joints else None


# ---------------------------------------------------------------------------------------- collisions
def adjacent_pairs(robot: RobotModel) -> set[frozenset[str]]:
    """Setup Assistant's Adjacent pairs: links joined by a joint, where a link without geometry joins
    all its neighbours to each other (so it is as if it were not there)."""
    nbrs: dict[str, set[str]] = {l: set() for l in robot.link_names}
    for j in robot.joints.values():
        nbrs[j.parent].add(j.child)
        nbrs[j.child].add(j.parent)
    geo = robot.collision_geometry
    # a geometry-less link joins its neighbours; chains of them need repeats until nothing changes
    changed = True
    while changed:
        changed = False
        for l in robot.link_names:
            if l not in geo:
                for a in list(nbrs[l]):
                    new = nbrs[l] - {a} - nbrs[a]
                    if new:
                        nbrs[a] |= new
                        changed = True
    return {frozenset((a, b)) for a in geo for b in nbrs[a] if b in geo and a != b}


class _PairChecker:
    """Exact FCL between two links' collision geometry at given link poses, with a bounding-sphere test.
    The geometries and fcl objects are the collision checker's (RobotCollisionModel: the same fcl shapes,
    mesh BVHs built once per robot, objects lent by its pool), so a pair is decided as a checker decides it."""

    def __init__(self, robot: RobotModel):
        model = RobotCollisionModel.for_robot(robot)
        self.links = sorted(robot.collision_geometry)
        self.objects: dict[str, list[tuple[fcl.CollisionObject, np.ndarray]]] = {}
        self.center: dict[str, np.ndarray] = {}
        self.radius: dict[str, float] = {}
        loan = model.objects.loan(self)  # objects back to the pool when this checker is collected
        for l in self.links:
            lc = model.links[l]
            self.objects[l] = [(loan.object(geom), g.origin) for geom, g in zip(lc.fcl_geoms, lc.shapes)]
            P = np.vstack([_bounding_points(g) for g in lc.shapes])
            c = (P.min(axis=0) + P.max(axis=0)) / 2
            self.center[l] = c
            self.radius[l] = float(np.max(np.linalg.norm(P - c, axis=1)))
        self.request = fcl.CollisionRequest()

    def collide(self, a: str, b: str, Ta: np.ndarray, Tb: np.ndarray) -> bool:
        for oa, Oa in self.objects[a]:
            oa.setTransform(fcl_transform(Ta @ Oa))
            for ob, Ob in self.objects[b]:
                ob.setTransform(fcl_transform(Tb @ Ob))
                if fcl.collide(oa, ob, self.request, fcl.CollisionResult()):
                    return True
        return False


def _bounding_points(g) -> np.ndarray:
    """Points whose hull holds the shape, in the link frame."""
    if g.kind == "mesh":
        local = g.vertices
    elif g.kind == "box":
        local = np.array(np.meshgrid(*[(-d / 2, d / 2) for d in g.dims])).reshape(3, -1).T
    elif g.kind == "sphere":
        r = g.dims[0]
        local = np.array([[sx * r, sy * r, sz * r] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    else:  # cylinder (radius, length) along z
        r, h = g.dims
        local = np.array([[sx * r, sy * r, sz * h / 2] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    return local @ g.origin[:3, :3].T + g.origin[:3, 3]


def sampled_pairs(robot: RobotModel, q_home: np.ndarray, samples: int, seed: int = 0,
                  skip: set[frozenset[str]] = frozenset(), chunk: int = 500,
                  ) -> tuple[set[frozenset[str]], set[frozenset[str]], set[frozenset[str]]]:
    """(Default, Always, Never) pairs among the links with geometry, `skip` left out: colliding at
    q_home; colliding in >= ALWAYS_FRACTION of `samples` uniform random configurations; never."""
    chk = _PairChecker(robot)
    links = chk.links
    li = {l: i for i, l in enumerate(links)}
    pairs = [(a, b) for i, a in enumerate(links) for b in links[i + 1:] if frozenset((a, b)) not in skip]
    home = robot.link_poses(q_home, links)
    default = {frozenset(p) for p in pairs if chk.collide(p[0], p[1], home[li[p[0]]], home[li[p[1]]])}
    pairs = [p for p in pairs if frozenset(p) not in default]
    if samples <= 0 or not pairs:
        return default, set(), set()
    A = np.array([li[a] for a, _ in pairs])
    B = np.array([li[b] for _, b in pairs])
    centers = np.array([chk.center[l] for l in links])
    rsum = np.array([chk.radius[a] + chk.radius[b] for a, b in pairs])
    hits = np.zeros(len(pairs), dtype=np.int64)
    free = np.zeros(len(pairs), dtype=np.int64)  # configurations known free so far
    max_free = samples - int(np.ceil(ALWAYS_FRACTION * samples))  # more free than this: not "always"
    rng = np.random.default_rng(seed)
    done = 0
    while done < samples:
        n = min(chunk, samples - done)
        Q = rng.uniform(robot.lower, robot.upper, size=(n, robot.dof))
        T = robot.link_poses(Q, links)  # (n, L, 4, 4)
        C = np.einsum("nlij,lj->nli", T[:, :, :3, :3], centers) + T[:, :, :3, 3]
        near = np.linalg.norm(C[:, A] - C[:, B], axis=2) <= rsum  # (n, pairs)
        free += n - near.sum(axis=0)
        for k in np.nonzero(near.any(axis=0))[0]:
            a, b = pairs[k]
            for c in np.nonzero(near[:, k])[0]:
                if hits[k] > 0 and free[k] > max_free:
                    break  # neither never nor always: decided
                if chk.collide(a, b, T[c, A[k]], T[c, B[k]]):
                    hits[k] += 1
                else:
                    free[k] += 1
        done += n
    always = {frozenset(p) for k, p in enumerate(pairs) if free[k] <= max_free}
    never = {frozenset(p) for k, p in enumerate(pairs) if hits[k] == 0}
    return default, always, never


# ---------------------------------------------------------------------------------------- SRDF
def _home(robot: RobotModel, root, state: str | None) -> tuple[np.ndarray, str]:
    names = [g.get("name") for g in root.findall("group_state")] if root is not None else []
    if state is not None and state not in names:
        raise SetupError(f"no group_state {state!r} in the input SRDF; it has: {names}")
    pick = state or next((n for n in HOME_STATE_NAMES if n in names), names[0] if names else None)
    if pick is None:
        return np.clip(np.zeros(robot.dof), robot.lower, robot.upper), "zero pose (clipped to the limits)"
    return robot.state(pick), f"the input SRDF's group_state {pick!r}"


def generate_srdf(urdf: str | Path, srdf: str | Path | None = None, *,
                  shoulders: dict[str, str] | None = None, hands: dict[str, str] | None = None,
                  samples: int = DEFAULT_SAMPLES, seed: int = 0, home_state: str | None = None) -> SetupResult:
    """The SRDF text for a URDF (+ an optional input SRDF to merge with), see the module docstring.
    shoulders / hands: {"left": link, "right": link}; missing entries are detected."""
    robot = RobotModel.from_urdf_srdf(urdf, srdf)
    root = None
    if srdf is not None:
        text = Path(srdf).read_text() if isinstance(srdf, Path) or "<robot" not in str(srdf) else str(srdf)
        root = etree.fromstring(text.encode(), etree.XMLParser(remove_blank_text=True))
    q_home, home_source = _home(robot, root, home_state)
    shoulders, hands = dict(shoulders or {}), dict(hands or {})
    sides: tuple[str, ...] = SIDES
    if not shoulders and not hands:
        try:
            shoulders = detect_arms(robot, q_home)
        except SetupError:  # one arm (Panda, UR, Kinova, TIAGo): groups `arm` / `hand`
            shoulders, sides = {"": detect_single_arm(robot)}, ("",)
    elif any(s not in shoulders for s in SIDES):
        detected = detect_arms(robot, q_home)
        for s in SIDES:
            shoulders.setdefault(s, detected[s])
    arms = tuple(_arm(robot, s, shoulders[s], hands.get(s)) for s in sides)
    waist = _waist_base(robot, arms)

    out = etree.Element("robot", name=robot.name)
    generated: list = []
    for a in arms:
        generated.append(_group(_group_name(a, "arm"), chain=(a.base_link, a.tcp_link)))
    if waist is not None:
        generated.append(_group("torso", chain=(waist, arms[0].base_link)))
        for a in arms:
            generated.append(_group(_group_name(a, "arm_torso"), chain=(waist, a.tcp_link)))
    for a in arms:
        generated.append(_group(_group_name(a, "hand"), links=robot.subtree_links(a.tcp_link)))
    generated.append(_group("whole_body", joints=robot.joint_names))
    state = etree.Element("group_state", name="home", group="whole_body")
    for n, v in zip(robot.joint_names, q_home):
        etree.SubElement(state, "joint", name=n, value=f"{v:.6g}")
    generated.append(state)
    for a in arms:
        generated.append(etree.Element("end_effector", name=_group_name(a, "hand"), parent_link=a.tcp_link,
                                       group=_group_name(a, "hand"), parent_group=_group_name(a, "arm")))
    names = {(e.tag, e.get("name")) for e in generated}
    if root is not None:  # the input's own elements first, except what is generated or recomputed
        for e in root:
            if isinstance(e.tag, str) and e.tag != "disable_collisions" and (e.tag, e.get("name")) not in names:
                out.append(e)
    out.extend(generated)

    user: dict[frozenset[str], str] = {}
    if root is not None:
        for d in root.findall("disable_collisions"):
            user[frozenset((d.get("link1"), d.get("link2")))] = d.get("reason") or "User"
    adjacent = adjacent_pairs(robot)
    default, always, never = sampled_pairs(robot, q_home, samples, seed, skip=adjacent)
    reasons: dict[frozenset[str], str] = {}
    for reason, pairs in (("Never", never), ("Always", always), ("Default", default), ("Adjacent", adjacent)):
        reasons.update(dict.fromkeys(pairs, reason))
    for p, r in user.items():
        reasons.setdefault(p, r)
    counts: dict[str, int] = {}
    for p in sorted(reasons, key=lambda p: tuple(sorted(p))):
        a, b = sorted(p) if len(p) == 2 else (next(iter(p)),) * 2
        etree.SubElement(out, "disable_collisions", link1=a, link2=b, reason=reasons[p])
        counts[reasons[p]] = counts.get(reasons[p], 0) + 1
    etree.indent(out, space="  ")
    header = (f"<?xml version=\"1.0\"?>\n<!-- SRDF for {robot.name}, written by planner_setup (humanoid_planner) "
              f"from {samples} sampled configurations, seed {seed}; home: {home_source} -->\n")
    text = header + etree.tostring(out, encoding="unicode") + "\n"
    RobotModel.from_urdf_srdf(urdf, text)  # what we write must load
    return SetupResult(text, arms, waist, home_source, counts)


def _group(name: str, chain: tuple[str, str] | None = None, links=(), joints=()) -> etree._Element:  # noqa: SLF001 - lxml's element class has no public name
    g = etree.Element("group", name=name)
    if chain is not None:
        etree.SubElement(g, "chain", base_link=chain[0], tip_link=chain[1])
    for l in links:
        etree.SubElement(g, "link", name=l)
    for j in joints:
        etree.SubElement(g, "joint", name=j)
    return g

