"""Compiled (numba) FK and levels 1–2 of the collision checker: one pass per configuration.

The numpy levels (levels.py) cost ~0.5–1 ms of numpy call overhead per batch whatever its size, and a
tree search checks small batches (an edge's samples, one extension): that overhead, not the
arithmetic, bounded the checker at 15–40k configurations/s. These kernels do the same tests in one
compiled loop per configuration — FK of the group's frames, unit bounding spheres against fixed
boxes and other units (level 1), inner-sphere proofs against exact boxes and cover spheres against
rounded boxes (level 2) — and stop a configuration at its first proof. The same tests and thresholds
as levels.py (the numpy path, the reference the unit tests compare verdicts with), plus tests that
only pay compiled: the convex hulls of mesh shapes against exact boxes and each other, hull vertices
inside inner spheres, and a grid over many small bodies (levels_12's docstring). What is still open
leaves as the same (configuration, shape, body) entries for the pair tables and FCL (checker.py).
screen_batches runs a search's motion sample by sample in one call, levels and triangle tests, up to its
first collision or to what only FCL can decide (CollisionChecker.first_collision).
numba rather than a C extension: the kernels read the checker's own numpy arrays as they are, and
stay Python a reader can compare with levels.py; compiled once per install (`cache=True`, ~15 s: `make
test` and the node do it before any plan) and loaded from the cache afterwards (~0.5 s).
"""
from __future__ import annotations

import numba as nb
import numpy as np
from numba.core import types
from numba.experimental import structref

STATUS_FREE1, STATUS_HIT, STATUS_OPEN, STATUS_FREE2, STATUS_UNCHECKED = 0, 1, 2, 3, 4
"""Per configuration: cleared by level 1, proven colliding, entries left for FCL, cleared by level 2, not
checked (after the configuration a check that stops at the first collision stopped at)."""


@structref.register
class KernelDataType(types.StructRef):
    """The numba type of KernelData: one field per array (or flag) the kernel reads."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class KernelData(structref.StructRefProxy):
    """One checker's arrays for levels_12 (CompiledPairs.compiled_12 builds it once), made by make_kernel_data."""


KERNEL_FIELDS = ("cols", "parents", "prismatic", "basis", "unit_frame", "bound_c", "bound_r", "env_u", "env_e",
                 "env_R", "env_t", "env_h", "env_thr2", "fR", "ft", "fh", "frho", "f_pad", "f_tight", "fc_c",
                 "fc_r", "fc_n", "fi_c", "fi_r", "fi_n", "self_s", "self_o", "self_two", "self_thr2", "uR", "ut",
                 "uh", "urho", "u_tight", "out_c", "out_r", "out_n", "out_own", "in_c", "in_r", "in_n",
                 "shape_tab", "hv", "hv_n", "hp", "hp_n", "hv_pts", "sb_ok", "sb_h", "sb_rho", "shape_R", "shape_t",
                 "frame_of", "fhv", "fhv_n", "fhp", "fhp_n", "fib_ok", "fibR", "fibt", "fibh", "use_grid", "g_lo",
                 "g_step", "g_shape", "g_start", "g_body", "g_big", "g_query", "g_pair", "tab_cols", "tab_nd",
                 "tab_lo", "tab_step", "tab_lev", "tab_size", "tab_off", "tab_dist", "self_tab", "env_tab",
                 "cs_tab", "cl_frame", "cl_c", "use_cl_env", "ce_slot", "ce_R", "ce_t", "ce_h", "ce_thr2",
                 "ce_start", "ce_count", "ce_members", "use_cl_self", "cs_a", "cs_b", "cs_thr2", "cs_start",
                 "cs_count", "cs_members")
"""KernelData's fields: the kinematic tree, the pairs and their geometry (see _levels_12), the grid, the
clearance tables and the clusters."""
structref.define_proxy(KernelData, KernelDataType, KERNEL_FIELDS)


AXIS_ITERATIONS = 16
"""Frank–Wolfe iterations of _axis_apart before a pair of hulls is left to FCL. Random hulls 5 mm or more
apart along no face normal: 4 iterations prove 11 of 48 apart, 16 prove 38, 64 prove 47; TALOS l_arm near
contact: 6 iterations decide as many configurations as 16."""


@nb.njit(cache=True)
def make_kernel_data(*arrays):
    """KernelData of the arrays in KERNEL_FIELDS order; compiled (and cached) like the kernels, so that no
    checker pays numba's typing of the ~100 fields (~2 s)."""
    return KernelData(*arrays)


@nb.njit(cache=True, nogil=True)
def _box_d2(px, py, pz, bR, bt, bh) -> float:
    """Squared distance from the point (px, py, pz) to the box (rotation bR, centre bt, half extents bh);
    0 inside."""
    dx, dy, dz = px - bt[0], py - bt[1], pz - bt[2]
    d2 = 0.0
    for j in range(3):
        x = abs(dx * bR[0, j] + dy * bR[1, j] + dz * bR[2, j]) - bh[j]
        if x > 0.0:
            d2 += x * x
    return d2


@nb.njit(cache=True, nogil=True)
def _touch(cx, cy, cz, r, bR, bt, bh, rho) -> bool:
    """Sphere (centre, radius r) reaches the rounded box (rotation bR, centre bt, half extents bh,
    rounding rho); r + rho ≤ 0 never touches (signed square, as levels.touch)."""
    thr = r + rho
    return _box_d2(cx, cy, cz, bR, bt, bh) < thr * abs(thr)


@nb.njit(cache=True, nogil=True)
def _grow(a: np.ndarray, need: int) -> np.ndarray:
    if need <= a.shape[0]:
        return a
    b = np.empty((max(need, 2 * a.shape[0]), a.shape[1]), dtype=a.dtype)
    b[:a.shape[0]] = a
    return b


@nb.njit(cache=True, nogil=True)
def fk_batch(q, cols, parents, prismatic, basis, R, t) -> None:
    """Frames of configurations q (N, n) into R (N, F, 3, 3), t (N, F, 3): W_k = W_parent · L_k(q)
    (local_transform)."""
    N, F = q.shape[0], cols.shape[0]
    L = np.empty((3, 4))
    for n in range(N):
        for k in range(F):
            local_transform(basis, k, q[n, cols[k]], prismatic[k], L)
            p = parents[k]
            if p < 0:
                for i in range(3):
                    for j in range(3):
                        R[n, k, i, j] = L[i, j]
                    t[n, k, i] = L[i, 3]
            else:
                for i in range(3):
                    for j in range(3):
                        R[n, k, i, j] = R[n, p, i, 0] * L[0, j] + R[n, p, i, 1] * L[1, j] + R[n, p, i, 2] * L[2, j]
                    t[n, k, i] = (R[n, p, i, 0] * L[0, 3] + R[n, p, i, 1] * L[1, 3] + R[n, p, i, 2] * L[2, 3]
                                  + t[n, p, i])


