"""The order bodies are stored in: the scene's own, or sorted by shape and place (Morton order).

Every kernel runs one thread per body or per pair and reads the bodies' records by index.  When
bodies that are near in space are near in memory as well, a pair's two records, and the records
of a slab or a grid cell, share cache lines (CPU) and a GPU warp reads runs of neighbouring
records; when consecutive bodies have the same shape, a warp takes the sphere branch or the box
branch, not both.  A scene lists its bodies in the order its tables made them.  A grid layout is
already local (row by row), but a scene assembled from many tables, or from another program's
list, need not be: the 10k mixed rain with body contact took 108-125 CPU ms a step in the grid's
own order, 128-131 sorted by shape then Morton code, and 176-186 in a random order of the same
bodies (2-core CPU).

``body_order(shape, position, mode, static)`` returns the permutation ``order``: internal body i
is scene body ``order[i]``.  Modes:

- ``scene``: the identity (nothing is sorted; the default everywhere).
- ``morton``: every body by the Morton code of its starting position.
- ``shape_morton``: dynamic spheres, then dynamic boxes, then static bodies (spheres, then
  boxes), each group in Morton order.  Static bodies go last as a group of their own: no kernel
  moves them, so their threads leave at once, together, and the dynamic bodies stay packed; a
  static floor's one record that many pairs read stays cached wherever it lies.

Morton code (``morton_codes``): each position is quantised to 10 bits an axis over the bounding
cube of all starting positions (its side the largest extent of their bounding box, so cells are
cubes and the codes of a flat scene interleave its two wide axes only, instead of stretching its
thin one over 1024 cells too), and the bits are interleaved x, y, z from the top: 30 bits, so
bodies with close codes lie close in space.  Cells are the cube's side / 1024 (10 cm for a 100 m
scene); bodies in one cell keep their relative order.  Sorting is stable (``np.argsort(kind =
"stable")``, ``np.lexsort``), with no randomness: the same scene always gives the same order.

The order is chosen once, at build (``ModelBuilder.finalize(body_order=...)``, ``[sim]
body_order``), from the starting positions; it is not updated as bodies move.  The Model keeps
``body_scene_index`` and its inverse so that whatever a user sees (recordings, exports, the
body a non-finite error names) is in scene order; ``Model.to_scene_order`` does the same for API
users reading ``sim.state`` arrays.
"""

from __future__ import annotations

import numpy as np

from .types import SHAPE_SPHERE
from .validation import BODY_ORDERS, Choice, check

MORTON_BITS = 10  # per axis: 30-bit codes in a uint32
MORTON_CELLS = 1 << MORTON_BITS


def _spread_bits(v: np.ndarray) -> np.ndarray:
    """The low 10 bits of ``v`` moved to every third bit (bit k to bit 3k), as uint32."""
    v = v.astype(np.uint32) & np.uint32(0x3FF)
    v = (v | (v << np.uint32(16))) & np.uint32(0x030000FF)
    v = (v | (v << np.uint32(8))) & np.uint32(0x0300F00F)
    v = (v | (v << np.uint32(4))) & np.uint32(0x030C30C3)
    v = (v | (v << np.uint32(2))) & np.uint32(0x09249249)
    return v


def morton_cells(position) -> np.ndarray:
    """(n, 3) integer cells in [0, 1023] of ``position`` over the bounding cube (module docstring)."""
    p = np.asarray(position, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0:
        return np.zeros((0, 3), np.uint32)
    low = p.min(axis=0)
    side = float((p.max(axis=0) - low).max())
    scale = MORTON_CELLS / side if side > 0.0 else 0.0
    if not np.isfinite(scale):  # a side so small that 1024 / side overflows: one cell
        scale = 0.0
    cells = np.floor((p - low) * scale)
    return np.clip(cells, 0, MORTON_CELLS - 1).astype(np.uint32)


def morton_codes(position) -> np.ndarray:
    """(n) uint32 30-bit Morton codes of ``position``, x in the top bit of each triple."""
    c = morton_cells(position)
    return (_spread_bits(c[:, 0]) << np.uint32(2)) | (_spread_bits(c[:, 1]) << np.uint32(1)) | _spread_bits(c[:, 2])


def body_order(shape, position, mode: str = "shape_morton", static=None) -> np.ndarray:
    """The permutation (int64) of ``mode``: internal body i is scene body ``order[i]``.

    shape: (n) SHAPE_SPHERE / SHAPE_BOX; position: (n, 3) starting positions; static: (n) bool
    or None (all dynamic).  A bad ``mode`` is a ValidationError naming ``body_order``.
    """
    mode = check(Choice(BODY_ORDERS), mode, "body_order")
    shape = np.asarray(shape)
    n = len(shape)
    if mode == "scene":
        return np.arange(n, dtype=np.int64)
    code = morton_codes(position)
    if mode == "morton":
        return np.argsort(code, kind="stable").astype(np.int64)
    static = np.zeros(n, bool) if static is None else np.asarray(static, bool)
    # lexsort is stable and sorts by its last key first: static, then shape (spheres first), then code
    return np.lexsort((code, shape != SHAPE_SPHERE, static)).astype(np.int64)


def inverse_order(order: np.ndarray) -> np.ndarray:
    """``inverse[order[i]] = i``: where each scene body is stored."""
    order = np.asarray(order, dtype=np.int64)
    inverse = np.empty_like(order)
    inverse[order] = np.arange(len(order), dtype=np.int64)
    return inverse
