"""Route distances around the radars, on a grid: the wavefront planner behind the guidance controller's
navigation function and behind the reward's approach term.

Both need, per layout, the length of the shortest way from every point of the area to the SAM's
detection disk (which layouts keep free of radars), going around the radars rather than through them.
:func:`wavefront` computes it on a square grid: a chamfer distance, relaxed to convergence, with a
per-cell traversal cost (1 in free air, more or infinite inside a radar). :class:`FieldCache` keeps one
field per world and recomputes it only when that world gets a new layout (the worlds reset together in one batch of
:func:`wavefronts`). :class:`RouteMap` turns a field into the *detour*: how much longer the way to the disk is than
the straight line.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from tssac_core.sim.world import cached_constant, constant_operand
from tssac_core.sim.world_state import WorldState

_SQRT2, _SQRT5 = float(np.sqrt(2.0)), float(np.sqrt(5.0))
KING_MOVES = [((1, 0), 1.0), ((-1, 0), 1.0), ((0, 1), 1.0), ((0, -1), 1.0)] + [
    ((a, b), _SQRT2) for a in (1, -1) for b in (1, -1)
]
"""8 neighbours: distances at most 8% longer than the straight line."""
KNIGHT_MOVES = KING_MOVES + [((a * p, b * q), _SQRT5) for a in (1, -1) for b in (1, -1) for p, q in ((1, 2), (2, 1))]
"""16 neighbours: at most 2.7% longer (the reward uses these: its approach term measures progress)."""


def wavefront(
    goal: np.ndarray, step_cost: np.ndarray, moves: list[tuple[tuple[int, int], float]] = KING_MOVES
) -> np.ndarray:
    """Shortest-path length (in cells) from every cell to the nearest ``goal`` cell.

    A move from cell a to cell b of length L costs ``L * (step_cost[a] + step_cost[b]) / 2``; cells of
    infinite cost are impassable and cells that cannot reach the goal get ``inf``. Iterated to the
    fixed point, so the result is exact for the move set. One grid of :func:`wavefronts`.
    """
    return wavefronts(goal[None], np.asarray(step_cost)[None], moves)[0]


WAVEFRONT_BATCH = 16
"""Grids relaxed together by :func:`wavefronts`: the line sweeps' thousands of small numpy calls per grid are paid once
per batch; a batch runs as many whole-grid sweeps as its slowest grid needs, so larger batches gain no more (100 x 100
route fields: about 2.5x less time per field than one at a time, at 16)."""


def wavefronts(
    goals: np.ndarray, step_costs: np.ndarray, moves: list[tuple[tuple[int, int], float]] = KING_MOVES
) -> np.ndarray:
    """:func:`wavefront` of each of B grids, (B, size, size) goals and step costs: the same numbers, to the bit, as
    one grid at a time (every grid is relaxed by the same operations in the same order, and further sweeps leave a
    grid at its fixed point unchanged), in batches of :data:`WAVEFRONT_BATCH`.

    Every relaxation is ``d_b = min(d_b, (d_a + L c_a / 2) + L c_b / 2)``, in this order of operations.
    The order in which relaxations are applied does not change the result, to the bit: starting from
    +inf, each relaxation is monotone in d and never goes below any fixed point, so the distances only
    fall and stay at or above the largest fixed point; iterating until a sweep of every relaxation
    changes nothing ends on a fixed point, hence on the largest one, whatever came before. So the schedule
    is chosen for speed: first :data:`LINE_SWEEP_ROUNDS` rounds of line sweeps (:func:`_line_sweeps`),
    which carry a distance across the whole grid in one pass, then whole-grid sweeps, each relaxing every
    move once (in place: a move sees what the moves before it in the same sweep found), until one changes
    nothing in any grid of the batch (after the line sweeps, one to five).
    """
    goals = np.asarray(goals, dtype=bool)
    step_costs = np.asarray(step_costs, dtype=np.float64)
    out = np.empty(goals.shape)
    for b in range(0, len(goals), WAVEFRONT_BATCH):
        out[b : b + WAVEFRONT_BATCH] = _wavefront_batch(
            goals[b : b + WAVEFRONT_BATCH], step_costs[b : b + WAVEFRONT_BATCH], tuple(moves)
        )
    return out


def _wavefront_batch(
    goal: np.ndarray, step_cost: np.ndarray, moves: tuple[tuple[tuple[int, int], float], ...]
) -> np.ndarray:
    """The grids of a batch, relaxed cell-major, (size_i, size_j, B): every gather then moves B numbers at once."""
    n_grids, size_i, size_j = goal.shape
    pad = max(max(abs(a), abs(b)) for (a, b), _ in moves)  # the longest move's reach
    half = np.full((size_i + 2 * pad, size_j + 2 * pad, n_grids), np.inf)
    inner = (slice(pad, pad + size_i), slice(pad, pad + size_j))
    half[inner] = 0.5 * step_cost.transpose(1, 2, 0)
    weighted = {length: length * half for _, length in moves}  # L c / 2, padded (the padding impassable)
    padded = np.full(half.shape, np.inf)
    dist = padded[inner]
    at_goal = goal.transpose(1, 2, 0)
    dist[at_goal] = 0.0
    _line_sweeps(padded, pad, weighted, moves)
    relaxations = []  # per move: where from, where to, and the two halves of its cost there
    for (a, b), length in moves:
        src = (slice(max(a, 0), size_i + min(a, 0)), slice(max(b, 0), size_j + min(b, 0)))
        dst = (slice(max(-a, 0), size_i + min(-a, 0)), slice(max(-b, 0), size_j + min(-b, 0)))
        cost = weighted[length][inner]
        relaxations.append((src, dst, cost[src], cost[dst]))
    while True:
        before = dist.copy()
        for src, dst, cost_src, cost_dst in relaxations:
            via = dist[src] + cost_src
            via += cost_dst  # (d_a + L c_a / 2) + L c_b / 2, in this order
            np.minimum(dist[dst], via, out=dist[dst])
        dist[at_goal] = 0.0
        if np.array_equal(before, dist):
            return dist.transpose(2, 0, 1).copy()


LINE_SWEEP_ROUNDS = 2
"""Rounds of line sweeps before the whole-grid sweeps. On the 100 x 100 route fields two leave the
whole-grid sweeps 1-5 passes, and the field takes 2.4x less time than with whole-grid sweeps alone (one
round: 1.4x, it leaves 10-50 passes; three: 1.8x, a round costs more than the passes it saves)."""


def _line_sweeps(
    padded: np.ndarray, pad: int, weighted: dict[float, np.ndarray], moves: tuple[tuple[tuple[int, int], float], ...]
) -> None:
    """Relax the ``padded`` distances of a batch of grids (rows, cols, B) in line sweeps: each grid with ``pad``
    cells (the longest move's reach) of impassable padding round it, at +inf; ``weighted`` holds each move length's
    L c / 2, padded likewise.

    A whole-grid sweep applies each move to all cells at once, so a distance travels one move per sweep,
    and the fields take 40-80 sweeps. A line sweep goes through the rows (or columns) in order and
    relaxes each line from the lines already done, with every move that comes from that side: a path
    that runs one way along the axis is found in one pass, however long. Four directions (rows up and
    down, columns up and down) make a round. Relaxations from the padding give +inf: no-ops.
    """
    n_grids = padded.shape[2]
    flat = padded.reshape(-1, n_grids)
    lengths = sorted(weighted)
    costs = np.stack([weighted[length].reshape(-1, n_grids) for length in lengths]).reshape(-1, n_grids)
    inner = padded[pad:-pad, pad:-pad]
    for _ in range(LINE_SWEEP_ROUNDS):
        for axis, lines, src, src_cost, dst_cost in _line_plan(padded.shape[:2], pad, moves):
            cost_src, cost_dst = costs.take(src_cost, axis=0), costs.take(dst_cost, axis=0)  # (lines, moves, cells, B)
            view = inner if axis == 0 else inner.transpose(1, 0, 2)
            for n, line in enumerate(lines):
                via = flat.take(src[n], axis=0)
                via += cost_src[n]
                via += cost_dst[n]  # (d_a + L c_a / 2) + L c_b / 2, as in the whole-grid sweeps
                np.minimum(view[line], np.minimum.reduce(via, axis=0), out=view[line])


@functools.lru_cache(maxsize=8)
def _line_plan(
    padded_shape: tuple[int, int], pad: int, moves: tuple[tuple[tuple[int, int], float], ...]
) -> list[tuple]:
    """Per direction of a line sweep: (axis, line order, source cells (lines, moves, cells) as flat indices
    into one padded grid, and the source's and destination's entries in its costs stacked by move length)."""
    rows, cols = padded_shape
    size = rows * cols
    lengths = sorted({length for _, length in moves})
    plan = []
    for axis in (0, 1):
        for step in (1, -1):
            # A move (a, b) relaxes cell p from p + (a, b): in a sweep along ``axis`` in direction ``step``
            # the moves whose source lies in a line already swept.
            chosen = [m for m, ((a, b), _) in enumerate(moves) if (a, b)[axis] * step < 0]
            if not chosen:
                continue
            n_lines, n_cells = (rows, cols)[axis] - 2 * pad, (rows, cols)[1 - axis] - 2 * pad
            line, cell = np.meshgrid(np.arange(n_lines), np.arange(n_cells), indexing="ij")
            i, j = (line, cell) if axis == 0 else (cell, line)
            dst = (i + pad) * cols + (j + pad)  # (lines, cells)
            src = np.stack([dst + moves[m][0][0] * cols + moves[m][0][1] for m in chosen], axis=1)
            # where each move's length's costs start in the stack
            offset = (np.array([lengths.index(moves[m][1]) for m in chosen]) * size)[None, :, None]
            order = range(n_lines) if step > 0 else range(n_lines - 1, -1, -1)
            plan.append(
                (
                    axis,
                    list(order),
                    src[list(order)],
                    (src + offset)[list(order)],
                    (dst[:, None, :] + offset)[list(order)],
                )
            )
    return plan


def cell_centres(area_m: float, grid_m: float) -> tuple[np.ndarray, np.ndarray]:
    """x and y of every cell centre, (size, size) each, indexed [i (x), j (y)]."""
    size = int(np.ceil(area_m / grid_m))
    centres = (np.arange(size) + 0.5) * grid_m
    return np.meshgrid(centres, centres, indexing="ij")


def radar_depth(state: WorldState, k: int, cx: np.ndarray, cy: np.ndarray, margin_m: float) -> np.ndarray:
    """How deep every cell lies inside world k's radars inflated by ``margin_m`` (<= 0: outside all), metres."""
    depth = np.full(cx.shape, -np.inf)
    for pos, r in zip(state.radar_m[k], state.radar_r_m[k]):
        if r > 0:
            depth = np.maximum(depth, r + margin_m - np.hypot(cx - pos[0], cy - pos[1]))
    return depth


def sam_disk(state: WorldState, k: int, cx: np.ndarray, cy: np.ndarray) -> np.ndarray:
    """Cells whose centre lies in world k's SAM detection disk (D <= R4)."""
    sam = state.sam_m[k]
    return np.hypot(cx - sam[0], cy - sam[1]) <= state.c.r4_m


class FieldCache:
    """One grid field per world of a :class:`WorldState`, rebuilt only for worlds whose SAM or radars changed.

    Keyed by the layout's content, not only by the state's ``layout_token``, so that a cache stays right when
    the World it serves is replaced (a resumed training run unpickles its worlds into a task that was
    built afresh); the token is the fast path while the layouts stay the same.
    """

    def __init__(self, build: Callable[[WorldState, np.ndarray], np.ndarray]) -> None:
        self.build = build
        """The fields of the worlds of the given indices, (K, size, size): the changed worlds are built at once."""
        self._fields: np.ndarray | None = None
        self._keys: np.ndarray | None = None
        self._token: object = None

    def fields(self, state: WorldState) -> np.ndarray:
        """(N, size, size) fields, current for every world's layout."""
        # Every step asks: one identity comparison while nothing was reset.
        if self._fields is not None and self._token is not None and state.layout_token is self._token:
            return self._fields
        keys = np.concatenate([state.sam_m, state.radar_m.reshape(state.n, -1), state.radar_r_m], axis=1)
        if self._fields is None or self._keys is None or self._keys.shape != keys.shape:
            self._fields, self._keys = None, np.full(keys.shape, np.nan)
        changed = np.flatnonzero(np.any(self._keys != keys, axis=1))
        if len(changed):
            built = self.build(state, changed)
            if self._fields is None:
                self._fields = np.zeros((state.n, *built.shape[1:]), dtype=np.float32)
            self._fields[changed] = built
            self._keys[changed] = keys[changed]
        assert self._fields is not None
        self._token = state.layout_token
        return self._fields


def sample_bilinear(fields: np.ndarray, grid_m: float, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of each world's field (N, size, size) at positions (N, K) in metres."""
    return _sample_stacked(fields, grid_m, np.stack([x_m, y_m]))


def _sample_stacked(fields: np.ndarray, grid_m: float, xy_m: np.ndarray) -> np.ndarray:
    """:func:`sample_bilinear` at positions stacked x over y, (2, N, K)."""
    n, size = fields.shape[0], fields.shape[1]
    f = xy_m * cached_constant(1.0 / grid_m)  # fractional cell coordinates, x and y in one call per operation
    f -= _HALF
    np.maximum(f, _ZERO, out=f)
    np.minimum(f, cached_constant(size - 1.000001), out=f)  # so that the lower corner index is at most size - 2
    cell = np.trunc(f)  # the lower corner (i, j); f >= 0, so truncation is the floor
    t = f - cell  # (tx, ty): the same numbers as f minus the integer corner, without a mixed-type call
    ij = cell.astype(np.intp)
    # The flat index of cell (i, j) of world w: (w size + i) size + j. Afresh, not in place: with one
    # vehicle in one world k has a single element, and an in-place update of that takes numpy's slow path.
    k = ij[0] * size + ij[1]
    # The four corners in one gather, corner-major (4, N, K): (i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1),
    # so that the corners at j and those at j + 1 are contiguous (2, N, K) halves.
    corners = fields.reshape(-1).take(k + _corner_offsets(n, size))
    rise = (corners[2:] - corners[:2]).astype(np.float64)  # along y at i and at i + 1, in float32 as the fields
    np.multiply(rise, t[1], out=rise)
    low, high = corners[:2].astype(np.float64) + rise  # the float32 corners promoted in a call of their own
    return low + t[0] * (high - low)


@functools.lru_cache(maxsize=16)
def _corner_offsets(n: int, size: int) -> np.ndarray:
    """Where the four corners of cell (0, 0) of each world lie in the flattened (N, size, size) fields,
    (4, N, 1): the world's start plus (i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)."""
    return np.arange(n)[None, :, None] * (size * size) + np.array([0, size, 1, size + 1]).reshape(4, 1, 1)


def field_gradient(
    fields: np.ndarray, grid_m: float, x_m: np.ndarray, y_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Gradient (per cell) of each world's field at positions (N, K): central differences at the nearest
    cell, with the diagonal differences added to smooth the grid metric's preferred directions."""
    size = fields.shape[1]
    i = np.clip(np.round(x_m / grid_m - 0.5).astype(np.int64), 1, size - 2)
    j = np.clip(np.round(y_m / grid_m - 0.5).astype(np.int64), 1, size - 2)
    w = np.arange(fields.shape[0])[:, None]
    gx = fields[w, i + 1, j] - fields[w, i - 1, j]
    gy = fields[w, i, j + 1] - fields[w, i, j - 1]
    d1 = fields[w, i + 1, j + 1] - fields[w, i - 1, j - 1]
    d2 = fields[w, i + 1, j - 1] - fields[w, i - 1, j + 1]
    return gx + 0.5 * (d1 + d2), gy + 0.5 * (d1 - d2)


_ZERO, _HALF = constant_operand(0.0), constant_operand(0.5)


@dataclass(frozen=True)
class RouteConfig:
    """The route field of the reward's approach term."""

    grid_m: float = 1000.0
    margin_m: float = 3000.0
    """Radars count as hazards out to radius + this margin (the guidance controller plans with 3 km too)."""
    hazard_weight: float = 5.0
    """Flying a metre inside a radar counts as this many metres of route, so a way around the radars is
    shorter unless it is more than this many times as long (finite, so the field has no jumps and a UAV
    inside a radar still has a way out)."""
    edge_margin_m: float = 0.0
    """Cells within this distance of the area's edge count as hazards too (0: the edge is only the grid's end):
    the route a monitored pilot follows leaves the monitor's backups their room at the geofence
    (:class:`~tssac_core.sim.pilot_view.PilotView`)."""


class RouteMap:
    """The detour of every vehicle: route length to the SAM's detection disk minus the straight-line length.

    Zero inside the disk and on a straight, free line to it; grows in front of radars that block the
    straight line. ``zone distance + detour`` is the length of the way to a role's zone around the
    radars, which the reward's approach term measures (:mod:`tssac_core.sim.reward`).
    """

    def __init__(self, cfg: RouteConfig = RouteConfig()) -> None:
        self.cfg = cfg
        self.cache = FieldCache(self._build)

    def _build(self, state: WorldState, worlds: np.ndarray) -> np.ndarray:
        cfg = self.cfg
        cx, cy = cell_centres(state.c.area_m, cfg.grid_m)
        goals = np.stack([sam_disk(state, int(k), cx, cy) for k in worlds])
        inside = np.stack([radar_depth(state, int(k), cx, cy, cfg.margin_m) > 0 for k in worlds])
        if cfg.edge_margin_m > 0:
            area, edge = state.c.area_m, cfg.edge_margin_m
            inside |= (np.minimum(cx, cy) < edge) | (np.maximum(cx, cy) > area - edge)
        return wavefronts(goals, np.where(inside, cfg.hazard_weight, 1.0), KNIGHT_MOVES) * cfg.grid_m

    def detour_m(self, state: WorldState, vehicle: int | None = None) -> np.ndarray:
        """Detour in metres of every vehicle, (N, 3), or of one vehicle index, (N,)."""
        cols = slice(None) if vehicle is None else slice(vehicle, vehicle + 1)
        # (2, N, 3 or 1), copied: one vehicle's column is a strided view, and a copy costs less than the
        # slower path numpy takes for strided operands in the next calls.
        xy = state.xy_m[:, :, cols].copy()
        route = _sample_stacked(self.cache.fields(state), self.cfg.grid_m, xy)
        to_sam = xy - state.sam_xy_m[:, :, cols].copy()
        # Afresh, not in place: one vehicle's (N, 1) arrays have a single element at N = 1, and an in-place
        # update of that takes numpy's slow path.
        straight = np.hypot(to_sam[0], to_sam[1]) - cached_constant(state.c.r4_m)
        route = np.maximum(route - straight, _ZERO)
        detour = np.where(straight > _ZERO, route, _ZERO)
        return detour if vehicle is None else detour[:, 0]

    def direction(self, state: WorldState, vehicle: int) -> np.ndarray:
        """Unit vector (N, 2), world frame, along which one vehicle's way to the SAM's detection disk
        starts (down the route field); straight at the SAM where the field is flat (inside the disk)."""
        x, y = state.x_m[:, vehicle : vehicle + 1], state.y_m[:, vehicle : vehicle + 1]
        gx, gy = field_gradient(self.cache.fields(state), self.cfg.grid_m, x, y)
        down = -np.concatenate([gx, gy], axis=1).astype(np.float64)
        to_sam = state.sam_m - np.concatenate([x, y], axis=1)
        norm = np.hypot(down[:, 0], down[:, 1])[:, None]
        flat = norm < 1e-3 * self.cfg.grid_m
        v = np.where(flat, to_sam, down)
        return v / np.maximum(np.hypot(v[:, 0], v[:, 1]), 1e-9)[:, None]
