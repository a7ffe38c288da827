"""Debug drawer (SEED.md 6): points and lines of any colour, optionally on top of everything.

``DebugOptions`` says what to show; ``simulation_debug_geometry`` turns the simulator's arrays into
points and lines: checkpoint world positions, contact points, contact normals, body velocities and
penetration vectors (from the contact point along the normal by the penetration depth: the
displacement that would take the body out of the terrain).
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass

import numpy as np
from OpenGL import GL

from .shader import load_program

CHECKPOINT_COLOR = (1.0, 0.95, 0.2, 1.0)
CONTACT_COLOR = (1.0, 0.15, 0.1, 1.0)
NORMAL_COLOR = (0.2, 0.6, 1.0, 1.0)
VELOCITY_COLOR = (0.2, 1.0, 0.3, 1.0)
PENETRATION_COLOR = (1.0, 0.2, 1.0, 1.0)


@dataclass
class DebugOptions:
    checkpoints: bool = False
    contacts: bool = False
    normals: bool = False
    velocities: bool = False
    penetration: bool = False
    on_top: bool = False
    normal_length: float = 0.5  # [m]
    velocity_scale: float = 0.1  # [s]: a vector of v * scale metres
    penetration_scale: float = 10.0  # depths are millimetres; drawn magnified
    max_points: int = 200_000

    def any(self) -> bool:
        return self.checkpoints or self.contacts or self.normals or self.velocities or self.penetration


def checkpoint_world_positions(model, state) -> np.ndarray:
    body = model.host["checkpoint_body"]
    local = model.host["checkpoint_local"]
    pos = state.body_pos.numpy()
    rot = state.body_rot.numpy()
    return pos[body] + np.einsum("nij,nj->ni", rot[body], local)


def pair_contacts(contacts) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points, normals, depths of the body-body contacts (empty when the scene has none).

    Pair p owns point slots 4p .. 4p + pair_point_count[p] - 1 and one normal per pair.
    """
    empty = (np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32), np.zeros(0, np.float32))
    if getattr(contacts, "pair_max", 0) <= 0 or not hasattr(contacts, "pair_point_count"):
        return empty
    pairs = min(int(contacts.pair_count.numpy()[0]), contacts.pair_max)
    if pairs == 0:
        return empty
    per_pair = len(contacts.pair_point) // max(len(contacts.pair_point_count), 1)
    counts = contacts.pair_point_count.numpy()[:pairs]
    slot = np.arange(per_pair)
    used = slot[None, :] < counts[:, None]
    points = contacts.pair_point.numpy()[: pairs * per_pair].reshape(pairs, per_pair, 3)[used]
    depths = contacts.pair_depth.numpy()[: pairs * per_pair].reshape(pairs, per_pair)[used]
    normals = np.repeat(contacts.pair_normal.numpy()[:pairs], counts, axis=0)
    return points, normals, depths


