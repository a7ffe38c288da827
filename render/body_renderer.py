"""Instanced spheres and boxes: one draw call per shape kind.

All bodies share one instance buffer, spheres first, then boxes.  Per instance, a Warp kernel
writes 16 floats: the columns of ``body_rot`` scaled by the shape's size with the position in
their w, and an RGBA colour (by shape or by speed).  The kernel runs on the simulation's device:

* CPU: it writes a host ``wp.array`` that is uploaded with one ``glBufferSubData`` per frame.
* CUDA: the instance VBO is registered with ``wp.RegisteredGLBuffer`` and the kernel writes straight
  into it while mapped (no copy through the host).

``body_rot`` (not the quaternion) is drawn, so the raw ``matrix`` rotation mode's drift shows as
a visibly stretched box, as in the thesis's figure 3.
"""

from __future__ import annotations

import ctypes
import math

import numpy as np
import warp as wp
from OpenGL import GL

from warp_sim.types import SHAPE_BOX, SHAPE_SPHERE

from .shader import load_program

# No kernel here is differentiated: skip generating (and compiling) the adjoints.
wp.set_module_options({"enable_backward": False})

INSTANCE_FLOATS = 16

COLOR_BY_SHAPE = 0
COLOR_BY_SPEED = 1
COLOR_MODES = {"shape": COLOR_BY_SHAPE, "speed": COLOR_BY_SPEED}

SHAPE_COLORS = {SHAPE_SPHERE: (0.93, 0.45, 0.16), SHAPE_BOX: (0.20, 0.45, 0.85)}


@wp.func
def speed_color(t: float) -> wp.vec3:
    """Blue -> cyan -> green -> yellow -> red for t in [0, 1]."""
    x = wp.clamp(t, 0.0, 1.0) * 4.0
    if x < 1.0:
        return wp.lerp(wp.vec3(0.10, 0.20, 0.85), wp.vec3(0.10, 0.75, 0.90), x)
    if x < 2.0:
        return wp.lerp(wp.vec3(0.10, 0.75, 0.90), wp.vec3(0.20, 0.80, 0.25), x - 1.0)
    if x < 3.0:
        return wp.lerp(wp.vec3(0.20, 0.80, 0.25), wp.vec3(0.95, 0.85, 0.15), x - 2.0)
    return wp.lerp(wp.vec3(0.95, 0.85, 0.15), wp.vec3(0.90, 0.15, 0.10), x - 3.0)


@wp.kernel
def fill_body_instances(
    # Model
    instance_body: wp.array(dtype=wp.int32),
    body_shape: wp.array(dtype=wp.int32),
    body_size: wp.array(dtype=wp.vec3),
    # State in
    body_pos: wp.array(dtype=wp.vec3),
    body_rot: wp.array(dtype=wp.mat33),
    body_vel: wp.array(dtype=wp.vec3),
    # Settings
    color_mode: int,
    shape_color: wp.array(dtype=wp.vec3),
    speed_max: float,
    # Out
    instances: wp.array2d(dtype=float),
):
    i = wp.tid()
    b = instance_body[i]
    size = body_size[b]
    if body_shape[b] == SHAPE_SPHERE:
        size = wp.vec3(size[0], size[0], size[0])
    r = body_rot[b]
    p = body_pos[b]
    for c in range(3):
        instances[i, 4 * c + 0] = r[0, c] * size[c]
        instances[i, 4 * c + 1] = r[1, c] * size[c]
        instances[i, 4 * c + 2] = r[2, c] * size[c]
        instances[i, 4 * c + 3] = p[c]
    color = shape_color[body_shape[b]]
    if color_mode == COLOR_BY_SPEED:
        color = speed_color(wp.length(body_vel[b]) / speed_max)
    else:
        # A small per-body brightness jitter keeps neighbours apart.
        state = wp.rand_init(7919, b)
        color = color * (0.8 + 0.4 * wp.randf(state))
    instances[i, 12] = color[0]
    instances[i, 13] = color[1]
    instances[i, 14] = color[2]
    instances[i, 15] = 1.0


