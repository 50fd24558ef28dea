"""Path guidance for POINTING slews: the shortest way round the keep-out zones, flown by pursuit.

The paper's law heads straight for its target and turns only inside a zone's eps-layer, so a slew
whose great circle crosses a zone runs into the layer and creeps round its edge (bench/slew.py: the
S1->S2 slew took 1.59 times an unconstrained eigen-axis slew, while its shortest safe path allows 1.20).
Here, on a new target, the flight software plans the shortest boresight path that keeps a standoff
from every zone the law avoids (a visibility graph over convex polygons drawn round the zones) and then
moves the law's target x_d along it, a look-ahead beyond the boresight. The law still runs on the
inflated zones with its eps chosen for that x_d, so the paper's invariance of the inflated zones holds
whatever x_d is: the plan only chooses which way round; the last leg is the paper's law to the real
target. Design note 10 in docs/design-notes.md.
"""
from __future__ import annotations

import heapq
import math

import numpy as np
from scipy.spatial import ConvexHull

from fsw.guidance._kernels import aim_index_nb
from gnc.sky_zones import cap_of

# a polygon about the kernel in one gnomonic chart needs every vertex inside the hemisphere (the Earth
# zone from 500 km with a 15 deg polygon, 3 deg margin and 2 deg standoff reaches 88 deg)
_MAX_POLYGON_RADIUS_RAD = math.radians(89.5)
_TOUCH = 1e-12    # products of signed distances below this are touching