@nb.njit(cache=True, nogil=True)
def local_transform(basis, k, x, prismatic, L) -> None:
    """Frame k's local transform K_k·M(x), its top three rows into L (3, 4), from KinematicTree's basis:
    u·A_k + v·B_k + C_k with (u, v) = (cos x, sin x), or (x, 0) when prismatic. The one form of it the
    compiled FK (fk_batch) and IK (ik/kernels.chain_pose) share."""
    if prismatic:
        u, v = x, 0.0
    else:
        u, v = np.cos(x), np.sin(x)
    for i in range(12):
        L[i // 4, i % 4] = u * basis[k, i, 0] + v * basis[k, i, 1] + basis[k, i, 2]


@nb.njit(cache=True, nogil=True)
def _levels_12(q, has_me, me, has_mp, mp, margin, self_padding, eps, stop_at_hit, cols, parents, prismatic, basis, unit_frame,
               bound_c, bound_r, env_u, env_e, env_R, env_t, env_h, env_thr2, fR, ft, fh, frho, f_pad, f_tight,
               fc_c, fc_r, fc_n, fi_c, fi_r, fi_n, self_s, self_o, self_two, self_thr2, uR, ut, uh, urho, u_tight,
               out_c, out_r, out_n, out_own, in_c, in_r, in_n, shape_tab, hv, hv_n, hp, hp_n, hv_pts, sb_ok, sb_h, sb_rho,
               shape_R, shape_t, frame_of, fhv, fhv_n, fhp, fhp_n, fib_ok, fibR, fibt, fibh, use_grid, g_lo,
               g_step, g_shape, g_start, g_body, g_big, g_query, g_pair, tab_cols, tab_nd, tab_lo, tab_step,
               tab_lev, tab_size, tab_off, tab_dist, self_tab, env_tab, cs_tab, cl_frame, cl_c, use_cl_env,
               ce_slot, ce_R, ce_t, ce_h, ce_thr2, ce_start, ce_count, ce_members, use_cl_self, cs_a, cs_b,
               cs_thr2, cs_start, cs_count, cs_members):
    """FK of configurations q (fk_batch; the tree's arrays), then per configuration, stopping at its first proof:
    - level 1: unit bounding spheres against the fixed bodies in reach (all pairs, or with use_grid the
      bodies in the grid cells a unit can reach: levels.PairGrid) and against the other units;
    - level 2, on what level 1 flags: inner spheres against exact boxes (proof of contact); cover spheres
      against rounded boxes (a fixed mesh's cover against the unit's box too) decide which shapes stay
      open; then, shape by shape, the hull of a mesh (vertices hv, face planes hp, frame coordinates;
      hv_n = 0: none) against an exact box (sb_*: a box or sphere shape of another unit; f_tight: a fixed
      one) — a vertex inside proves contact, an extent past a face (either side's) by more than the
      padding proves the pair apart; two hulls by their face planes (fhv / fhp: fixed meshes, world);
      inner spheres of both sides meeting, or a hull vertex within the other side's inner sphere or (fib_*:
      a fixed robot mesh's geometry.mesh_inner_box, world) inside its inner box, prove contact
      (levels.CompiledPairs.prove_inner's test, made here before the pair tables: a pair whose inner
      spheres meet has no table lower bound above its padding).
    Each configuration runs in two passes: level 1, the tables and the cheap proofs (inner spheres against an
    exact box or against the other side's inner spheres) of every pair, then the covers and hull tests of the
    pairs still flagged (colliding configurations of Panda: 3.6 → 1.2 µs each, most proven in the first pass).
    Level 1 visits the unit pairs under the cluster pairs that touch (levels.CompiledPairs.build_clusters:
    one sphere per cluster of a frame's units; use_cl_env / use_cl_self when the checker built them) and
    otherwise every pair: a robot of many small units (a spherized arm: 58 spheres, 648 unit pairs)
    spent most of its time in that loop.
    Before level 2, a pair flagged by level 1 that has a clearance table (self_tab[p] / env_tab[k] ≥ 0: a
    table of pair_tables.py, packed by levels.TablePack; cs_tab[g] for a cluster pair's unit pairs at once)
    is cleared when the table's lower bound of its
    exact distance exceeds the required clearance: the pairs next to each other on a chain (Panda's link5
    against link7 and the hand) touch at level 1 in most configurations, and their hull tests cost more
    than the rest of the configuration.
    me (N, U) / mp (N, P): edge margins per unit / self pair, read only when has_me / has_mp.
    Returns the frames R (N, F, 3, 3), t (N, F, 3), status (N,) (STATUS_*), the env entries (K, 3) =
    (config, moving shape, fixed body) and self entries (K', 4) = (config, shape, shape, pair) still open
    — none of a proven configuration — and how many pairs the tables cleared."""
    N, U, F = q.shape[0], unit_frame.shape[0], cols.shape[0]
    R, t = np.empty((N, F, 3, 3)), np.empty((N, F, 3))
    Q, P = env_u.shape[0], self_s.shape[0]
    S = shape_tab.shape[1]
    status = np.zeros(N, dtype=np.int8)
    env = np.empty((64, 3), dtype=np.int64)
    slf = np.empty((64, 4), dtype=np.int64)
    ne = 0
    ns = 0
    B = np.empty((U, 3))
    w = np.empty(3)  # a sphere's centre in the world
    cand = np.empty(Q, dtype=np.int64)  # one configuration's env pairs (from the grid or the clusters)
    pcand = np.empty(P, dtype=np.int64)  # ... self pairs (from the clusters)
    near = np.empty(Q, dtype=np.int64)  # one configuration's env pairs left after pass 1
    pnear = np.empty(P, dtype=np.int64)  # ... self pairs
    C = np.empty((cl_frame.shape[0], 3))  # cluster centres in the world
    I3, Z3 = np.eye(3), np.zeros(3)  # the world frame (fixed bodies)
    Ra, ta, Rb, tb = np.empty((3, 3)), np.empty(3), np.empty((3, 3)), np.empty(3)
    Wb = np.empty((max(in_c.shape[1], 1), 3))  # the other unit's inner spheres in the world
    zero_r = np.zeros(hv.shape[1])  # hull vertices as spheres of radius 0
    own_a = np.zeros(S, dtype=np.bool_)
    own_b = np.zeros(S, dtype=np.bool_)
    boxR = np.empty((3, 3))
    boxt = np.empty(3)
    boxR2 = np.empty((3, 3))
    boxt2 = np.empty(3)
    n_tab = 0
    for n in range(N):
        fk_batch(q[n:n + 1], cols, parents, prismatic, basis, R[n:n + 1], t[n:n + 1])  # none past a stop
        for u in range(U):
            f = unit_frame[u]
            for i in range(3):
                B[u, i] = (R[n, f, i, 0] * bound_c[u, 0] + R[n, f, i, 1] * bound_c[u, 1]
                           + R[n, f, i, 2] * bound_c[u, 2] + t[n, f, i])
        if use_cl_env or use_cl_self:
            for c in range(cl_frame.shape[0]):
                f = cl_frame[c]
                for i in range(3):
                    C[c, i] = (R[n, f, i, 0] * cl_c[c, 0] + R[n, f, i, 1] * cl_c[c, 1]
                               + R[n, f, i, 2] * cl_c[c, 2] + t[n, f, i])
        e0, s0 = ne, ns
        flagged = False
        hit = False
        # ---- units against fixed bodies
        nk = Q
        listed = use_grid or use_cl_env
        if use_grid:  # many bodies: the pairs listed in each unit's cell (levels.PairGrid)
            nk = 0
            for u in range(U):
                for j in range(g_big.shape[0]):
                    k = g_pair[u, g_big[j]]
                    if k >= 0:
                        cand[nk] = k
                        nk += 1
                r = g_query[u]
                x0 = max(int(np.floor((B[u, 0] - r - g_lo[0]) / g_step)), 0)
                x1 = min(int(np.floor((B[u, 0] + r - g_lo[0]) / g_step)), g_shape[0] - 1)
                y0 = max(int(np.floor((B[u, 1] - r - g_lo[1]) / g_step)), 0)
                y1 = min(int(np.floor((B[u, 1] + r - g_lo[1]) / g_step)), g_shape[1] - 1)
                z0 = max(int(np.floor((B[u, 2] - r - g_lo[2]) / g_step)), 0)
                z1 = min(int(np.floor((B[u, 2] + r - g_lo[2]) / g_step)), g_shape[2] - 1)
                for ix in range(x0, x1 + 1):
                    for iy in range(y0, y1 + 1):
                        c0 = (ix * g_shape[1] + iy) * g_shape[2]
                        for j in range(g_start[c0 + z0], g_start[c0 + z1 + 1] if z1 >= z0 else g_start[c0 + z0]):
                            k = g_pair[u, g_body[j]]
                            if k >= 0:
                                cand[nk] = k
                                nk += 1
        elif use_cl_env:  # the unit pairs under the cluster–body pairs that touch
            nk = 0
            for g in range(ce_slot.shape[0]):
                c = ce_slot[g]
                if _box_d2(C[c, 0], C[c, 1], C[c, 2], ce_R[g], ce_t[g], ce_h[g]) < ce_thr2[g]:
                    for j in range(ce_start[g], ce_start[g] + ce_count[g]):
                        cand[nk] = ce_members[j]
                        nk += 1
        # pass 1: level 1, the tables and the cheap proofs (inner spheres against an exact box or against
        # inner spheres) of every flagged pair, env pairs then self pairs; pass 2: covers and hulls of the pairs
        # left. A colliding configuration then rarely pays the hull tests of pairs that are apart.
        nf = 0
        for kk in range(nk):
            k = cand[kk] if listed else kk
            u = env_u[k]
            if _box_d2(B[u, 0], B[u, 1], B[u, 2], env_R[k], env_t[k], env_h[k]) >= env_thr2[k]:
                continue
            flagged = True
            e = env_e[k]
            f = unit_frame[u]
            mu = me[n, u] if has_me else 0.0
            if env_tab[k] >= 0 and _table_lb(q, n, env_tab[k], tab_cols, tab_nd, tab_lo, tab_step, tab_lev, tab_size,
                                             tab_off, tab_dist) > f_pad[e] + mu + eps:
                n_tab += 1
                continue
            if f_tight[e] and in_n[u] > 0:  # proof: an inner sphere reaches the exact box
                thr = f_pad[e] + mu - eps
                for i in range(in_n[u]):
                    _world(R, t, n, f, in_c[u, i], w)
                    if _touch(w[0], w[1], w[2], in_r[u, i] + thr, fR[e], ft[e], fh[e], frho[e]):
                        hit = True
                        break
                if hit:
                    break
            if not f_tight[e] and in_n[u] > 0 and fi_n[e] > 0:
                # inner spheres of both sides meet: a mesh or cylinder the box does not fit exactly
                if _inner_meet(R, t, n, f, in_c[u], in_r[u], in_n[u], fi_c[e], fi_r[e], fi_n[e],
                               f_pad[e] + mu - eps, w):
                    hit = True
                    break
            near[nf] = k
            nf += 1
        # ---- unit against unit
        npc = P
        cs_margin = 2 * margin + 1e-9 if has_mp else 0.0  # the largest edge margin a self pair may ask (check_configs)
        if not hit and use_cl_self:  # the unit pairs under the cluster pairs that touch
            npc = 0
            for g in range(cs_a.shape[0]):
                ca, cb = cs_a[g], cs_b[g]
                dx, dy, dz = C[ca, 0] - C[cb, 0], C[ca, 1] - C[cb, 1], C[ca, 2] - C[cb, 2]
                if dx * dx + dy * dy + dz * dz < cs_thr2[g]:
                    # a cluster pair its table clears counts as cleared by level 1 (in the stats only)
                    if cs_tab[g] >= 0 and _table_lb(q, n, cs_tab[g], tab_cols, tab_nd, tab_lo, tab_step, tab_lev,
                                                    tab_size, tab_off, tab_dist) > self_padding + cs_margin + eps:
                        n_tab += 1
                        continue
                    for j in range(cs_start[g], cs_start[g] + cs_count[g]):
                        pcand[npc] = cs_members[j]
                        npc += 1
        nsf = 0
        if not hit:
            for pp in range(npc):
                p = pcand[pp] if use_cl_self else pp
                a, b = self_s[p], self_o[p]
                dx, dy, dz = B[a, 0] - B[b, 0], B[a, 1] - B[b, 1], B[a, 2] - B[b, 2]
                if dx * dx + dy * dy + dz * dz >= self_thr2[p]:
                    continue
                fa, fb = unit_frame[a], unit_frame[b]
                reach = self_padding + 2 * margin + eps
                _unit_box(R, t, n, fb, uR[b], ut[b], boxR, boxt)
                if not _touch(B[a, 0], B[a, 1], B[a, 2], bound_r[a] + reach, boxR, boxt, uh[b], urho[b]):
                    continue
                # the other way round too: a small unit's sphere against a big one's box (TIAGo's 41 hand links
                # against its torso column, whose sphere reaches all of them: 7 of its 10.6 µs per configuration)
                _unit_box(R, t, n, fa, uR[a], ut[a], boxR2, boxt2)
                if not _touch(B[b, 0], B[b, 1], B[b, 2], bound_r[b] + reach, boxR2, boxt2, uh[a], urho[a]):
                    continue
                flagged = True
                mpv = mp[n, p] if has_mp else 0.0
                if self_tab[p] >= 0 and _table_lb(q, n, self_tab[p], tab_cols, tab_nd, tab_lo, tab_step, tab_lev,
                                                  tab_size, tab_off, tab_dist) > self_padding + mpv + eps:
                    n_tab += 1
                    continue
                if u_tight[b] and in_n[a] > 0:
                    thr = self_padding + mpv - eps
                    for i in range(in_n[a]):
                        _world(R, t, n, fa, in_c[a, i], w)
                        if _touch(w[0], w[1], w[2], in_r[a, i] + thr, boxR, boxt, uh[b], urho[b]):
                            hit = True
                            break
                    if hit:
                        break
                if not u_tight[b] and in_n[b] > 0 and in_n[a] > 0:  # inner spheres of both sides meet
                    for i in range(in_n[b]):
                        _world(R, t, n, fb, in_c[b, i], Wb[i])
                    if _inner_meet(R, t, n, fa, in_c[a], in_r[a], in_n[a], Wb, in_r[b], in_n[b],
                                   self_padding + mpv - eps, w):
                        hit = True
                        break
                pnear[nsf] = p
                nsf += 1
        if not hit:  # pass 2, env pairs
            for kk in range(nf):
                k = near[kk]
                u = env_u[k]
                e = env_e[k]
                f = unit_frame[u]
                mu = me[n, u] if has_me else 0.0
                pad = f_pad[e] + mu + eps
                any_a = _covers(R, t, n, f, out_c[u], out_r[u], out_n[u], out_own[u], fR[e], ft[e], fh[e], frho[e], pad,
                                own_a, w)
                if any_a and fc_n[e] > 0:  # a fixed mesh: its cover against the unit's box too
                    _unit_box(R, t, n, f, uR[u], ut[u], boxR, boxt)
                    back = False
                    for j in range(fc_n[e]):
                        if _touch(fc_c[e, j, 0], fc_c[e, j, 1], fc_c[e, j, 2], fc_r[e, j] + pad, boxR, boxt, uh[u], urho[u]):
                            back = True
                            break
                    any_a = back
                if any_a and f_tight[e]:  # hull vertices of meshes against the exact box
                    v = _prune_by_hulls(R, t, n, f, shape_tab[u], own_a, hv, hv_n, hp, hp_n, hv_pts, fR[e], ft[e], fh[e], frho[e],
                                        pad, eps)
                    if v > 0:
                        hit = True
                        break
                    any_a = v == 0
                if any_a and fhv_n[e] > 0:  # a fixed mesh: hull against hull, by their face planes
                    any_a = False
                    _frame(R, t, n, f, Ra, ta)
                    for s in range(S):
                        if own_a[s] and hv_n[shape_tab[u, s]] > 0:
                            m = shape_tab[u, s]
                            if _hulls_apart(Ra, ta, hv[m], hv_n[m], hp[m], hp_n[m], I3, Z3, fhv[e], fhv_n[e], fhp[e],
                                            fhp_n[e], pad):
                                own_a[s] = False
                        any_a |= own_a[s]
                if any_a and fib_ok[e]:  # a point of a mesh (hull vertex) inside the fixed mesh's inner box
                    for s in range(S):
                        m = shape_tab[u, s]
                        if own_a[s] and hv_pts[m] and _verts_box(R, t, n, f, hv[m], hv_n[m], fibR[e], fibt[e], fibh[e],
                                                                   0.0, 0.0, -eps) > 0:
                            hit = True
                            break
                    if hit:
                        break
                if any_a and fi_n[e] > 0:  # a point of a mesh (hull vertex) inside the fixed body's solid
                    for s in range(S):
                        m = shape_tab[u, s]
                        if own_a[s] and hv_pts[m] and _inner_meet(R, t, n, f, hv[m], zero_r, hv_n[m], fi_c[e], fi_r[e],
                                                                    fi_n[e], f_pad[e] + mu - eps, w):
                            hit = True
                            break
                    if hit:
                        break
                if any_a:
                    for s in range(S):
                        if own_a[s]:
                            env = _grow(env, ne + 1)
                            env[ne, 0] = n
                            env[ne, 1] = shape_tab[u, s]
                            env[ne, 2] = e
                            ne += 1
                own_a[:] = False
        if not hit:  # pass 2, self pairs
            for pp in range(nsf):
                p = pnear[pp]
                a, b = self_s[p], self_o[p]
                fa, fb = unit_frame[a], unit_frame[b]
                _unit_box(R, t, n, fb, uR[b], ut[b], boxR, boxt)
                mpv = mp[n, p] if has_mp else 0.0
                pad = self_padding + mpv + eps
                any_a = _covers(R, t, n, fa, out_c[a], out_r[a], out_n[a], out_own[a], boxR, boxt, uh[b], urho[b], pad,
                                own_a, w)
                if any_a:
                    if self_two[p]:
                        _unit_box(R, t, n, fa, uR[a], ut[a], boxR2, boxt2)
                        any_a = _covers(R, t, n, fb, out_c[b], out_r[b], out_n[b], out_own[b], boxR2, boxt2, uh[a],
                                        urho[a], pad, own_b, w)
                    else:
                        for s in range(S):
                            own_b[s] = shape_tab[b, s] >= 0
                if any_a and u_tight[b]:  # hull vertices of a's meshes against b's exact box
                    v = _prune_by_hulls(R, t, n, fa, shape_tab[a], own_a, hv, hv_n, hp, hp_n, hv_pts, boxR, boxt, uh[b], urho[b],
                                        pad, eps)
                    if v > 0:
                        hit = True
                        break
                    any_a = v == 0
                if any_a and not u_tight[b] and in_n[b] > 0:
                    for i in range(in_n[b]):  # b's inner spheres in the world
                        _world(R, t, n, fb, in_c[b, i], Wb[i])
                    for x in range(S):  # a point of one of a's meshes (a hull vertex) inside b's solid
                        m = shape_tab[a, x]
                        if own_a[x] and hv_pts[m] and _inner_meet(R, t, n, fa, hv[m], zero_r, hv_n[m], Wb, in_r[b],
                                                                    in_n[b], self_padding + mpv - eps, w):
                            hit = True
                            break
                    if hit:
                        break
                if any_a:
                    for x in range(S):
                        if not own_a[x]:
                            continue
                        for y in range(S):
                            if own_b[y]:
                                v = _shape_pair(R, t, n, shape_tab[a, x], shape_tab[b, y], hv, hv_n, hp, hp_n, hv_pts, sb_ok, sb_h,
                                                sb_rho, shape_R, shape_t, frame_of, pad, eps, boxR2, boxt2, Ra, ta, Rb, tb)
                                if v > 0:
                                    hit = True
                                    break
                                if v < 0:
                                    continue
                                slf = _grow(slf, ns + 1)
                                slf[ns, 0] = n
                                slf[ns, 1] = shape_tab[a, x]
                                slf[ns, 2] = shape_tab[b, y]
                                slf[ns, 3] = p
                                ns += 1
                        if hit:
                            break
                    if hit:
                        break
                own_a[:] = False
                own_b[:] = False
        if hit:
            ne, ns = e0, s0
            status[n] = STATUS_HIT
        elif ne > e0 or ns > s0:
            status[n] = STATUS_OPEN
        elif flagged:
            status[n] = STATUS_FREE2
        else:
            status[n] = STATUS_FREE1
        own_a[:] = False
        own_b[:] = False
        if hit and stop_at_hit:
            status[n + 1:] = STATUS_UNCHECKED
            break
    return R, t, status, env[:ne], slf[:ns], n_tab


@nb.njit(cache=True, nogil=True)
def levels_12(q, has_me, me, has_mp, mp, margin, self_padding, eps, d):
    """_levels_12 on a checker's KernelData d: its arrays as one argument, so that a call unboxes one
    object, not ~100 arrays (a call's fixed cost 8.4 → 6.1 µs, which small batches pay per configuration)."""
    return _levels_12_of(q, has_me, me, has_mp, mp, margin, self_padding, eps, False, d)


@nb.njit(cache=True, nogil=True)
def levels_12_until_hit(q, margin, self_padding, eps, d):
    """levels_12 without edge margins, stopping at the first configuration proven colliding: those after it
    are left STATUS_UNCHECKED (no frames, no entries). A search's motion stops there anyway."""
    none = np.zeros((0, 0))
    return _levels_12_of(q, False, none, False, none, margin, self_padding, eps, True, d)


@nb.njit(cache=True, nogil=True)
def _levels_12_of(q, has_me, me, has_mp, mp, margin, self_padding, eps, stop_at_hit, d):
    """_levels_12 with KernelData d's arrays unpacked (one place for both entry points)."""
    return _levels_12(q, has_me, me, has_mp, mp, margin, self_padding, eps, stop_at_hit,
                      d.cols, d.parents, d.prismatic, d.basis, d.unit_frame, d.bound_c, d.bound_r, d.env_u,
                      d.env_e, d.env_R, d.env_t, d.env_h, d.env_thr2, d.fR, d.ft, d.fh, d.frho, d.f_pad, d.f_tight,
                      d.fc_c, d.fc_r, d.fc_n, d.fi_c, d.fi_r, d.fi_n, d.self_s, d.self_o, d.self_two, d.self_thr2,
                      d.uR, d.ut, d.uh, d.urho, d.u_tight, d.out_c, d.out_r, d.out_n, d.out_own, d.in_c, d.in_r,
                      d.in_n, d.shape_tab, d.hv, d.hv_n, d.hp, d.hp_n, d.hv_pts, d.sb_ok, d.sb_h, d.sb_rho, d.shape_R,
                      d.shape_t, d.frame_of, d.fhv, d.fhv_n, d.fhp, d.fhp_n, d.fib_ok, d.fibR, d.fibt, d.fibh,
                      d.use_grid, d.g_lo, d.g_step, d.g_shape, d.g_start, d.g_body, d.g_big, d.g_query, d.g_pair,
                      d.tab_cols, d.tab_nd, d.tab_lo, d.tab_step, d.tab_lev, d.tab_size, d.tab_off, d.tab_dist,
                      d.self_tab, d.env_tab, d.cs_tab, d.cl_frame, d.cl_c, d.use_cl_env, d.ce_slot, d.ce_R, d.ce_t,
                      d.ce_h, d.ce_thr2, d.ce_start, d.ce_count, d.ce_members, d.use_cl_self, d.cs_a, d.cs_b,
                      d.cs_thr2, d.cs_start, d.cs_count, d.cs_members)


@nb.njit(cache=True, nogil=True)
def _table_lb(q, n, T, cols, nd, lo, step, lev, size, off, dist) -> float:
    """Table T's lower bound of its pair's distance at configuration n (pair_tables.PairTable.lower_bound,
    the same arithmetic): the nearest grid point's distance less the levers times the offsets; -inf
    outside the grid (the levers hold only within it)."""
    flat = 0
    slack = 0.0
    for j in range(nd[T]):
        x = q[n, cols[T, j]]
        s, m = step[T, j], size[T, j] - 1
        if abs(x - (lo[T, j] + m * s / 2)) > m * s / 2 + s / 2:
            return -np.inf
        i = min(max(np.rint((x - lo[T, j]) / s), 0.0), float(m))
        slack += abs(x - (lo[T, j] + i * s)) * lev[T, j]
        flat = flat * (m + 1) + int(i)
    return dist[off[T] + flat] - slack


@nb.njit(cache=True, nogil=True)
def _world(R, t, n, f, c, out) -> None:
    for i in range(3):
        out[i] = R[n, f, i, 0] * c[0] + R[n, f, i, 1] * c[1] + R[n, f, i, 2] * c[2] + t[n, f, i]


@nb.njit(cache=True, nogil=True)
def _unit_box(R, t, n, f, bR, bt, outR, outt) -> None:
    """World pose of a unit's box (bR, bt in frame f) in configuration n."""
    for i in range(3):
        for j in range(3):
            outR[i, j] = R[n, f, i, 0] * bR[0, j] + R[n, f, i, 1] * bR[1, j] + R[n, f, i, 2] * bR[2, j]
        outt[i] = R[n, f, i, 0] * bt[0] + R[n, f, i, 1] * bt[1] + R[n, f, i, 2] * bt[2] + t[n, f, i]


@nb.njit(cache=True, nogil=True)
def _inner_meet(R, t, n, f, ca, ra, na, cb, rb, nb_, extra, w) -> bool:
    """An inner sphere of a unit (frame f, centres ca in it) comes within extra of one of the world
    spheres (cb, rb): both solids overlap there (signed squares: padding entries never meet)."""
    for i in range(na):
        _world(R, t, n, f, ca[i], w)
        for j in range(nb_):
            dx, dy, dz = w[0] - cb[j, 0], w[1] - cb[j, 1], w[2] - cb[j, 2]
            thr = ra[i] + rb[j] + extra
            if dx * dx + dy * dy + dz * dz < thr * abs(thr):
                return True
    return False


@nb.njit(cache=True, nogil=True, fastmath={'reassoc', 'nsz', 'contract'})
def _verts_box(R, t, n, f, V, nv, bR, bt, bh, rho, pad, reach) -> int:
    """Points V[:nv] (frame f) against the rounded box (bR, bt, half extents bh, rounding rho): 1 when
    one lies closer to it than reach (signed: -eps is inside it by more than eps; a mesh's points within a
    pair's required clearance prove it too close, as FCL's padded check would find), -1 when all lie beyond
    one of its faces by more than pad (the points' convex hull is that far from it), else 0."""
    # frame f into the box's frame in one transform (M = bRᵀ R_f, c = bRᵀ (t_f − bt)), held in scalars: the
    # loop over a hull's 50-400 vertices is most of a mesh robot's check next to boxes (TALOS in a shelf)
    if nv == 0:
        return -1  # no points: nothing near the box (V[0] is padding)
    M00, M01, M02, M10, M11, M12, M20, M21, M22, c0, c1, c2 = _into_box(R, t, n, f, bR, bt)
    h0, h1, h2 = bh[0], bh[1], bh[2]
    # minima and maxima over all vertices, decided after the loop: no branch inside it (an early exit cost more
    # than it saved), and min / max are exact in any order, so the fastmath flags (reassociation, fused
    # multiply-adds: ~1e-16 m) change no verdict beyond rounding (numba's LLVM still does not vectorize it)
    lo0 = hi0 = M00 * V[0, 0] + M01 * V[0, 1] + M02 * V[0, 2] + c0
    lo1 = hi1 = M10 * V[0, 0] + M11 * V[0, 1] + M12 * V[0, 2] + c1
    lo2 = hi2 = M20 * V[0, 0] + M21 * V[0, 1] + M22 * V[0, 2] + c2
    deep = max(abs(lo0) - h0, abs(lo1) - h1, abs(lo2) - h2)  # least of the vertices' largest face offsets
    near2 = max(abs(lo0) - h0, 0.0) ** 2 + max(abs(lo1) - h1, 0.0) ** 2 + max(abs(lo2) - h2, 0.0) ** 2
    for i in range(1, nv):
        l0 = M00 * V[i, 0] + M01 * V[i, 1] + M02 * V[i, 2] + c0
        l1 = M10 * V[i, 0] + M11 * V[i, 1] + M12 * V[i, 2] + c1
        l2 = M20 * V[i, 0] + M21 * V[i, 1] + M22 * V[i, 2] + c2
        lo0, lo1, lo2 = min(lo0, l0), min(lo1, l1), min(lo2, l2)
        hi0, hi1, hi2 = max(hi0, l0), max(hi1, l1), max(hi2, l2)
        x0, x1, x2 = abs(l0) - h0, abs(l1) - h1, abs(l2) - h2
        deep = min(deep, max(x0, x1, x2))
        near2 = min(near2, max(x0, 0.0) ** 2 + max(x1, 0.0) ** 2 + max(x2, 0.0) ** 2)
    r = reach + rho  # the reach from the box without its rounding
    # a vertex inside it by more than -r (r ≤ 0), or within r of it (r > 0: one inside is at 0)
    if (r <= 0.0 and deep < r) or (r > 0.0 and near2 < r * r):
        return 1
    e0, e1, e2 = h0 + rho + pad, h1 + rho + pad, h2 + rho + pad
    if lo0 > e0 or hi0 < -e0 or lo1 > e1 or hi1 < -e1 or lo2 > e2 or hi2 < -e2:
        return -1
    return 0


@nb.njit(cache=True, nogil=True)
def _into_box(R, t, n, f, bR, bt):
    """Frame f of configuration n into the box's frame (bR, bt): M = bRᵀ R_f and c = bRᵀ (t_f − bt), as 12 scalars."""
    d0, d1, d2 = t[n, f, 0] - bt[0], t[n, f, 1] - bt[1], t[n, f, 2] - bt[2]
    return (bR[0, 0] * R[n, f, 0, 0] + bR[1, 0] * R[n, f, 1, 0] + bR[2, 0] * R[n, f, 2, 0],
            bR[0, 0] * R[n, f, 0, 1] + bR[1, 0] * R[n, f, 1, 1] + bR[2, 0] * R[n, f, 2, 1],
            bR[0, 0] * R[n, f, 0, 2] + bR[1, 0] * R[n, f, 1, 2] + bR[2, 0] * R[n, f, 2, 2],
            bR[0, 1] * R[n, f, 0, 0] + bR[1, 1] * R[n, f, 1, 0] + bR[2, 1] * R[n, f, 2, 0],
            bR[0, 1] * R[n, f, 0, 1] + bR[1, 1] * R[n, f, 1, 1] + bR[2, 1] * R[n, f, 2, 1],
            bR[0, 1] * R[n, f, 0, 2] + bR[1, 1] * R[n, f, 1, 2] + bR[2, 1] * R[n, f, 2, 2],
            bR[0, 2] * R[n, f, 0, 0] + bR[1, 2] * R[n, f, 1, 0] + bR[2, 2] * R[n, f, 2, 0],
            bR[0, 2] * R[n, f, 0, 1] + bR[1, 2] * R[n, f, 1, 1] + bR[2, 2] * R[n, f, 2, 1],
            bR[0, 2] * R[n, f, 0, 2] + bR[1, 2] * R[n, f, 1, 2] + bR[2, 2] * R[n, f, 2, 2],
            bR[0, 0] * d0 + bR[1, 0] * d1 + bR[2, 0] * d2,
            bR[0, 1] * d0 + bR[1, 1] * d1 + bR[2, 1] * d2,
            bR[0, 2] * d0 + bR[1, 2] * d1 + bR[2, 2] * d2)


@nb.njit(cache=True, nogil=True)
def _shape_pair(R, t, n, ma, mb, hv, hv_n, hp, hp_n, hv_pts, sb_ok, sb_h, sb_rho, shape_R, shape_t, frame_of, pad,
                eps, boxR, boxt, Ra, ta, Rb, tb) -> int:
    """Moving shapes ma, mb: a mesh's hull against the other's exact box (either way round), or two
    meshes' hulls by their face planes → 1 contact, -1 apart by more than pad, 0 undecided. A hull whose
    vertices are not mesh points (hv_pts False: a bounding polytope) never proves contact."""
    for k in range(2):
        m, o = (ma, mb) if k == 0 else (mb, ma)
        if hv_n[m] > 0 and sb_ok[o]:
            fo = frame_of[o]
            _unit_box(R, t, n, fo, shape_R[o], shape_t[o], boxR, boxt)
            return _hull_box(R, t, n, frame_of[m], hv[m], hv_n[m], hp[m], hp_n[m], boxR, boxt, sb_h[o], sb_rho[o],
                             pad, eps if hv_pts[m] else np.inf)
    if hv_n[ma] > 0 and hv_n[mb] > 0:
        _frame(R, t, n, frame_of[ma], Ra, ta)
        _frame(R, t, n, frame_of[mb], Rb, tb)
        if _hulls_apart(Ra, ta, hv[ma], hv_n[ma], hp[ma], hp_n[ma], Rb, tb, hv[mb], hv_n[mb], hp[mb], hp_n[mb], pad):
            return -1
    return 0


@nb.njit(cache=True, nogil=True)
def _frame(R, t, n, f, outR, outt) -> None:
    for i in range(3):
        outt[i] = t[n, f, i]
        for j in range(3):
            outR[i, j] = R[n, f, i, j]


@nb.njit(cache=True, nogil=True)
def _beyond_planes(Ra, ta, Pa, npa, Rb, tb, Vb, nvb, pad) -> bool:
    """Some face plane of hull a (frame Ra, ta) has every vertex of hull b (frame Rb, tb) beyond it by
    more than pad. A plane is given up at its first vertex within pad (most are, at once)."""
    # b's vertices into a's frame: x_a = M x_b + c with M = Raᵀ Rb, c = Raᵀ (tb − ta); scalars, not
    # arrays: an array allocated per call costs as much as a few planes
    d0, d1, d2 = tb[0] - ta[0], tb[1] - ta[1], tb[2] - ta[2]
    c0 = Ra[0, 0] * d0 + Ra[1, 0] * d1 + Ra[2, 0] * d2
    c1 = Ra[0, 1] * d0 + Ra[1, 1] * d1 + Ra[2, 1] * d2
    c2 = Ra[0, 2] * d0 + Ra[1, 2] * d1 + Ra[2, 2] * d2
    M00 = Ra[0, 0] * Rb[0, 0] + Ra[1, 0] * Rb[1, 0] + Ra[2, 0] * Rb[2, 0]
    M01 = Ra[0, 0] * Rb[0, 1] + Ra[1, 0] * Rb[1, 1] + Ra[2, 0] * Rb[2, 1]
    M02 = Ra[0, 0] * Rb[0, 2] + Ra[1, 0] * Rb[1, 2] + Ra[2, 0] * Rb[2, 2]
    M10 = Ra[0, 1] * Rb[0, 0] + Ra[1, 1] * Rb[1, 0] + Ra[2, 1] * Rb[2, 0]
    M11 = Ra[0, 1] * Rb[0, 1] + Ra[1, 1] * Rb[1, 1] + Ra[2, 1] * Rb[2, 1]
    M12 = Ra[0, 1] * Rb[0, 2] + Ra[1, 1] * Rb[1, 2] + Ra[2, 1] * Rb[2, 2]
    M20 = Ra[0, 2] * Rb[0, 0] + Ra[1, 2] * Rb[1, 0] + Ra[2, 2] * Rb[2, 0]
    M21 = Ra[0, 2] * Rb[0, 1] + Ra[1, 2] * Rb[1, 1] + Ra[2, 2] * Rb[2, 1]
    M22 = Ra[0, 2] * Rb[0, 2] + Ra[1, 2] * Rb[1, 2] + Ra[2, 2] * Rb[2, 2]
    for k in range(npa):
        # the plane in b's frame: n_b = Mᵀ n, d_b = d − n·c
        n0, n1, n2 = Pa[k, 0], Pa[k, 1], Pa[k, 2]
        m0 = M00 * n0 + M10 * n1 + M20 * n2
        m1 = M01 * n0 + M11 * n1 + M21 * n2
        m2 = M02 * n0 + M12 * n1 + M22 * n2
        d = Pa[k, 3] - (n0 * c0 + n1 * c1 + n2 * c2) + pad
        out = True
        for i in range(nvb):
            if m0 * Vb[i, 0] + m1 * Vb[i, 1] + m2 * Vb[i, 2] <= d:
                out = False
                break
        if out:
            return True
    return False


@nb.njit(cache=True, nogil=True)
def _hulls_apart(Ra, ta, Va, nva, Pa, npa, Rb, tb, Vb, nvb, Pb, npb, pad) -> bool:
    """Two convex hulls (vertices, face planes, each in its frame) are more than pad apart along some
    axis: a face normal of either, else an axis found by _axis_apart (where edges face each other)."""
    return (_beyond_planes(Ra, ta, Pa, npa, Rb, tb, Vb, nvb, pad) or _beyond_planes(Rb, tb, Pb, npb, Ra, ta, Va, nva, pad)
            or _axis_apart(Ra, ta, Va, nva, Rb, tb, Vb, nvb, pad))


@nb.njit(cache=True, nogil=True)
def _extreme(R, t, V, nv, d0, d1, d2, lowest):
    """The vertex of V (frame R, t) lowest (or highest) along the world direction d: (its height, world x, y, z)."""
    e0 = R[0, 0] * d0 + R[1, 0] * d1 + R[2, 0] * d2  # d in the hull's frame
    e1 = R[0, 1] * d0 + R[1, 1] * d1 + R[2, 1] * d2
    e2 = R[0, 2] * d0 + R[1, 2] * d1 + R[2, 2] * d2
    best, k = 0.0, 0
    for i in range(nv):
        h = e0 * V[i, 0] + e1 * V[i, 1] + e2 * V[i, 2]
        if i == 0 or (h < best if lowest else h > best):
            best, k = h, i
    x0, x1, x2 = _to_world(R, t, V[k, 0], V[k, 1], V[k, 2])
    return best + d0 * t[0] + d1 * t[1] + d2 * t[2], x0, x1, x2


@nb.njit(cache=True, nogil=True)
def _to_world(R, t, v0, v1, v2):
    """The point v (frame R, t) in world coordinates."""
    return (R[0, 0] * v0 + R[0, 1] * v1 + R[0, 2] * v2 + t[0], R[1, 0] * v0 + R[1, 1] * v1 + R[1, 2] * v2 + t[1],
            R[2, 0] * v0 + R[2, 1] * v1 + R[2, 2] * v2 + t[2])


@nb.njit(cache=True, nogil=True)
def _mean_world(R, t, V, nv):
    """The mean of the vertices V[:nv] (frame R, t), in world coordinates."""
    m0 = m1 = m2 = 0.0
    for i in range(nv):
        m0 += V[i, 0]
        m1 += V[i, 1]
        m2 += V[i, 2]
    return _to_world(R, t, m0 / nv, m1 / nv, m2 / nv)


@nb.njit(cache=True, nogil=True)
def _axis_apart(Ra, ta, Va, nva, Rb, tb, Vb, nvb, pad) -> bool:
    """Two convex hulls more than pad apart along an axis found by Frank–Wolfe iterations towards the point
    of the Minkowski difference A − B nearest the origin (GJK's question, without its simplex): each
    iterate x is a point of A − B, so |x| ≤ pad means they cannot be proven apart; each direction d = x
    gives the gap min_A d·a − max_B d·b, and a gap above pad·|d| proves them apart — whatever the
    iterations converge to, only that exact axis test decides. Where face normals fail (two links whose
    edges face each other: TALOS's forearm beside the pelvis), most such pairs are proven apart within
    a few iterations, in the kernels instead of FCL."""
    # start: the vertices' mean of a minus that of b (a point of A − B)
    a0, a1, a2 = _mean_world(Ra, ta, Va, nva)
    b0, b1, b2 = _mean_world(Rb, tb, Vb, nvb)
    x0, x1, x2 = a0 - b0, a1 - b1, a2 - b2
    for _ in range(AXIS_ITERATIONS):
        nx = np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        if nx <= pad:
            return False
        ha, p0, p1, p2 = _extreme(Ra, ta, Va, nva, x0, x1, x2, True)
        hb, q0, q1, q2 = _extreme(Rb, tb, Vb, nvb, x0, x1, x2, False)
        if ha - hb > pad * nx:
            return True
        # s = p − q: the point of A − B lowest along x; step from x towards it, to the nearest point of the segment
        w0, w1, w2 = p0 - q0 - x0, p1 - q1 - x1, p2 - q2 - x2
        ww = w0 * w0 + w1 * w1 + w2 * w2
        if ww <= 1e-18:
            return False
        g = min(1.0, max(0.0, -(x0 * w0 + x1 * w1 + x2 * w2) / ww))
        x0, x1, x2 = x0 + g * w0, x1 + g * w1, x2 + g * w2
    return False


@nb.njit(cache=True, nogil=True)
def _covers(R, t, n, f, c, r, cnt, owners, bR, bt, bh, rho, pad, own, w) -> bool:
    """A unit's cover spheres (c, r: cnt of them in frame f, owners: the shape each belongs to) grown by
    pad against a rounded box: the owners of those that reach it are flagged in own; any?"""
    any_hit = False
    for i in range(cnt):
        _world(R, t, n, f, c[i], w)
        if _touch(w[0], w[1], w[2], r[i] + pad, bR, bt, bh, rho):
            own[owners[i]] = True
            any_hit = True
    return any_hit


@nb.njit(cache=True, nogil=True)
def _prune_by_hulls(R, t, n, f, shapes, own, hv, hv_n, hp, hp_n, hv_pts, bR, bt, bh, rho, pad, eps) -> int:
    """A unit's flagged shapes (own[s]; shapes[s]: their ids, frame f) against an exact rounded box, the
    meshes by their hulls (_hull_box): 1 when one proves contact; else the flags of those proven apart
    are cleared, and 0 when a flag is left, -1 when none is."""
    left = False
    for s in range(shapes.shape[0]):
        m = shapes[s]
        if own[s] and m >= 0 and hv_n[m] > 0:
            v = _hull_box(R, t, n, f, hv[m], hv_n[m], hp[m], hp_n[m], bR, bt, bh, rho, pad, eps if hv_pts[m] else np.inf)
            if v > 0:
                return 1
            if v < 0:
                own[s] = False
        left |= own[s]
    return 0 if left else -1


@nb.njit(cache=True, nogil=True)
def _hull_box(R, t, n, f, V, nv, P, npl, bR, bt, bh, rho, pad, eps) -> int:
    """A mesh's hull (vertices V, face planes P in frame f) against a rounded box: _verts_box, then the
    box against each face plane — wholly beyond one by more than pad: apart (-1)."""
    # a vertex closer than pad - 2 eps (pad: the pair's clearance + eps) proves the pair too close; none
    # with eps = inf (a bounding polytope's vertices are no mesh points)
    v = _verts_box(R, t, n, f, V, nv, bR, bt, bh, rho, pad, pad - 2.0 * eps)
    if v != 0:
        return v
    # the box in frame f: centre c, axes a_j (columns of A); scalars, not arrays (one allocation per call
    # costs as much as a few planes)
    d0, d1, d2 = bt[0] - t[n, f, 0], bt[1] - t[n, f, 1], bt[2] - t[n, f, 2]
    c0 = R[n, f, 0, 0] * d0 + R[n, f, 1, 0] * d1 + R[n, f, 2, 0] * d2
    c1 = R[n, f, 0, 1] * d0 + R[n, f, 1, 1] * d1 + R[n, f, 2, 1] * d2
    c2 = R[n, f, 0, 2] * d0 + R[n, f, 1, 2] * d1 + R[n, f, 2, 2] * d2
    A00 = R[n, f, 0, 0] * bR[0, 0] + R[n, f, 1, 0] * bR[1, 0] + R[n, f, 2, 0] * bR[2, 0]
    A01 = R[n, f, 0, 0] * bR[0, 1] + R[n, f, 1, 0] * bR[1, 1] + R[n, f, 2, 0] * bR[2, 1]
    A02 = R[n, f, 0, 0] * bR[0, 2] + R[n, f, 1, 0] * bR[1, 2] + R[n, f, 2, 0] * bR[2, 2]
    A10 = R[n, f, 0, 1] * bR[0, 0] + R[n, f, 1, 1] * bR[1, 0] + R[n, f, 2, 1] * bR[2, 0]
    A11 = R[n, f, 0, 1] * bR[0, 1] + R[n, f, 1, 1] * bR[1, 1] + R[n, f, 2, 1] * bR[2, 1]
    A12 = R[n, f, 0, 1] * bR[0, 2] + R[n, f, 1, 1] * bR[1, 2] + R[n, f, 2, 1] * bR[2, 2]
    A20 = R[n, f, 0, 2] * bR[0, 0] + R[n, f, 1, 2] * bR[1, 0] + R[n, f, 2, 2] * bR[2, 0]
    A21 = R[n, f, 0, 2] * bR[0, 1] + R[n, f, 1, 2] * bR[1, 1] + R[n, f, 2, 2] * bR[2, 1]
    A22 = R[n, f, 0, 2] * bR[0, 2] + R[n, f, 1, 2] * bR[1, 2] + R[n, f, 2, 2] * bR[2, 2]
    for k in range(npl):
        n0, n1, n2 = P[k, 0], P[k, 1], P[k, 2]
        low = n0 * c0 + n1 * c1 + n2 * c2 - rho
        low -= bh[0] * abs(n0 * A00 + n1 * A10 + n2 * A20)
        low -= bh[1] * abs(n0 * A01 + n1 * A11 + n2 * A21)
        low -= bh[2] * abs(n0 * A02 + n1 * A12 + n2 * A22)
        if low - P[k, 3] > pad:
            return -1
    return 0


@nb.njit(cache=True, nogil=True)
def _axis_gap(a0, a1, a2, x0, y0, z0, x1, y1, z1, x2, y2, z2, g0, g1, g2) -> float:
    """Along the axis (a0, a1, a2) (box coordinates, any length): the gap between the triangle's
    projection and the box [-g, g]'s, divided by the axis' length; > 0 apart along it, else minus the
    overlap. A zero axis separates nothing (-inf)."""
    la = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    if la < 1e-12:
        return -np.inf
    p0 = a0 * x0 + a1 * y0 + a2 * z0
    p1 = a0 * x1 + a1 * y1 + a2 * z1
    p2 = a0 * x2 + a1 * y2 + a2 * z2
    r = g0 * abs(a0) + g1 * abs(a1) + g2 * abs(a2)
    return max(min(p0, p1, p2) - r, -r - max(p0, p1, p2)) / la


@nb.njit(cache=True, nogil=True)
def _tri_box(x0, y0, z0, x1, y1, z1, x2, y2, z2, g0, g1, g2) -> float:
    """Separating-axis test of a triangle (box coordinates) against the box [-g, g] (g > 0): the box's 3
    face normals, the triangle's normal, the 9 edge × box-axis products. The largest gap along them
    (unit axes): > 0 apart by at least that, ≤ 0 they intersect (exact: these 13 axes suffice)."""
    best = max(min(x0, x1, x2) - g0, -g0 - max(x0, x1, x2),
               min(y0, y1, y2) - g1, -g1 - max(y0, y1, y2),
               min(z0, z1, z2) - g2, -g2 - max(z0, z1, z2))
    if best > 0.0:
        return best
    ex0, ey0, ez0 = x1 - x0, y1 - y0, z1 - z0
    ex1, ey1, ez1 = x2 - x1, y2 - y1, z2 - z1
    ex2, ey2, ez2 = x0 - x2, y0 - y2, z0 - z2
    best = max(best, _axis_gap(ey0 * ez1 - ez0 * ey1, ez0 * ex1 - ex0 * ez1, ex0 * ey1 - ey0 * ex1,
                               x0, y0, z0, x1, y1, z1, x2, y2, z2, g0, g1, g2))
    if best > 0.0:
        return best
    for i in range(3):
        if i == 0:
            ex, ey, ez = ex0, ey0, ez0
        elif i == 1:
            ex, ey, ez = ex1, ey1, ez1
        else:
            ex, ey, ez = ex2, ey2, ez2
        # e × x̂ = (0, ez, -ey), e × ŷ = (-ez, 0, ex), e × ẑ = (ey, -ex, 0)
        best = max(best, _axis_gap(0.0, ez, -ey, x0, y0, z0, x1, y1, z1, x2, y2, z2, g0, g1, g2),
                   _axis_gap(-ez, 0.0, ex, x0, y0, z0, x1, y1, z1, x2, y2, z2, g0, g1, g2),
                   _axis_gap(ey, -ex, 0.0, x0, y0, z0, x1, y1, z1, x2, y2, z2, g0, g1, g2))
    return best


@nb.njit(cache=True, nogil=True)
def mesh_box_entries(R, t, conf, shape, body, pad, frame_of, tri, tri_c, tri_r, run_lo, run_hi, run_c, run_r, run_off,
                     fR, ft, fh, frho, f_tight, eps):
    """The open (configuration, moving mesh, fixed box) entries, decided by the mesh's own triangles
    against the exact box (a scene box; FCL's mesh–box test is the same: the mesh as its surface
    against the solid box): 1 when a triangle meets the box shrunk by eps on every side, or comes within
    pad - eps of it (contact, or closer than the padding), -1
    when every triangle is apart from the box grown by pad + eps (a cube's growth contains the rounded
    one, so the pair is farther apart than pad), 0 otherwise (left to FCL). Shapes without triangles
    (run_off[m] == run_off[m + 1]) and bodies other than exact boxes give 0. Near contact, where the
    hull tests cannot tell and most configurations went to FCL (~18 µs a call with its Python).
    Triangles come in runs of nearby ones (run_lo..run_hi, bounding spheres run_c, run_r; tri_c, tri_r
    per triangle, frame coordinates): a run or triangle whose sphere is farther than pad + eps from the
    box is apart without its separating-axis test (TALOS's meshes have up to 1 900 triangles)."""
    K = conf.shape[0]
    out = np.zeros(K, dtype=np.int8)
    A = np.empty((3, 3))
    c = np.empty(3)
    v = np.empty((3, 3))
    for k in range(K):
        m, e, n = shape[k], body[k], conf[k]
        if not f_tight[e] or frho[e] > 0.0 or run_off[m + 1] == run_off[m]:
            continue
        f = frame_of[m]
        # frame f → box coordinates: x_b = A x_f + c, A = bRᵀ Rf, c = bRᵀ (tf − bt)
        A[0, 0], A[0, 1], A[0, 2], A[1, 0], A[1, 1], A[1, 2], A[2, 0], A[2, 1], A[2, 2], c[0], c[1], c[2] = \
            _into_box(R, t, n, f, fR[e], ft[e])
        h0, h1, h2 = fh[e, 0], fh[e, 1], fh[e, 2]
        grow = pad[k] + eps
        # a contact is proven by a triangle meeting the box shrunk by eps or, with a padding, grown by
        # (pad - eps) / √3: a cube's growth by g lies within distance √3 g of the box
        inner = -eps if pad[k] <= eps else (pad[k] - eps) / np.sqrt(3.0)
        shrink = min(h0, h1, h2) + inner > eps
        verdict = -1
        open_ = False
        for g in range(run_off[m], run_off[m + 1]):
            if _far(A, c, run_c[g], run_r[g] + grow, h0, h1, h2):
                continue
            for x in range(run_lo[g], run_hi[g]):
                if _far(A, c, tri_c[x], tri_r[x] + grow, h0, h1, h2):
                    continue
                verdict = _tri_verdict(A, c, tri[x], v, h0, h1, h2, grow, inner, shrink)
                if verdict > 0:
                    break
                if verdict == 0:
                    open_ = True
            if verdict > 0:
                break
        out[k] = verdict if verdict > 0 else (0 if open_ else -1)
    return out


@nb.njit(cache=True, nogil=True)
def _far(A, c, p, r, h0, h1, h2) -> bool:
    """The sphere (p, frame coordinates; radius r) lies outside the box [-h, h] (x_b = A p + c)."""
    d2 = 0.0
    for i in range(3):
        x = abs(A[i, 0] * p[0] + A[i, 1] * p[1] + A[i, 2] * p[2] + c[i])
        if i == 0:
            x -= h0
        elif i == 1:
            x -= h1
        else:
            x -= h2
        if x > 0.0:
            d2 += x * x
    return d2 > r * r


@nb.njit(cache=True, nogil=True)
def _tri_verdict(A, c, T, v, h0, h1, h2, grow, inner, shrink) -> int:
    """One triangle T (frame coordinates) against the box [-h, h] (box coordinates x_b = A x + c):
    1 it meets the box grown by inner (contact proven, when shrink allows), -1 apart from the box
    grown by grow, else 0."""
    for a in range(3):
        for i in range(3):
            v[a, i] = A[i, 0] * T[a, 0] + A[i, 1] * T[a, 1] + A[i, 2] * T[a, 2] + c[i]
    if _tri_box(v[0, 0], v[0, 1], v[0, 2], v[1, 0], v[1, 1], v[1, 2], v[2, 0], v[2, 1], v[2, 2],
                h0 + grow, h1 + grow, h2 + grow) > 0.0:
        return -1
    if shrink and _tri_box(v[0, 0], v[0, 1], v[0, 2], v[1, 0], v[1, 1], v[1, 2], v[2, 0], v[2, 1], v[2, 2],
                           h0 + inner, h1 + inner, h2 + inner) <= 0.0:
        return 1
    return 0


@nb.njit(cache=True, nogil=True)
def _gap(a0, a1, a2, P, Q) -> float:
    """Along the axis (a0, a1, a2): the gap between triangles P and Q (rows: vertices), divided by the
    axis' length; > 0 apart along it, else minus the overlap; -inf for a zero axis."""
    la = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    if la < 1e-12:
        return -np.inf
    p0 = a0 * P[0, 0] + a1 * P[0, 1] + a2 * P[0, 2]
    p1 = a0 * P[1, 0] + a1 * P[1, 1] + a2 * P[1, 2]
    p2 = a0 * P[2, 0] + a1 * P[2, 1] + a2 * P[2, 2]
    q0 = a0 * Q[0, 0] + a1 * Q[0, 1] + a2 * Q[0, 2]
    q1 = a0 * Q[1, 0] + a1 * Q[1, 1] + a2 * Q[1, 2]
    q2 = a0 * Q[2, 0] + a1 * Q[2, 1] + a2 * Q[2, 2]
    return max(min(q0, q1, q2) - max(p0, p1, p2), min(p0, p1, p2) - max(q0, q1, q2)) / la


@nb.njit(cache=True, nogil=True)
def tri_tri_gap(P, Q, E, N) -> float:
    """Separating-axis test of two triangles (rows: vertices, same coordinates): both normals, the 9
    edge × edge products and each normal × its own edges (coplanar triangles) — enough axes for two
    triangles. The largest gap along them (unit axes): > 0 apart by at least that; -x with x > 0: they
    overlap by x along every axis, so they intersect. E (2, 3, 3), N (2, 3): scratch for the edges and
    normals (an allocation per call costs more than the test)."""
    for i in range(3):
        j = (i + 1) % 3
        for d in range(3):
            E[0, i, d] = P[j, d] - P[i, d]
            E[1, i, d] = Q[j, d] - Q[i, d]
    best = -np.inf
    for s in range(2):
        N[s, 0] = E[s, 0, 1] * E[s, 1, 2] - E[s, 0, 2] * E[s, 1, 1]
        N[s, 1] = E[s, 0, 2] * E[s, 1, 0] - E[s, 0, 0] * E[s, 1, 2]
        N[s, 2] = E[s, 0, 0] * E[s, 1, 1] - E[s, 0, 1] * E[s, 1, 0]
        best = max(best, _gap(N[s, 0], N[s, 1], N[s, 2], P, Q))
    for i in range(3):
        u0, u1, u2 = E[0, i, 0], E[0, i, 1], E[0, i, 2]
        for j in range(3):
            w0, w1, w2 = E[1, j, 0], E[1, j, 1], E[1, j, 2]
            best = max(best, _gap(u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0, P, Q))
    for s in range(2):
        u0, u1, u2 = N[s, 0], N[s, 1], N[s, 2]
        for i in range(3):
            w0, w1, w2 = E[s, i, 0], E[s, i, 1], E[s, i, 2]
            best = max(best, _gap(u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0, P, Q))
    return best


@nb.njit(cache=True, nogil=True)
def _point_tri_d2(p0, p1, p2, T) -> float:
    """The squared distance from the point p to a point of triangle T (rows: vertices) nearest it (Ericson,
    Real-Time Collision Detection 5.1.5); a degenerate triangle: to its nearest vertex. Never below the
    true distance: what it measures to is a point of the triangle."""
    ab0, ab1, ab2 = T[1, 0] - T[0, 0], T[1, 1] - T[0, 1], T[1, 2] - T[0, 2]
    ac0, ac1, ac2 = T[2, 0] - T[0, 0], T[2, 1] - T[0, 1], T[2, 2] - T[0, 2]
    ap0, ap1, ap2 = p0 - T[0, 0], p1 - T[0, 1], p2 - T[0, 2]
    d1 = ab0 * ap0 + ab1 * ap1 + ab2 * ap2
    d2 = ac0 * ap0 + ac1 * ap1 + ac2 * ap2
    bp0, bp1, bp2 = p0 - T[1, 0], p1 - T[1, 1], p2 - T[1, 2]
    d3 = ab0 * bp0 + ab1 * bp1 + ab2 * bp2
    d4 = ac0 * bp0 + ac1 * bp1 + ac2 * bp2
    cp0, cp1, cp2 = p0 - T[2, 0], p1 - T[2, 1], p2 - T[2, 2]
    d5 = ab0 * cp0 + ab1 * cp1 + ab2 * cp2
    d6 = ac0 * cp0 + ac1 * cp1 + ac2 * cp2
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    corner = min(ap0 * ap0 + ap1 * ap1 + ap2 * ap2, bp0 * bp0 + bp1 * bp1 + bp2 * bp2, cp0 * cp0 + cp1 * cp1 + cp2 * cp2)
    if d1 <= 0.0 and d2 <= 0.0 or d3 >= 0.0 and d4 <= d3 or d6 >= 0.0 and d5 <= d6:
        return corner  # the nearest point is a vertex
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:  # on edge ab
        v = d1 / (d1 - d3)
        x0, x1, x2 = ap0 - v * ab0, ap1 - v * ab1, ap2 - v * ab2
    elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:  # on edge ac
        w = d2 / (d2 - d6)
        x0, x1, x2 = ap0 - w * ac0, ap1 - w * ac1, ap2 - w * ac2
    elif va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:  # on edge bc
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        x0 = bp0 - w * (T[2, 0] - T[1, 0])
        x1 = bp1 - w * (T[2, 1] - T[1, 1])
        x2 = bp2 - w * (T[2, 2] - T[1, 2])
    elif va + vb + vc > 0.0:  # inside the face
        den = 1.0 / (va + vb + vc)
        v, w = vb * den, vc * den
        x0, x1, x2 = ap0 - ab0 * v - ac0 * w, ap1 - ab1 * v - ac1 * w, ap2 - ab2 * v - ac2 * w
    else:
        return corner
    d = x0 * x0 + x1 * x1 + x2 * x2
    return d if d < corner else corner


@nb.njit(cache=True, nogil=True)
def _seg_seg_d2(P, i, Q, j) -> float:
    """The squared distance between a point of edge i of triangle P (vertex i to i + 1) and one of edge j of
    Q, the nearest such points (Ericson 5.1.9) up to rounding: never below the edges' true distance."""
    i2, j2 = (i + 1) % 3, (j + 1) % 3
    d10, d11, d12 = P[i2, 0] - P[i, 0], P[i2, 1] - P[i, 1], P[i2, 2] - P[i, 2]
    d20, d21, d22 = Q[j2, 0] - Q[j, 0], Q[j2, 1] - Q[j, 1], Q[j2, 2] - Q[j, 2]
    r0, r1, r2 = P[i, 0] - Q[j, 0], P[i, 1] - Q[j, 1], P[i, 2] - Q[j, 2]
    a = d10 * d10 + d11 * d11 + d12 * d12
    e = d20 * d20 + d21 * d21 + d22 * d22
    f = d20 * r0 + d21 * r1 + d22 * r2
    tiny = 1e-24
    if a <= tiny and e <= tiny:
        s = t = 0.0
    elif a <= tiny:
        s, t = 0.0, min(max(f / e, 0.0), 1.0)
    else:
        c = d10 * r0 + d11 * r1 + d12 * r2
        if e <= tiny:
            s, t = min(max(-c / a, 0.0), 1.0), 0.0
        else:
            b = d10 * d20 + d11 * d21 + d12 * d22
            den = a * e - b * b
            s = min(max((b * f - c * e) / den, 0.0), 1.0) if den > tiny else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                s, t = min(max(-c / a, 0.0), 1.0), 0.0
            elif t > 1.0:
                s, t = min(max((b - c) / a, 0.0), 1.0), 1.0
    x0 = r0 + d10 * s - d20 * t
    x1 = r1 + d11 * s - d21 * t
    x2 = r2 + d12 * s - d22 * t
    return x0 * x0 + x1 * x1 + x2 * x2


@nb.njit(cache=True, nogil=True)
def tri_tri_upper(P, Q) -> float:
    """A distance between two triangles (rows: vertices, same coordinates) no smaller than their true one:
    the least from a vertex of either to the other triangle and between their edges — their distance, up to
    rounding, when they do not intersect (the nearest points of two triangles apart lie on a vertex and a
    face or on two edges). Below a pair's clearance, the meshes they belong to are that close."""
    d2 = np.inf
    for v in range(3):
        d2 = min(d2, _point_tri_d2(P[v, 0], P[v, 1], P[v, 2], Q), _point_tri_d2(Q[v, 0], Q[v, 1], Q[v, 2], P))
        for w in range(3):
            d2 = min(d2, _seg_seg_d2(P, v, Q, w))
    return np.sqrt(d2)


@nb.njit(cache=True, nogil=True)
def _witness_hit(R, t, n, a, b, slot, frame_of, M, tri, tri_c, tri_r, wit, wit_n, eps, reach, Ra, ta, Rb, tb, P, Q, E,
                 N) -> bool:
    """Configuration n, meshes a and b (a moving shape, or M + e for a fixed link mesh e whose triangles
    are in the world): one of the triangle pairs FCL found intersecting, or closer than the pair's clearance,
    for them before (wit[slot], rows of tri) overlaps by more than eps along every separating axis here —
    two triangles of the meshes intersect, which is FCL's mesh–mesh contact — or (reach > 0: the clearance
    asked less eps) lies closer than reach by tri_tri_upper, which FCL's padded check would find. Ra … N:
    scratch."""
    for side in range(2):
        s = a if side == 0 else b
        Rs, ts = (Ra, ta) if side == 0 else (Rb, tb)
        if s >= M:  # a fixed body: world coordinates
            for i in range(3):
                ts[i] = 0.0
                for j in range(3):
                    Rs[i, j] = 1.0 if i == j else 0.0
        else:
            _frame(R, t, n, frame_of[s], Rs, ts)
    for w in range(wit_n[slot]):
        x, y = wit[slot, w, 0], wit[slot, w, 1]
        # their bounding spheres first: most remembered pairs are apart at another configuration
        d2 = 0.0
        for i in range(3):
            d = (Ra[i, 0] * tri_c[x, 0] + Ra[i, 1] * tri_c[x, 1] + Ra[i, 2] * tri_c[x, 2] + ta[i]
                 - Rb[i, 0] * tri_c[y, 0] - Rb[i, 1] * tri_c[y, 1] - Rb[i, 2] * tri_c[y, 2] - tb[i])
            d2 += d * d
        if d2 >= (tri_r[x] + tri_r[y] + max(reach, 0.0)) ** 2:
            continue
        for v in range(3):
            for i in range(3):
                P[v, i] = Ra[i, 0] * tri[x, v, 0] + Ra[i, 1] * tri[x, v, 1] + Ra[i, 2] * tri[x, v, 2] + ta[i]
                Q[v, i] = Rb[i, 0] * tri[y, v, 0] + Rb[i, 1] * tri[y, v, 1] + Rb[i, 2] * tri[y, v, 2] + tb[i]
        if tri_tri_gap(P, Q, E, N) < -eps:
            return True
        if reach > 0.0 and tri_tri_upper(P, Q) < reach:
            return True
    return False


@nb.njit(cache=True, nogil=True)
def triangle_tests(R, t, ok, en, em, ee, has_me, me_e, sn, sa, sb, self_padding, has_mp, mp_s, frame_of, tri, tri_c,
                   tri_r, run_lo, run_hi, run_c, run_r, run_off, fR, ft, fh, frho, f_tight, f_pad, wit_slot, wit, wit_n,
                   eps):
    """The open entries — env (configuration en, moving shape em, fixed body ee) and self (sn, sa, sb) —
    decided by triangles before FCL, in one call (a search checks small batches: numpy calls around
    separate kernels cost more than the tests): env entries against scene boxes by mesh_box_entries;
    then, for pairs of meshes, the triangle pairs FCL found intersecting or too close for them before
    (wit_slot (shape, shape or M + e) → slot; _witness_hit, each entry's clearance less eps as its reach).
    A configuration with a contact is cleared in ok.
    me_e / mp_s: the entries' edge margins (read when has_me / has_mp). Returns which env and self
    entries are left for FCL, and how many configurations were proven colliding."""
    M = frame_of.shape[0]
    K, L = en.shape[0], sn.shape[0]
    pad = np.empty(K)
    for k in range(K):
        pad[k] = f_pad[ee[k]] + (me_e[k] if has_me else 0.0)
    v = mesh_box_entries(R, t, en, em, ee, pad, frame_of, tri, tri_c, tri_r, run_lo, run_hi, run_c, run_r, run_off,
                         fR, ft, fh, frho, f_tight, eps)
    Ra, ta, Rb, tb = np.empty((3, 3)), np.empty(3), np.empty((3, 3)), np.empty(3)
    P, Q = np.empty((3, 3)), np.empty((3, 3))
    E, N = np.empty((2, 3, 3)), np.empty((2, 3))
    hits = 0
    for k in range(K):
        if not ok[en[k]]:
            continue
        if v[k] == 0 and wit_slot.shape[0] > 0:
            slot = wit_slot[em[k], M + ee[k]]
            if slot >= 0 and _witness_hit(R, t, en[k], em[k], M + ee[k], slot, frame_of, M, tri, tri_c, tri_r, wit,
                                          wit_n, eps, pad[k] - eps, Ra, ta, Rb, tb, P, Q, E, N):
                v[k] = 1
        if v[k] > 0:
            ok[en[k]] = False
            hits += 1
    for k in range(L):
        if ok[sn[k]] and wit_slot.shape[0] > 0:
            slot = wit_slot[sa[k], sb[k]]
            reach = self_padding + (mp_s[k] if has_mp else 0.0) - eps
            if slot >= 0 and _witness_hit(R, t, sn[k], sa[k], sb[k], slot, frame_of, M, tri, tri_c, tri_r, wit, wit_n,
                                          eps, reach, Ra, ta, Rb, tb, P, Q, E, N):
                ok[sn[k]] = False
                hits += 1
    keep_e = np.empty(K, dtype=np.bool_)
    for k in range(K):
        keep_e[k] = v[k] == 0 and ok[en[k]]
    keep_s = np.empty(L, dtype=np.bool_)
    for k in range(L):
        keep_s[k] = ok[sn[k]]
    return keep_e, keep_s, hits


@nb.njit(cache=True, nogil=True)
def _compact(a, keep):
    """The rows of a (K, m) that keep marks (numba indexes 2-d arrays by a mask only along with a slice)."""
    out = np.empty((keep.sum(), a.shape[1]), dtype=a.dtype)
    j = 0
    for k in range(a.shape[0]):
        if keep[k]:
            out[j] = a[k]
            j += 1
    return out


@nb.njit(cache=True, nogil=True)
def screen_batches(q, bounds, i, margin, self_padding, eps, d, frame_of, tri, tri_c, tri_r, run_lo, run_hi, run_c,
                   run_r, run_off, fR, ft, fh, frho, f_tight, f_pad, wit_slot, wit, wit_n):
    """The first colliding configuration of q (N, n) (no edge margins), as far as the levels and the triangle
    tests decide it: the configurations in order, in the batches q[bounds[b, 0]:bounds[b, 1]] from batch i
    on, levels_12 stopping at the first one proven colliding, the open entries of those before it tested
    by their triangles (triangle_tests), up to the first batch with a collision or with entries left for
    FCL — one call for a search's motion, where a call per batch cost more in Python around the kernels
    than the tests themselves. Returns (b, first, ok, R, t, env, slf, counts, n_tab, hits, dropped): the
    batch it stopped at (len(bounds): none), the first configuration proven colliding (index into q, -1:
    none), of batch b the verdicts so far (ok), frames and the entries left for FCL (as levels_12's; only
    of configurations before `first`), counts (5,) the configurations of the batches by levels_12 status,
    n_tab the pairs the tables cleared, hits the configurations the triangles proved colliding, dropped
    the open configurations past `first` left undecided."""
    counts = np.zeros(5, dtype=np.int64)
    n_tab = 0
    hits = 0
    no_f = np.zeros(0)
    F = d.cols.shape[0]
    R, t = np.empty((0, F, 3, 3)), np.empty((0, F, 3))
    ok = np.ones(0, dtype=np.bool_)
    env, slf = np.empty((0, 3), dtype=np.int64), np.empty((0, 4), dtype=np.int64)
    while i < bounds.shape[0]:
        lo, hi = bounds[i, 0], bounds[i, 1]
        R, t, status, env, slf, nt = levels_12_until_hit(q[lo:hi], margin, self_padding, eps, d)
        n_tab += nt
        ok = np.empty(hi - lo, dtype=np.bool_)
        for k in range(hi - lo):
            counts[status[k]] += 1
            ok[k] = status[k] != STATUS_HIT
        if (env.shape[0] > 0 or slf.shape[0] > 0) and tri.shape[0] > 0:
            keep_e, keep_s, h = triangle_tests(
                R, t, ok, np.ascontiguousarray(env[:, 0]), np.ascontiguousarray(env[:, 1]),
                np.ascontiguousarray(env[:, 2]), False, no_f, np.ascontiguousarray(slf[:, 0]),
                np.ascontiguousarray(slf[:, 1]), np.ascontiguousarray(slf[:, 2]), self_padding, False, no_f, frame_of,
                tri, tri_c, tri_r, run_lo, run_hi, run_c, run_r, run_off, fR, ft, fh, frho, f_tight, f_pad, wit_slot,
                wit, wit_n, eps)
            hits += h
            env, slf = _compact(env, keep_e), _compact(slf, keep_s)
        first = hi - lo
        for k in range(hi - lo):
            if not ok[k]:
                first = k
                break
        dropped = 0
        if first < hi - lo:  # the open configurations past the first collision do not matter
            past = np.zeros(hi - lo, dtype=np.bool_)
            for k in range(env.shape[0]):
                past[env[k, 0]] = env[k, 0] > first
            for k in range(slf.shape[0]):
                past[slf[k, 0]] = slf[k, 0] > first
            dropped = past.sum()
            env, slf = _compact(env, env[:, 0] < first), _compact(slf, slf[:, 0] < first)
        if env.shape[0] > 0 or slf.shape[0] > 0 or first < hi - lo:
            return i, lo + first if first < hi - lo else -1, ok, R, t, env, slf, counts, n_tab, hits, dropped
        i += 1
    return i, -1, ok, R, t, env, slf, counts, n_tab, hits, 0


@nb.njit(cache=True, nogil=True)
def _box_sphere(tri, lo, hi, c, k) -> float:
    """The sphere of triangles tri[lo:hi] centred at their bounding box's centre: the centre into c[k], the
    radius returned."""
    for a in range(3):
        mn, mx = np.inf, -np.inf
        for i in range(lo, hi):
            for v in range(3):
                mn = min(mn, tri[i, v, a])
                mx = max(mx, tri[i, v, a])
        c[k, a] = (mn + mx) / 2
    r2 = 0.0
    for i in range(lo, hi):
        for v in range(3):
            d = 0.0
            for a in range(3):
                d += (tri[i, v, a] - c[k, a]) ** 2
            r2 = max(r2, d)
    return np.sqrt(r2)


@nb.njit(cache=True, nogil=True)
def triangle_spheres(tri, lo, hi):
    """Spheres bounding each triangle of tri (T, 3, 3) and each run tri[lo[k]:hi[k]] (non-empty), centred
    at their bounding boxes' centres (not the least spheres): (tri_c (T, 3), tri_r (T,), run_c (K, 3),
    run_r (K,)). Compiled: a checker is built per plan, and in numpy these cost 12 ms of each on TALOS's
    23k link triangles."""
    T, K = tri.shape[0], lo.shape[0]
    tri_c, tri_r = np.empty((T, 3)), np.empty(T)
    run_c, run_r = np.empty((K, 3)), np.empty(K)
    for i in range(T):
        tri_r[i] = _box_sphere(tri, i, i + 1, tri_c, i)
    for k in range(K):
        run_r[k] = _box_sphere(tri, lo[k], hi[k], run_c, k)
    return tri_c, tri_r, run_c, run_r


def warm() -> None:
    """Compile (or load from the cache) every kernel for the argument types the checker passes:
    `make test` runs this first, and the node before its first plan, so that no plan compiles (~15 s)."""
    i, b = np.int64, np.bool_
    R, t = np.zeros((1, 1, 3, 3)), np.zeros((1, 1, 3))
    tree = (np.zeros((1, 1)), np.zeros(1, i), np.full(1, -1, i), np.zeros(1, b), np.zeros((1, 16, 3)))
    fk_batch(*tree, R, t)
    e1, e2, e3 = np.zeros(0, i), np.zeros((0, 3)), np.zeros((0, 3, 3))
    one = np.zeros((1, 1))
    d = make_kernel_data(*tree[1:],
                         np.zeros(1, i), np.zeros((1, 3)), np.zeros(1),
                         e1, e1, e3, e2, e2, np.zeros(0),
                         e3, e2, e2, np.zeros(0), np.zeros(0), np.zeros(0, b),
                         np.zeros((0, 1, 3)), np.zeros((0, 1)), e1, np.zeros((0, 1, 3)), np.zeros((0, 1)), e1,
                         e1, e1, np.zeros(0, b), np.zeros(0),
                         np.zeros((1, 3, 3)), np.zeros((1, 3)), np.zeros((1, 3)), np.zeros(1), np.zeros(1, b),
                         np.zeros((1, 1, 3)), np.zeros((1, 1)), np.zeros(1, i), np.zeros((1, 1), i),
                         np.zeros((1, 1, 3)), np.zeros((1, 1)), np.zeros(1, i), np.zeros((1, 1), i),
                         np.zeros((0, 1, 3)), e1, np.zeros((0, 1, 4)), e1, np.zeros(0, b), np.zeros(0, b), e2, np.zeros(0), e3, e2, e1,
                         np.zeros((0, 1, 3)), e1, np.zeros((0, 1, 4)), e1,
                         np.zeros(0, b), e3, e2, e2,
                         False, np.zeros(3), 1.0, np.ones(3, i), np.zeros(2, i), e1, e1, np.zeros(1), np.zeros((1, 1), i),
                         np.zeros((0, 2), i), e1, np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2), i), e1,
                         np.zeros(0), np.zeros(0, i), np.zeros(0, i), np.zeros(0, i),
                         e1, e2, False, e1, e3, e2, e2, np.zeros(0), e1, e1, e1, False, e1, e1, np.zeros(0), e1, e1, e1)
    levels_12(tree[0], False, one, False, one, 0.0, 0.0, 1e-4, d)
    levels_12_until_hit(tree[0], 0.0, 0.0, 1e-4, d)
    screen_batches(tree[0], np.array([[0, 1]]), 0, 0.0, 0.0, 1e-4, d, np.zeros(1, i), np.zeros((0, 3, 3)), e2,
                   np.zeros(0), e1, e1, e2, np.zeros(0), np.zeros(2, i), e3, e2, e2, np.zeros(0), np.zeros(0, b),
                   np.zeros(0), np.zeros((0, 0), i), np.zeros((0, 4, 2), i), e1)
    mesh_box_entries(R, t, e1, e1, e1, np.zeros(0), np.zeros(1, i), np.zeros((0, 3, 3)), e2, np.zeros(0), e1, e1, e2,
                     np.zeros(0), np.zeros(2, i), e3, e2, e2, np.zeros(0), np.zeros(0, b), 1e-4)
    triangle_spheres(np.zeros((1, 3, 3)), np.zeros(1, i), np.ones(1, i))
    triangle_tests(R, t, np.ones(1, b), e1, e1, e1, False, np.zeros(0), e1, e1, e1, 0.0, False, np.zeros(0),
                   np.zeros(1, i), np.zeros((0, 3, 3)), e2, np.zeros(0), e1, e1, e2, np.zeros(0), np.zeros(2, i), e3, e2,
                   e2, np.zeros(0), np.zeros(0, b), np.zeros(0), np.zeros((0, 0), i), np.zeros((0, 4, 2), i), e1, 1e-4)
