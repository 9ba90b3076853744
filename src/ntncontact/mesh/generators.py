"""Structured Q4 mesh generators: rectangle, annulus, disk, half disk (Hertz cylinder).

Every generator returns a :class:`QuadMesh` whose cells are counter-clockwise and whose edge
sets are oriented with the body on the left of each edge (outward normal ``rot(-90)(b - a)``),
so surfaces can be handed straight to the contact and ALE layers (report sections 2.1, 4.1).
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ntncontact.mesh.quadmesh import MeshError, QuadMesh

__all__ = [
    "annulus",
    "disk",
    "geometric_breaks",
    "half_disk",
    "hertz_cylinder_mesh",
    "rectangle",
]


#: Memory a run needs per element, beyond the imports: peak resident size of 2-step dynamic
#: runs of 100 x 100 and 200 x 200 rectangles grew by 7.7 kB per element (stiffness triplets,
#: the sparse factor, the state and output arrays). The sparse factor grows a little faster than
#: the element count, so this under-estimates large meshes (contact runs of 10^4-6x10^4
#: elements measure 8-13 kB): only meshes that cannot fit are refused.
BYTES_PER_ELEMENT = 8_000


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (Linux MemAvailable, else physical)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def check_size(n_cells: int, what: str) -> None:
    """Raise MeshError, before anything is allocated, if a mesh of ``n_cells`` elements could
    not be run in the memory available (``what`` names the keys that set the count)."""
    needed = n_cells * BYTES_PER_ELEMENT
    available = available_memory()
    if available is not None and needed > available:
        raise MeshError(f"{what} = {n_cells:.3g} elements would need about "
                        f"{needed / 1e9:.3g} GB to run, more than the {available / 1e9:.3g} GB "
                        "of memory available")


# ----------------------------------------------------------------------------------------------
# spacing helpers
# ----------------------------------------------------------------------------------------------
def geometric_breaks(length: float, n: int, grading: float = 1.0) -> NDArray[np.float64]:
    """``n + 1`` coordinates from 0 to ``length`` whose cell sizes grow geometrically.

    ``grading`` is the ratio last/first cell size (1 gives a uniform division).
    """
    if n < 1:
        raise MeshError(f"need at least one element along a side, got n={n}")
    if not (length > 0 and np.isfinite(length)):
        raise MeshError(f"side length must be positive and finite, got {length}")
    if not (grading > 0 and np.isfinite(grading)):
        raise MeshError(f"grading must be positive and finite, got {grading}")
    ratio = grading ** (1.0 / (n - 1)) if n > 1 else 1.0
    sizes = ratio ** np.arange(n)
    breaks = length * np.concatenate(([0.0], np.cumsum(sizes))) / sizes.sum()
    breaks[-1] = length  # exact end point despite round-off in the cumulative sum
    return breaks


def _validated_breaks(breaks: ArrayLike, length: float, n: int, axis: str) -> NDArray[np.float64]:
    """Explicit break coordinates (relative to the origin), checked against ``length`` and ``n``."""
    b = np.asarray(breaks, dtype=float).reshape(-1)
    if b.size != n + 1:
        raise MeshError(f"{axis}_breaks has {b.size} entries but n{axis}={n} needs {n + 1}")
    if not np.all(np.diff(b) > 0):
        raise MeshError(f"{axis}_breaks must be strictly increasing")
    scale = max(abs(length), 1.0)
    # break ends must reproduce the side exactly up to round-off of the caller's arithmetic
    if abs(b[0]) > 1e-12 * scale or abs(b[-1] - length) > 1e-12 * scale:
        raise MeshError(
            f"{axis}_breaks must run from 0 to the side length {length} (relative to the origin),"
            f" got {b[0]} .. {b[-1]}"
        )
    b[0], b[-1] = 0.0, length
    return b


def _sizes_with_first(length: float, first: float, n: int, n_uniform: int = 1) -> NDArray:
    """``n`` cell sizes summing to ``length``: ``n_uniform`` cells of size ``first``, then a
    geometric progression ``first * r**k`` (k = 1, 2, ...) with the ratio ``r`` solved for."""
    if n_uniform > n:
        raise MeshError(f"{n_uniform} uniform cells do not fit into {n} cells")
    exponents = np.maximum(np.arange(n) - n_uniform + 1, 0)
    if n_uniform == n or np.isclose(first * n, length, rtol=1e-13):
        if not np.isclose(first * n, length, rtol=1e-9):
            raise MeshError(f"{n} cells of size {first} cannot cover length {length}")
        return np.full(n, length / n)
    if first * n_uniform >= length:
        raise MeshError(f"first cell size {first} is too large for length {length} with n={n}")

    def excess(ratio: float) -> float:
        return float(first * np.sum(ratio**exponents) - length)

    # excess(0) = first*n_uniform - length < 0 and excess grows monotonically with the ratio
    upper = 2.0
    while excess(upper) < 0:
        upper *= 2.0
    from scipy.optimize import brentq  # here: scipy.optimize takes 0.1 s to import

    ratio = brentq(excess, 0.0, upper, xtol=1e-15, rtol=1e-14)
    sizes = first * ratio**exponents
    return sizes * (length / sizes.sum())


def _chain_edges(chain: NDArray[np.int64]) -> NDArray[np.int64]:
    """Consecutive node pairs of an ordered node chain."""
    return np.column_stack((chain[:-1], chain[1:]))


def _grid_cells(grid: NDArray[np.int64]) -> NDArray[np.int64]:
    """Q4 cells of a logically structured node grid ``grid[j, i]``.

    The cells are counter-clockwise when ``i`` runs along +x-like and ``j`` along +y-like
    directions of a right-handed frame (the callers arrange their grids that way).
    """
    return np.stack(
        (grid[:-1, :-1], grid[:-1, 1:], grid[1:, 1:], grid[1:, :-1]), axis=-1
    ).reshape(-1, 4)


# ----------------------------------------------------------------------------------------------
# rectangle
# ----------------------------------------------------------------------------------------------
def rectangle(
    width: float,
    height: float,
    nx: int,
    ny: int,
    origin: Sequence[float] = (0.0, 0.0),
    grading_x: float = 1.0,
    grading_y: float = 1.0,
    name: str = "body",
    x_breaks: ArrayLike | None = None,
    y_breaks: ArrayLike | None = None,
) -> QuadMesh:
    """Structured ``nx`` x ``ny`` Q4 mesh of ``[x0, x0 + width] x [y0, y0 + height]``.

    Node ``j * (nx + 1) + i`` sits at column ``i``, row ``j`` (rows from the bottom); cells are
    numbered row by row. ``grading_*`` is the last/first element size ratio (geometric);
    ``x_breaks``/``y_breaks`` give the column/row coordinates relative to ``origin`` instead
    (``nx + 1`` increasing values from 0 to ``width``). Edge sets ``bottom``, ``right``, ``top``,
    ``left`` form the counter-clockwise boundary; node sets carry the same names, the four
    ``corner_*`` nodes and ``all``.
    """
    check_size(int(nx) * int(ny), f"mesh.nx x mesh.ny = {nx} x {ny}")
    xs = (geometric_breaks(width, nx, grading_x) if x_breaks is None
          else _validated_breaks(x_breaks, width, nx, "x"))
    ys = (geometric_breaks(height, ny, grading_y) if y_breaks is None
          else _validated_breaks(y_breaks, height, ny, "y"))
    gx, gy = np.meshgrid(xs + float(origin[0]), ys + float(origin[1]))
    nodes = np.column_stack((gx.ravel(), gy.ravel()))
    grid = np.arange(nodes.shape[0]).reshape(ny + 1, nx + 1)
    chains = {
        "bottom": grid[0, :],
        "right": grid[:, -1],
        "top": grid[-1, ::-1],
        "left": grid[::-1, 0],
    }
    node_sets = chains | {
        "corner_bottom_left": grid[:1, 0],
        "corner_bottom_right": grid[:1, -1],
        "corner_top_right": grid[-1:, -1],
        "corner_top_left": grid[-1:, 0],
        "all": grid.ravel(),
    }
    edge_sets = {key: _chain_edges(chain) for key, chain in chains.items()}
    return QuadMesh(nodes, _grid_cells(grid), node_sets, edge_sets, name)


# ----------------------------------------------------------------------------------------------
# annulus
# ----------------------------------------------------------------------------------------------
def annulus(
    r_inner: float,
    r_outer: float,
    n_radial: int,
    n_circ: int,
    center: Sequence[float] = (0.0, 0.0),
    name: str = "ring",
    start_angle_deg: float = -90.0,
) -> QuadMesh:
    """Ring ``r_inner <= |x - center| <= r_outer``: ``n_radial`` layers x ``n_circ`` sectors.

    Node ``j * n_circ + i`` is on circle ``j`` (0 = inner) at angle
    ``start_angle_deg + 360 i / n_circ``, so with the default the lowest point is node
    ``n_radial * n_circ`` (node set ``bottom``). Edge set ``outer`` runs counter-clockwise,
    ``inner`` clockwise (body on the left of both). Node sets ``outer``, ``inner``, ``bottom``
    (the outer node at the start angle) and ``all``.
    """
    if not (0 < r_inner < r_outer):
        raise MeshError(f"annulus needs 0 < r_inner < r_outer, got {r_inner}, {r_outer}")
    if n_radial < 1 or n_circ < 3:
        raise MeshError(f"annulus needs n_radial >= 1 and n_circ >= 3, got {n_radial}, {n_circ}")
    check_size(int(n_radial) * int(n_circ), f"mesh.n_radial x mesh.n_circ = {n_radial} x {n_circ}")
    radii = np.linspace(r_inner, r_outer, n_radial + 1)
    angles = np.deg2rad(start_angle_deg) + 2.0 * np.pi * np.arange(n_circ) / n_circ
    unit = np.column_stack((np.cos(angles), np.sin(angles)))
    nodes = (radii[:, None, None] * unit[None, :, :]).reshape(-1, 2) + np.asarray(center, float)
    ring = np.arange(nodes.shape[0]).reshape(n_radial + 1, n_circ)
    closed = np.concatenate((ring, ring[:, :1]), axis=1)  # wrap around: column n_circ = column 0
    # i runs counter-clockwise (tangential), j must run inward for a right-handed (i, j) frame
    cells = _grid_cells(closed[::-1])
    node_sets = {
        "outer": ring[-1],
        "inner": ring[0],
        "bottom": ring[-1, :1],
        "all": ring.ravel(),
    }
    edge_sets = {"outer": _chain_edges(closed[-1]), "inner": _chain_edges(closed[0, ::-1])}
    return QuadMesh(nodes, cells, node_sets, edge_sets, name)


# ----------------------------------------------------------------------------------------------
# disk
# ----------------------------------------------------------------------------------------------
def _ring_fractions(n_radial: int, thickness: float, surface_size: float | None) -> NDArray:
    """Blend parameters (0 at the core, 1 on the circle) of the ``n_radial + 1`` ring rows:
    uniform, or with the outermost layer ``surface_size`` thick and the layers thickening
    (or thinning) geometrically inward."""
    if surface_size is None:
        return np.linspace(0.0, 1.0, n_radial + 1)
    if not surface_size > 0:
        raise MeshError(f"surface_size must be positive, got {surface_size}")
    try:
        sizes = _sizes_with_first(thickness, surface_size, n_radial)[::-1]  # core -> circle
    except MeshError as err:
        raise MeshError(
            f"surface_size = {surface_size} does not fit: the {n_radial} ring layer(s) span "
            f"{thickness:.6g} (the radius minus the core's half-width): {err}") from None
    fractions = np.concatenate(([0.0], np.cumsum(sizes))) / thickness
    fractions[-1] = 1.0
    return fractions


def disk(
    radius: float,
    n_circ: int,
    n_radial: int,
    surface_size: float | None = None,
    center: Sequence[float] = (0.0, 0.0),
    name: str = "disk",
    core_fraction: float = 0.5,
    core_blend: float = 0.5,
) -> QuadMesh:
    """Full disk ``|x - center| <= radius`` of quads: an "O-grid".

    A square core ``[-c, c]^2`` (``c = core_fraction * radius``) of ``(n_circ / 4)^2`` cells,
    surrounded by ``n_radial`` ring layers that blend linearly from the core boundary to the
    ``n_circ`` circle nodes, as in :func:`half_disk`. The circle nodes sit at the angles
    ``-90 + 360 i / n_circ`` degrees, so node ``i = 0`` is the lowest point; ``n_circ`` must be
    a multiple of 8 so that the core's corners face the 45-degree points and the lowest point
    and the centre are nodes. With ``surface_size`` the outermost layer has that thickness and
    the layers thicken geometrically inward (contact elements about square:
    ``surface_size ~ 2 pi radius / n_circ``). ``core_blend`` in [0, 1] mixes uniform (0) and
    circle-following (1) spacing of the core's rows and columns.

    Edge set ``outer`` runs counter-clockwise from the lowest node (body on the left); node
    sets ``outer`` (same order), ``bottom`` (lowest node), ``top`` (highest), ``center`` and
    ``all``.
    """
    if not (radius > 0 and np.isfinite(radius)) or n_radial < 1 or n_circ < 8 or n_circ % 8:
        raise MeshError(
            f"disk needs radius > 0, n_radial >= 1 and n_circ a multiple of 8 (so the lowest "
            f"point and the centre are nodes); got radius={radius}, n_circ={n_circ}, "
            f"n_radial={n_radial}")
    if not (0.0 < core_fraction < 1.0 / np.sqrt(2.0)) or not (0.0 <= core_blend <= 1.0):
        raise MeshError("disk needs 0 < core_fraction < 1/sqrt(2) and 0 <= core_blend <= 1")
    m = n_circ // 4
    check_size(int(n_circ) * int(n_radial) + m * m,
               f"mesh.n_circ x mesh.n_radial = {n_circ} x {n_radial} (+ the core)")
    c = core_fraction * radius
    # core rows/columns: the circle's projection onto the core side (the 90-degree arc facing
    # it, scaled to [-c, c]) blended with a uniform division
    facing = np.sin(np.deg2rad(np.linspace(-45.0, 45.0, m + 1))) / np.sin(np.pi / 4.0)
    ticks = c * (core_blend * facing + (1.0 - core_blend) * np.linspace(-1.0, 1.0, m + 1))
    ticks[0], ticks[m // 2], ticks[-1] = -c, 0.0, c
    gx, gy = np.meshgrid(ticks, ticks)
    core = np.column_stack((gx.ravel(), gy.ravel()))
    grid = np.arange(core.shape[0]).reshape(m + 1, m + 1)  # [j up, i right]
    # the core's rim counter-clockwise from its bottom-left corner, then rolled to start below
    # the centre (angle -90 degrees, like circle node 0)
    rim = np.concatenate((grid[0, :-1], grid[:-1, -1], grid[-1, :0:-1], grid[:0:-1, 0]))
    rim = np.roll(rim, -(m // 2))
    theta = -0.5 * np.pi + 2.0 * np.pi * np.arange(n_circ) / n_circ
    circle = radius * np.column_stack((np.cos(theta), np.sin(theta)))
    quarter = np.arange(0, n_circ, n_circ // 4)  # exactly below, right of, above, left of it
    circle[quarter] = radius * np.array([[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])
    fractions = _ring_fractions(n_radial, radius - c, surface_size)[1:, None, None]
    nodes, ring = _blended_rings(core, rim, circle, fractions, center)
    closed = np.concatenate((ring, ring[:, :1]), axis=1)  # column n_circ = column 0
    # ring: i runs counter-clockwise, j must run from the circle inward (as in ``annulus``)
    cells = np.vstack((_grid_cells(grid), _grid_cells(closed[::-1])))
    outer = ring[-1]
    node_sets = {
        "outer": outer,
        "bottom": outer[:1],
        "top": outer[n_circ // 2: n_circ // 2 + 1],
        "center": grid[m // 2, m // 2:][:1],
        "all": np.arange(nodes.shape[0]),
    }
    return QuadMesh(nodes, cells, node_sets, {"outer": _chain_edges(closed[-1])}, name)


# ----------------------------------------------------------------------------------------------
# half disk (Hertz cylinder)
# ----------------------------------------------------------------------------------------------
def _half_arc_sizes(radius: float, n_half: int, bottom_size: float | None,
                    fine_half_width: float) -> NDArray[np.float64]:
    """Arc-length sizes of the ``n_half`` cells from the lowest point up to one end."""
    quarter = 0.5 * np.pi * radius
    if bottom_size is None:
        return np.full(n_half, quarter / n_half)
    if not bottom_size > 0:
        raise MeshError(f"bottom_size must be positive, got {bottom_size}")
    n_uniform = max(1, int(round(fine_half_width / bottom_size)))
    if n_uniform >= n_half:
        raise MeshError(
            f"fine zone of {n_uniform} cells leaves no room for grading in {n_half} half-arc cells"
        )
    return _sizes_with_first(quarter, bottom_size, n_half, n_uniform)


def _layer_fractions(n_radial: int, thickness: float, first: float | None,
                     arc_spacing: NDArray) -> NDArray:
    """Blend parameters ``s[k, i]`` (0 at the core, 1 at the arc) of the ring layers.

    The outermost layer is ``first`` thick where the arc spacing is ``first`` and as thick as
    the local arc spacing elsewhere (up to uniform layers), keeping ring cells near square.
    """
    uniform = np.linspace(0.0, 1.0, n_radial + 1)
    h_uniform = thickness / n_radial
    if first is None or first >= h_uniform:
        return np.repeat(uniform[:, None], arc_spacing.size, axis=1)
    sizes_from_arc = _sizes_with_first(thickness, first, n_radial)
    graded = np.concatenate(([0.0], np.cumsum(sizes_from_arc[::-1]))) / thickness
    # weight 1 -> graded (first layer = first), 0 -> uniform; linear in the first-layer size
    weight = np.clip((h_uniform - arc_spacing) / (h_uniform - first), 0.0, 1.0)
    return weight[None, :] * graded[:, None] + (1.0 - weight[None, :]) * uniform[:, None]


def half_disk(
    radius: float,
    n_arc: int,
    n_radial: int,
    bottom_size: float | None = None,
    center: Sequence[float] = (0.0, 0.0),
    name: str = "cylinder",
    fine_half_width: float = 0.0,
    core_fraction: float = 0.5,
    core_blend: float = 0.5,
) -> QuadMesh:
    """Half disk with its flat side up (on ``y = center_y``) and the arc below; quads only.

    Mapped "O-grid" mesh: a rectangular core ``[-c, c] x [-c, 0]`` (``c = core_fraction *
    radius``) meshed as a tensor grid, surrounded by ``n_radial`` layers that blend linearly
    from the core boundary to the ``n_arc`` arc cells. ``n_arc`` must be even so the lowest
    point is a node. With ``bottom_size`` the arc cells within ``fine_half_width`` (arc length)
    of the lowest point have that size and grow geometrically beyond; the outermost layer is
    ``bottom_size`` thick at the bottom and the layers thicken geometrically inward, so contact
    elements are about square. ``core_blend`` in [0, 1] mixes uniform (0) and arc-following (1)
    column spacing of the core, trading core aspect ratio against ring skew.

    Edge sets ``arc`` (left end -> bottom -> right end) and ``flat`` (right -> left), body on
    the left; node sets ``arc``, ``flat``, ``bottom`` (lowest node), ``flat_center`` (the flat
    side node above it) and ``all``.
    """
    if radius <= 0 or n_radial < 1 or n_arc < 4 or n_arc % 2:
        raise MeshError(
            f"half_disk needs radius > 0, n_radial >= 1 and an even n_arc >= 4 (so the lowest"
            f" point is a node); got radius={radius}, n_arc={n_arc}, n_radial={n_radial}"
        )
    if not (0.0 < core_fraction < 1.0 / np.sqrt(2.0)) or not (0.0 <= core_blend <= 1.0):
        raise MeshError("half_disk needs 0 < core_fraction < 1/sqrt(2) and 0 <= core_blend <= 1")
    # the ring layers alone (the core adds about (n_arc / 4)^2 more)
    check_size(int(n_arc) * int(n_radial), f"mesh.n_arc x mesh.n_radial = {n_arc} x {n_radial}")
    half = _half_arc_sizes(radius, n_arc // 2, bottom_size, fine_half_width)
    s_right = np.concatenate(([0.0], np.cumsum(half)))
    s_right[-1] = 0.5 * np.pi * radius
    theta = -0.5 * np.pi + np.concatenate((-s_right[:0:-1], s_right)) / radius  # -pi .. 0
    arc = radius * np.column_stack((np.cos(theta), np.sin(theta)))
    # the core corners are the arc nodes closest to -135 and -45 degrees
    n_side = int(np.argmin(np.abs(theta[: n_arc // 2] + 0.75 * np.pi)))
    n_side = min(max(n_side, 1), n_arc // 2 - 1)
    c = core_fraction * radius
    core_nodes, core_grid, rim = _core_block(arc, n_side, c, core_blend)
    cell_arc = np.concatenate((half[::-1], half))
    node_spacing = np.concatenate((cell_arc[:1], 0.5 * (cell_arc[1:] + cell_arc[:-1]),
                                   cell_arc[-1:]))
    fractions = _layer_fractions(n_radial, radius - c, bottom_size, node_spacing)[1:, :, None]
    nodes, ring_grid = _blended_rings(core_nodes, rim, arc, fractions, center)
    # ring: i runs along the arc (counter-clockwise), j must run from the arc inward
    cells = np.vstack((_grid_cells(core_grid), _grid_cells(ring_grid[::-1])))
    arc_chain = ring_grid[-1]
    flat_chain = np.concatenate((ring_grid[::-1, -1], core_grid[-1, -2:0:-1], ring_grid[:, 0]))
    node_sets = {
        "arc": arc_chain,
        "flat": flat_chain,
        "bottom": arc_chain[n_arc // 2: n_arc // 2 + 1],
        "flat_center": core_grid[-1, (core_grid.shape[1] - 1) // 2:][:1],
        "all": np.arange(nodes.shape[0]),
    }
    edge_sets = {"arc": _chain_edges(arc_chain), "flat": _chain_edges(flat_chain)}
    return QuadMesh(nodes, cells, node_sets, edge_sets, name)


def _blended_rings(core: NDArray, rim: NDArray[np.int64], outline: NDArray, fractions: NDArray,
                   center: Sequence[float]) -> tuple[NDArray, NDArray[np.int64]]:
    """The nodes (the core's, then the ring layers' that blend linearly from the core's
    ``rim`` nodes, 0, to ``outline``, 1, by ``fractions`` (layers, rim nodes or 1, 1)), moved
    to ``center``, and the ring's node grid [layer, i] (row 0: the rim)."""
    ring_xy = (1.0 - fractions) * core[rim][None] + fractions * outline[None]
    layers = len(core) + np.arange(ring_xy.shape[0] * ring_xy.shape[1]).reshape(ring_xy.shape[:2])
    nodes = np.vstack((core, ring_xy.reshape(-1, 2))) + np.asarray(center, float)
    return nodes, np.vstack((rim[None], layers))