def planning_polygon(zone, standoff_deg: float, rays: int) -> tuple[np.ndarray, np.ndarray] | None:
    """Convex polygon round ``zone`` with every side ``standoff_deg`` outside it: (vertices, inward edge
    normals), or None when the zone plus standoff reaches too near the far side of its kernel's
    hemisphere for one gnomonic chart.

    The zone's boundary (a polygon's own vertices, else ``rays`` boundary samples) is replaced by its
    convex hull in the gnomonic chart about the kernel (great circles are straight lines there, so this
    is the spherical hull, and a star-shaped zone's notches count as blocked: a path through a notch
    would only be a shortcut for the law to undo); each side is then moved out by the standoff (plus the
    sagitta of a sampled curved boundary) and the vertices put where neighbouring moved sides meet.
    """
    g, cap = cap_of(zone)
    s = math.radians(standoff_deg)
    if cap + s > _MAX_POLYGON_RADIUS_RAD:
        return None
    exact = getattr(zone, "shape", None) == "polygon"  # its own vertices; other shapes are sampled
    B = zone.vertices_sphere if exact else zone.boundary(rays)
    e1 = np.cross(g, [0.0, 0.0, 1.0] if abs(g[2]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(g, e1)
    uv = np.column_stack([B @ e1, B @ e2]) / (B @ g)[:, None]
    P = B[ConvexHull(uv).vertices]  # counter-clockwise about g seen from outside
    if not exact:
        # sides between boundary samples cut inside a curved boundary by their sagitta, about
        # length x turning / 8: moved out by that much more, the polygon contains the zone
        length = _successive_angles(P)
        turn = _successive_angles(_sides(P))
        s += float(np.max(length * np.maximum(turn, np.roll(turn, 1)))) / 8.0
    P, N = _fewer_sides(P, g, 2.0 * math.pi / rays)
    if s > 0.0:
        # the vertex at distance s outside both sides through P_i: w.a = w.b = -sin s, |w| = 1
        a, b = np.roll(N, 1, axis=0), N
        c = np.einsum("ij,ij->i", a, b)
        x = -math.sin(s) / (1.0 + c)
        axb = np.cross(a, b)
        axb /= np.linalg.norm(axb, axis=1)[:, None] * np.sign(np.einsum("ij,ij->i", axb, P))[:, None]
        z = np.sqrt(np.maximum(0.0, 1.0 - 2.0 * math.sin(s) ** 2 / (1.0 + c)))
        P = x[:, None] * (a + b) + z[:, None] * axb
        N = _sides(P)
    return P, N


def _successive_angles(U: np.ndarray) -> np.ndarray:
    """Angle [rad] between each unit row and the next, cyclically."""
    return np.arccos(np.clip(np.einsum("ij,ij->i", U, np.roll(U, -1, axis=0)), -1.0, 1.0))


def path_length_deg(vertices: np.ndarray) -> float:
    """Length [deg] of the great-circle legs through ``vertices`` (an open path)."""
    return float(np.degrees(_successive_angles(vertices)[:-1]).sum())


def _sides(P: np.ndarray) -> np.ndarray:
    """Inward unit normals of the sides P_i -> P_i+1 of a counter-clockwise convex polygon."""
    N = np.cross(P, np.roll(P, -1, axis=0))
    return N / np.linalg.norm(N, axis=1)[:, None]


def _fewer_sides(P: np.ndarray, g: np.ndarray, turn_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """A circumscribed convex polygon keeping only sides that turn by ``turn_rad`` or more from the last
    kept one (a sampled circle of 360 points becomes ~2 pi / turn_rad sides; a long straight side is
    always kept). The kept sides' great circles meet outside the dropped run, so it still contains P.
    The visibility graph costs the square of the vertex count."""
    N = _sides(P)
    turning = _successive_angles(N)
    step = np.floor(np.concatenate([[0.0], np.cumsum(turning)[:-1]]) / turn_rad)
    keep = np.flatnonzero(np.diff(np.concatenate([[-1.0], step])) > 0)
    if len(keep) == len(N) or len(keep) < 3:
        return P, N
    a, b = N[keep], np.roll(N[keep], -1, axis=0)
    V = np.cross(a, b)
    V /= np.linalg.norm(V, axis=1)[:, None]
    V *= np.sign(V @ g)[:, None]  # of the two points where the circles meet, the one on the kernel's side
    P = np.roll(V, 1, axis=0)  # vertex k starts kept side k
    return P, _sides(P)


def _inside(X: np.ndarray, N: np.ndarray) -> np.ndarray:
    """Which rows of X lie strictly inside the convex polygon with inward normals N."""
    return np.all(X @ N.T > 1e-9, axis=1)


def _blocked(nodes: np.ndarray, i: np.ndarray, j: np.ndarray, sc: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """For each arc nodes[i_k] -> nodes[j_k] (shorter than 180 deg): does it cross or touch a polygon side
    nodes[sc_s] -> nodes[sd_s] that does not end at one of its own nodes? Touching counts (an arc through
    a polygon vertex may enter the polygon there). Each arc must straddle the other's great circle, at
    the same one of the two points where the circles meet: the one on the side of both midpoints."""
    A, B, C, D = nodes[i], nodes[j], nodes[sc], nodes[sd]
    n1, n2 = np.cross(A, B), np.cross(C, D)
    straddle1 = (n1 @ C.T) * (n1 @ D.T) <= _TOUCH
    straddle2 = (A @ n2.T) * (B @ n2.T) <= _TOUCH
    p = np.cross(n1[:, None, :], n2[None, :, :])
    same_point = np.einsum("ksj,kj->ks", p, A + B) * np.einsum("ksj,sj->ks", p, C + D) > 0.0
    own = ((i[:, None] == sc[None, :]) | (i[:, None] == sd[None, :]) |
           (j[:, None] == sc[None, :]) | (j[:, None] == sd[None, :]))
    return np.any(straddle1 & straddle2 & same_point & ~own, axis=1)


def _kept_polygon(zone, standoff_deg: float, rays: int, kept: dict | None):
    """`planning_polygon`, taken from ``kept`` when the same zone object (zones are immutable) was planned
    round at the same standoff and rays before; its arrays read-only, as the planner only reads them."""
    if kept is None:
        return planning_polygon(zone, standoff_deg, rays)
    key = (id(zone), standoff_deg, rays)
    entry = kept.get(key)
    if entry is not None and entry[0] is zone:
        return entry[1]
    poly = planning_polygon(zone, standoff_deg, rays)
    if poly is not None:
        poly[0].setflags(write=False)
        poly[1].setflags(write=False)
    if len(kept) > 64:
        kept.clear()
    kept[key] = (zone, poly)
    return poly


def plan_path(start: np.ndarray, end: np.ndarray, zones: list, standoff_deg: float,
              rays: int = 48, kept: dict | None = None) -> np.ndarray | None:
    """Vertices (start, ..., end) of the shortest boresight path keeping ``standoff_deg`` from every
    zone (within the polygon approximation), or None when there is none or the zones are too large to
    plan round. A zone within the standoff of the start or the end is planned round at zero standoff.

    Visibility graph on start, end and the polygon vertices. Besides polygon sides, a shortest path only
    uses tangent segments (both neighbours of a polygon vertex on the same side of the segment), so only
    those and the sides are tested against every polygon side. ``kept``: a dict the caller keeps between
    plans, for the polygons of zones planned round before (`_kept_polygon`; the same polygons).
    """
    start, end = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    polys = []
    for z in zones:
        poly = _kept_polygon(z, standoff_deg, rays, kept)
        if poly is not None and _inside(np.array([start, end]), poly[1]).any():
            poly = _kept_polygon(z, 0.0, rays, kept)
        if poly is None or _inside(np.array([start, end]), poly[1]).any():
            return None
        polys.append(poly)
    nodes = np.vstack([start, end] + [P for P, _ in polys])
    m = len(nodes)
    owner = np.full(m, -1)
    prev_pt, next_pt = nodes.copy(), nodes.copy()
    sc, sd = [], []  # every polygon side, as the node indices of its ends
    off = 2
    for k, (P, _) in enumerate(polys):
        owner[off:off + len(P)] = k
        prev_pt[off:off + len(P)] = np.roll(P, 1, axis=0)
        next_pt[off:off + len(P)] = np.roll(P, -1, axis=0)
        sc.append(np.arange(off, off + len(P)))
        sd.append(np.roll(sc[-1], -1))
        off += len(P)
    sc = np.concatenate(sc) if polys else np.zeros(0, dtype=int)
    sd = np.concatenate(sd) if polys else np.zeros(0, dtype=int)
    usable = np.ones(m, dtype=bool)
    for k, (_, N) in enumerate(polys):
        usable &= ~(_inside(nodes, N) & (owner != k))

    # candidate segments: tangent at both ends (start and end are tangent to everything)
    n = np.cross(nodes[:, None, :], nodes[None, :, :])
    side_prev = np.einsum("ik,ijk->ij", prev_pt, n)
    side_next = np.einsum("ik,ijk->ij", next_pt, n)
    tangent = (side_prev * side_next >= 0.0) | (owner < 0)[:, None]
    cand = tangent & tangent.T & usable[:, None] & usable[None, :]
    cand &= ~((owner[:, None] == owner[None, :]) & (owner[:, None] >= 0))  # chords and sides: below
    i, j = np.nonzero(np.triu(cand, 1))
    # the polygon sides are edges too, unless another polygon overlaps them
    i = np.concatenate([i, sc[usable[sc] & usable[sd]]])
    j = np.concatenate([j, sd[usable[sc] & usable[sd]]])
    if len(i) and len(sc):
        free = ~_blocked(nodes, i, j, sc, sd)
        i, j = i[free], j[free]
    edges = list(zip(i.tolist(), j.tolist()))
    return shortest_route(nodes, edges)


def shortest_route(nodes: np.ndarray, edges: list[tuple[int, int]]) -> np.ndarray | None:
    """Dijkstra from nodes[0] to nodes[1] over great-circle ``edges``: the route's nodes, or None."""
    adj: dict[int, list[tuple[int, float]]] = {}
    for a, b in edges:
        length = math.acos(max(-1.0, min(1.0, float(nodes[a] @ nodes[b]))))
        adj.setdefault(a, []).append((b, length))
        adj.setdefault(b, []).append((a, length))
    dist, prev = {0: 0.0}, {0: -1}
    heap = [(0.0, 0)]
    while heap:
        d, a = heapq.heappop(heap)
        if a == 1:
            path = []
            while a >= 0:
                path.append(nodes[a])
                a = prev[a]
            return np.array(path[::-1])
        if d > dist.get(a, math.inf):
            continue
        for b, length in adj.get(a, ()):
            if d + length < dist.get(b, math.inf):
                dist[b], prev[b] = d + length, a
                heapq.heappush(heap, (d + length, b))
    return None


def densify(vertices: np.ndarray, step_deg: float) -> np.ndarray:
    """The path's great-circle legs sampled every ``step_deg`` or closer, every vertex kept."""
    out = [vertices[0]]
    for a, b in zip(vertices[:-1], vertices[1:]):
        ang = math.acos(max(-1.0, min(1.0, float(a @ b))))
        k = max(1, math.ceil(math.degrees(ang) / step_deg))
        s = np.arange(1, k + 1) / k
        out.extend((np.sin((1.0 - s) * ang)[:, None] * a + np.sin(s * ang)[:, None] * b) / math.sin(ang)
                   if ang > 1e-12 else [b])
    return np.array(out)


class PathFollower:
    """Pure pursuit along a planned path: the aim is the first path point at least ``lookahead_deg`` from
    the boresight beyond the path point nearest to it, and the path's end once that is nearer.

    Progress along the path only goes forward (the nearest point is searched from the last one on): a
    boresight pushed back by the law's repulsion does not pull the aim back with it."""

    STEP_DEG = 0.5

    def __init__(self, vertices: np.ndarray, lookahead_deg: float):
        self.path = np.ascontiguousarray(densify(vertices, self.STEP_DEG), dtype=float)
        self.cos_ahead = math.cos(math.radians(lookahead_deg))
        self.index = 0

    def aim_index(self, y: np.ndarray) -> int:
        """Index in ``path`` of the law's target for boresight ``y`` (the last index: the path's end).
        Every cycle of a planned slew: one compiled pass (`fsw.guidance._kernels.aim_index_nb`)."""
        self.index, aim = aim_index_nb(self.path, self.index, np.ascontiguousarray(y, dtype=float), self.cos_ahead)
        return int(aim)


def advance_aim(follower: PathFollower, x: np.ndarray, aim_k: int, target: np.ndarray
                ) -> tuple[bool, PathFollower | None, np.ndarray | None, int]:
    """The law's aim for the state ``x`` on ``follower``'s path, its index having been ``aim_k``:
    (moved, follower, aim, index). On the path's last point the path is done: (True, None, target, -1),
    the last leg being the paper's law to the real target. Unmoved: (False, follower, None, aim_k)."""
    k = follower.aim_index(x)
    if k == aim_k:
        return False, follower, None, aim_k
    if k == len(follower.path) - 1:
        return True, None, target, -1
    return True, follower, follower.path[k], k