def sphere_mesh(slices: int = 24, stacks: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Unit UV sphere: (positions|normals interleaved (V, 6), triangle indices)."""
    verts = []
    for j in range(stacks + 1):
        theta = math.pi * j / stacks
        for i in range(slices + 1):
            phi = 2.0 * math.pi * i / slices
            p = (math.sin(theta) * math.cos(phi), math.cos(theta), math.sin(theta) * math.sin(phi))
            verts.append((*p, *p))
    idx = []
    for j in range(stacks):
        for i in range(slices):
            a = j * (slices + 1) + i
            b = a + slices + 1
            idx += [a, a + 1, b, a + 1, b + 1, b]
    return np.asarray(verts, np.float32), np.asarray(idx, np.uint32)


def cube_mesh() -> tuple[np.ndarray, np.ndarray]:
    """Cube [-1, 1]^3 with flat face normals: 24 vertices, 36 indices (counter-clockwise outside)."""
    verts, idx = [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            u = np.zeros(3)
            u[(axis + 1) % 3] = 1.0
            v = np.cross(n, u)
            base = len(verts)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                verts.append((*(n + a * u + b * v), *n))
            idx += [base, base + 1, base + 2, base, base + 2, base + 3]
    return np.asarray(verts, np.float32), np.asarray(idx, np.uint32)


def sphere_detail_for(count: int) -> tuple[int, int]:
    """Fewer triangles per sphere as the count grows (software rasterisers are vertex bound)."""
    if count <= 2000:
        return 24, 16
    if count <= 20000:
        return 14, 9
    return 8, 6


class ShapeBatch:
    """One mesh drawn once per body of one shape kind: instances first .. first + count - 1 of
    the shared instance buffer (its attribute pointers start at that instance)."""

    def __init__(self, shape: int, mesh: tuple[np.ndarray, np.ndarray], first: int, count: int, instance_vbo):
        self.shape = shape
        self.first = first
        self.count = count
        vertices, indices = mesh
        self.index_count = len(indices)
        self.vao = GL.glGenVertexArrays(1)
        self.mesh_vbo, self.ibo = GL.glGenBuffers(2)
        GL.glBindVertexArray(self.vao)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, self.mesh_vbo)
        GL.glBufferData(GL.GL_ARRAY_BUFFER, vertices.nbytes, vertices, GL.GL_STATIC_DRAW)
        for location, offset in ((0, 0), (1, 12)):
            GL.glEnableVertexAttribArray(location)
            GL.glVertexAttribPointer(location, 3, GL.GL_FLOAT, GL.GL_FALSE, 24, ctypes.c_void_p(offset))
        GL.glBindBuffer(GL.GL_ELEMENT_ARRAY_BUFFER, self.ibo)
        GL.glBufferData(GL.GL_ELEMENT_ARRAY_BUFFER, indices.nbytes, indices, GL.GL_STATIC_DRAW)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, instance_vbo)
        stride = INSTANCE_FLOATS * 4
        for k in range(4):
            GL.glEnableVertexAttribArray(2 + k)
            GL.glVertexAttribPointer(2 + k, 4, GL.GL_FLOAT, GL.GL_FALSE, stride, ctypes.c_void_p(first * stride + 16 * k))
            GL.glVertexAttribDivisor(2 + k, 1)
        GL.glBindVertexArray(0)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, 0)

    def draw(self):
        if self.count == 0:
            return
        GL.glBindVertexArray(self.vao)
        GL.glDrawElementsInstanced(GL.GL_TRIANGLES, self.index_count, GL.GL_UNSIGNED_INT, None, self.count)
        GL.glBindVertexArray(0)

    def delete(self):
        GL.glDeleteVertexArrays(1, [self.vao])
        GL.glDeleteBuffers(2, [self.mesh_vbo, self.ibo])


class BodyRenderer:
    """All bodies in one instance buffer, spheres first, then boxes: one kernel launch and one
    upload per frame, one draw call per shape kind."""

    def __init__(self):
        self.program = load_program("body.vert", "body.frag")
        self.batches: list[ShapeBatch] = []
        self.color_mode = COLOR_BY_SHAPE
        self.speed_max = 10.0  # [m/s] mapped to red in speed colouring
        self.count = 0
        self.instance_vbo = None
        self.interop = None
        self.host_instances = None

    def set_model(self, model, sphere_detail: tuple[int, int] | None = None):
        """(Re)create the buffers for a model's bodies; call after a rebuild or scene change."""
        self._release()
        shapes = model.host["body_shape"]
        spheres = np.flatnonzero(shapes == SHAPE_SPHERE)
        boxes = np.flatnonzero(shapes == SHAPE_BOX)
        self.device = wp.get_device(model.device)
        self.count = len(spheres) + len(boxes)
        self.order = np.concatenate([spheres, boxes]).astype(np.int32)
        self.instance_body = wp.array(self.order, dtype=wp.int32, device=self.device)
        palette = np.zeros((max(SHAPE_COLORS) + 1, 3), np.float32)
        for shape, color in SHAPE_COLORS.items():
            palette[shape] = color
        self.shape_color = wp.array(palette, dtype=wp.vec3, device=self.device)
        nbytes = max(self.count, 1) * INSTANCE_FLOATS * 4
        self.instance_vbo = GL.glGenBuffers(1)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, self.instance_vbo)
        GL.glBufferData(GL.GL_ARRAY_BUFFER, nbytes, None, GL.GL_STREAM_DRAW)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, 0)
        if self.device.is_cuda:
            # CUDA-GL interop: the kernel writes straight into the mapped vertex buffer.
            self.interop = wp.RegisteredGLBuffer(int(self.instance_vbo), self.device,
                                                 flags=wp.RegisteredGLBuffer.WRITE_DISCARD)
        else:
            self.host_instances = wp.zeros((max(self.count, 1), INSTANCE_FLOATS), dtype=float, device=self.device)
        detail = sphere_detail or sphere_detail_for(len(spheres))
        self.batches = [ShapeBatch(SHAPE_SPHERE, sphere_mesh(*detail), 0, len(spheres), self.instance_vbo),
                        ShapeBatch(SHAPE_BOX, cube_mesh(), len(spheres), len(boxes), self.instance_vbo)]

    def update(self, model, state):
        """Fill the instance buffer from the current state (one launch, one upload)."""
        if self.count == 0:
            return
        shape = (self.count, INSTANCE_FLOATS)
        out = self.interop.map(dtype=float, shape=shape) if self.interop else self.host_instances
        wp.launch(
            fill_body_instances,
            dim=self.count,
            inputs=[
                # Model
                self.instance_body, model.body_shape, model.body_size,
                # State in
                state.body_pos, state.body_rot, state.body_vel,
                # Settings
                self.color_mode, self.shape_color, max(self.speed_max, 1e-6),
            ],
            outputs=[out],
            device=self.device,
        )
        if self.interop:
            self.interop.unmap()
        else:
            GL.glBindBuffer(GL.GL_ARRAY_BUFFER, self.instance_vbo)
            GL.glBufferSubData(GL.GL_ARRAY_BUFFER, 0, self.count * INSTANCE_FLOATS * 4, out.numpy())
            GL.glBindBuffer(GL.GL_ARRAY_BUFFER, 0)

    def read_instances(self) -> np.ndarray:
        """The instance buffer as the GL sees it, (count, 16), in ``order`` (tests)."""
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, self.instance_vbo)
        raw = GL.glGetBufferSubData(GL.GL_ARRAY_BUFFER, 0, self.count * INSTANCE_FLOATS * 4)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, 0)
        data = raw if isinstance(raw, np.ndarray) else np.frombuffer(bytes(raw), np.uint8)
        return data.view(np.float32).reshape(self.count, INSTANCE_FLOATS).copy()

    def draw(self):
        self.program.use()
        GL.glEnable(GL.GL_CULL_FACE)
        for batch in self.batches:
            self.program.set_int("shape_kind", batch.shape)
            batch.draw()
        GL.glDisable(GL.GL_CULL_FACE)

    def _release(self):
        for batch in self.batches:
            batch.delete()
        self.batches = []
        self.interop = None
        self.host_instances = None
        if self.instance_vbo is not None:
            GL.glDeleteBuffers(1, [self.instance_vbo])
            self.instance_vbo = None

    def delete(self):
        self._release()
        self.program.delete()