def active_contacts(contacts) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points, normals, depths of the active terrain and body-body contacts."""
    n = contacts.slot_count
    active = contacts.terrain_contact_active.numpy()[:n] != 0
    terrain = (contacts.terrain_contact_point.numpy()[:n][active], contacts.terrain_contact_normal.numpy()[:n][active],
               contacts.terrain_contact_depth.numpy()[:n][active])
    pairs = pair_contacts(contacts)
    return tuple(np.concatenate([a, b]) for a, b in zip(terrain, pairs))


class DebugDraw:
    def __init__(self):
        self.program = load_program("debug.vert", "debug.frag")
        self.vao = GL.glGenVertexArrays(1)
        self.vbo = GL.glGenBuffers(1)
        self.capacity = 0
        GL.glBindVertexArray(self.vao)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, self.vbo)
        GL.glEnableVertexAttribArray(0)
        GL.glVertexAttribPointer(0, 3, GL.GL_FLOAT, GL.GL_FALSE, 28, ctypes.c_void_p(0))
        GL.glEnableVertexAttribArray(1)
        GL.glVertexAttribPointer(1, 4, GL.GL_FLOAT, GL.GL_FALSE, 28, ctypes.c_void_p(12))
        GL.glBindVertexArray(0)
        self.point_size = 5.0
        self.clear()

    def clear(self):
        self._points = {False: [], True: []}
        self._lines = {False: [], True: []}

    @staticmethod
    def _vertices(positions, color) -> np.ndarray:
        p = np.asarray(positions, np.float32).reshape(-1, 3)
        c = np.broadcast_to(np.asarray(color, np.float32), (len(p), 4))
        return np.concatenate([p, c], axis=1)

    def points(self, positions, color, on_top: bool = False):
        if len(positions):
            self._points[on_top].append(self._vertices(positions, color))

    def lines(self, starts, ends, color, on_top: bool = False):
        starts = np.asarray(starts, np.float32).reshape(-1, 3)
        ends = np.asarray(ends, np.float32).reshape(-1, 3)
        if len(starts):
            pairs = np.stack([starts, ends], axis=1).reshape(-1, 3)
            self._lines[on_top].append(self._vertices(pairs, color))

    def vertex_count(self) -> int:
        return sum(len(v) for group in (self._points, self._lines) for parts in group.values() for v in parts)

    def flush(self):
        """Draw everything queued since the last flush, then clear the queue."""
        batches = []
        for on_top in (False, True):
            for mode, group in ((GL.GL_POINTS, self._points), (GL.GL_LINES, self._lines)):
                if group[on_top]:
                    batches.append((on_top, mode, np.concatenate(group[on_top])))
        self.clear()
        if not batches:
            return
        data = np.ascontiguousarray(np.concatenate([b[2] for b in batches]), dtype=np.float32)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, self.vbo)
        if data.nbytes > self.capacity:
            self.capacity = max(data.nbytes, 2 * self.capacity)
            GL.glBufferData(GL.GL_ARRAY_BUFFER, self.capacity, None, GL.GL_STREAM_DRAW)
        GL.glBufferSubData(GL.GL_ARRAY_BUFFER, 0, data.nbytes, data)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, 0)
        self.program.use()
        self.program.set_float("point_size", self.point_size)
        GL.glEnable(GL.GL_PROGRAM_POINT_SIZE)
        GL.glBindVertexArray(self.vao)
        first = 0
        for on_top, mode, vertices in batches:
            if on_top:
                GL.glDisable(GL.GL_DEPTH_TEST)
            GL.glDrawArrays(mode, first, len(vertices))
            if on_top:
                GL.glEnable(GL.GL_DEPTH_TEST)
            first += len(vertices)
        GL.glBindVertexArray(0)

    def add_simulation(self, sim, options: DebugOptions):
        """Queue the simulator's debug geometry selected by ``options``."""
        if not options.any():
            return
        top = options.on_top
        state = sim.state
        if options.checkpoints and sim.model.checkpoint_count:
            pts = checkpoint_world_positions(sim.model, state)[: options.max_points]
            self.points(pts, CHECKPOINT_COLOR, top)
        if options.contacts or options.normals or options.penetration:
            points, normals, depths = active_contacts(sim.contacts)
            points, normals, depths = (a[: options.max_points] for a in (points, normals, depths))
            if options.contacts:
                self.points(points, CONTACT_COLOR, top)
            if options.normals:
                self.lines(points, points + options.normal_length * normals, NORMAL_COLOR, top)
            if options.penetration:
                inside = depths > 0.0
                p, n, d = points[inside], normals[inside], depths[inside]
                self.lines(p, p + (options.penetration_scale * d)[:, None] * n, PENETRATION_COLOR, top)
        if options.velocities:
            pos = state.body_pos.numpy()[: options.max_points]
            vel = state.body_vel.numpy()[: options.max_points]
            self.lines(pos, pos + options.velocity_scale * vel, VELOCITY_COLOR, top)

    def delete(self):
        GL.glDeleteVertexArrays(1, [self.vao])
        GL.glDeleteBuffers(1, [self.vbo])
        self.program.delete()