def _core_block(arc: NDArray, n_side: int, c: float, blend: float
                ) -> tuple[NDArray, NDArray, NDArray]:
    """Tensor-grid core ``[-c, c] x [-c, 0]`` matched node for node to the arc.

    Returns the core coordinates, its node grid ``[j, i]`` (j up, i right) and the core rim:
    the core boundary nodes in arc order (left side down, bottom left to right, right side up).
    """
    n_arc = arc.shape[0] - 1
    n_bottom = n_arc - 2 * n_side
    bottom_arc = arc[n_side: n_side + n_bottom + 1, 0]
    follow = c * bottom_arc / abs(bottom_arc[0])
    xs = blend * follow + (1.0 - blend) * np.linspace(-c, c, n_bottom + 1)
    xs[0], xs[-1] = -c, c
    side_arc = arc[n_side::-1, 1]  # from the corner up to the flat end
    ys = c * side_arc / abs(side_arc[0])
    ys[0], ys[-1] = -c, 0.0
    gx, gy = np.meshgrid(xs, ys)
    grid = np.arange(gx.size).reshape(gy.shape)
    rim = np.concatenate((grid[::-1, 0], grid[0, 1:], grid[1:, -1]))
    return np.column_stack((gx.ravel(), gy.ravel())), grid, rim


_HERTZ_LEVELS = {
    # level: (bottom size as in report Table 6.2, arc cells, ring layers)
    # (800, 1310, 2128 cylinder cells against the report's 711, 950, 2229)
    1: (6.0, 52, 12),
    2: (4.0, 68, 15),
    3: (3.0, 88, 19),
}


def hertz_cylinder_mesh(level: int, radius: float = 400.0, fine_half_width: float = 60.0,
                        center: Sequence[float] = (0.0, 0.0)) -> QuadMesh:
    """Half cylinder of the report's Hertz problem (section 6.2, Table 6.2), levels 1-3.

    The contact-zone element size is 6, 4, 3 for levels 1, 2, 3, uniform within
    ``fine_half_width`` of the lowest point (the analytic Hertz half-width is about 47).
    """
    if level not in _HERTZ_LEVELS:
        raise MeshError(f"Hertz mesh level must be one of {sorted(_HERTZ_LEVELS)}, got {level}")
    bottom_size, n_arc, n_radial = _HERTZ_LEVELS[level]
    return half_disk(radius, n_arc, n_radial, bottom_size=bottom_size, center=center,
                     name="cylinder", fine_half_width=fine_half_width)
