"""Terrain through the tessellation pipeline (SEED.md 6).

An N x N grid of flat 4-corner patches is uploaded once.  The control shader picks per-edge outer
levels from camera distance (min/max depth, min/max level), the evaluation shader computes height,
normal and texture coordinates from the Terrain uniform block.  That block is filled from
``FourierTerrain.glsl_uniforms()``: the same complex coefficients, frequency, scale and offset the
Warp kernels read, so what you see is what the bodies collide with.

A ``PlaneTerrain`` uses the same pipeline with kind = plane (height (d - n.x x - n.z z) / n.y);
``NoTerrain`` draws nothing.  The grid follows the camera in whole patches, so the terrain seems
unbounded while every corner keeps its world position.
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass

import numpy as np
from OpenGL import GL

from warp_sim.terrain import TERRAIN_FOURIER, TERRAIN_NONE, TERRAIN_PLANE, FourierTerrain, PlaneTerrain

from .shader import BLOCK_BINDINGS, Std140Block, UniformBuffer, check_block_size, load_program

MAX_TERMS = 32  # must match TERRAIN_MAX_TERMS in shaders/terrain_common.glsl


@dataclass
class TessellationSettings:
    """Level of detail: ``max_level`` up to ``min_depth`` [m] from the eye, falling linearly to
    ``min_level`` at ``max_depth`` and beyond."""

    min_depth: float = 4.0
    max_depth: float = 40.0
    min_level: float = 1.0
    max_level: float = 12.0


def terrain_block() -> Std140Block:
    return Std140Block([
        ("terrain_info", "ivec4", 1),
        ("terrain_params", "vec4", 1),
        ("terrain_scale", "vec4", 1),
        ("terrain_offset", "vec4", 1),
        ("terrain_plane", "vec4", 1),
        ("terrain_tess", "vec4", 1),
        ("terrain_grid", "vec4", 1),
        ("terrain_coef", "vec4", MAX_TERMS * MAX_TERMS // 2),
    ])


def patch_corners(patches_per_side: int) -> np.ndarray:
    """(N*N*4, 2) corners in patch units, counter-clockwise per patch seen from above."""
    j, i = np.meshgrid(np.arange(patches_per_side), np.arange(patches_per_side), indexing="ij")
    i, j = i.ravel().astype(np.float32), j.ravel().astype(np.float32)
    corners = np.stack([np.stack([i, j], 1), np.stack([i + 1, j], 1), np.stack([i + 1, j + 1], 1),
                        np.stack([i, j + 1], 1)], axis=1)
    return np.ascontiguousarray(corners.reshape(-1, 2))


class TerrainRenderer:
    def __init__(self, patches_per_side: int = 64, patch_size: float = 4.0, contour_spacing: float = 0.5,
                 grid_spacing: float = 1.0):
        self.program = load_program("terrain.vert", "terrain.tesc", "terrain.tese", "terrain.frag")
        self.block = terrain_block()
        check_block_size(self.program, "Terrain", self.block)
        self.ubo = UniformBuffer(BLOCK_BINDINGS["Terrain"], self.block)
        self.patches_per_side = int(patches_per_side)
        self.patch_size = float(patch_size)
        self.contour_spacing = contour_spacing
        self.grid_spacing = grid_spacing
        self.tessellation = TessellationSettings()
        self.cull = True
        self.follow_camera = True
        self.kind = TERRAIN_NONE
        self.wireframe = False
        self._origin = None
        self._feedback_program = None

        corners = patch_corners(self.patches_per_side)
        self.vertex_count = len(corners)
        self.vao = GL.glGenVertexArrays(1)
        self.vbo = GL.glGenBuffers(1)
        GL.glBindVertexArray(self.vao)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, self.vbo)
        GL.glBufferData(GL.GL_ARRAY_BUFFER, corners.nbytes, corners, GL.GL_STATIC_DRAW)
        GL.glEnableVertexAttribArray(0)
        GL.glVertexAttribPointer(0, 2, GL.GL_FLOAT, GL.GL_FALSE, 0, ctypes.c_void_p(0))
        GL.glBindVertexArray(0)
        self.set_grid_origin(0.0, 0.0)
        self.set_tessellation(self.tessellation)

    # Uniform block ----------------------------------------------------------------------------

    def set_terrain(self, terrain):
        """Fill the Terrain block from a terrain description and upload it now."""
        b = self.block
        coef = np.zeros((MAX_TERMS * MAX_TERMS, 2), np.float32)
        if isinstance(terrain, FourierTerrain):
            u = terrain.glsl_uniforms()
            k = u["terrain_terms"]
            if k > MAX_TERMS:
                raise ValueError(f"terrain.terms: at most {MAX_TERMS} can be drawn, got {k}")
            coef[: k * k] = u["terrain_coef"]
            self.kind = TERRAIN_FOURIER
            b.set("terrain_scale", (*u["terrain_scale"], 0.0))
            b.set("terrain_offset", (*u["terrain_offset"], 0.0))
            b.set("terrain_plane", (0.0, 1.0, 0.0, 0.0))
            bound, frequency = terrain.max_height_deviation(), u["terrain_frequency"]
        elif isinstance(terrain, PlaneTerrain):
            self.kind, k, bound, frequency = TERRAIN_PLANE, 0, 0.0, 0.0
            b.set("terrain_scale", (1.0, 1.0, 1.0, 0.0))
            b.set("terrain_offset", (0.0, 0.0, 0.0, 0.0))
            b.set("terrain_plane", (*terrain.normal, terrain.offset))
        else:
            self.kind, k, bound, frequency = TERRAIN_NONE, 0, 0.0, 0.0
        self.height_bound = bound
        b.set("terrain_info", (self.kind, k, int(self.cull), self.patches_per_side))
        b.set("terrain_params", (frequency, bound, self.contour_spacing, self.grid_spacing))
        b.set("terrain_coef", coef.reshape(-1, 4))
        self.ubo.upload()

    def set_tessellation(self, settings: TessellationSettings):
        self.tessellation = settings
        s = settings
        self.block.set("terrain_tess", (s.min_depth, s.max_depth, s.min_level, s.max_level))
        self.ubo.upload()

    def set_culling(self, on: bool):
        self.cull = bool(on)
        info = self.block.get("terrain_info")
        info[2] = int(self.cull)
        self.block.set("terrain_info", info)
        self.ubo.upload()

    def set_grid_origin(self, x: float, z: float):
        origin = (float(x), float(z))
        if origin == self._origin:
            return
        self._origin = origin
        self.block.set("terrain_grid", (x, z, self.patch_size, 0.0))
        self.ubo.upload()

    def center_on(self, x: float, z: float):
        """Centre the grid on a world point, snapped to whole patches."""
        half = self.patches_per_side // 2
        self.set_grid_origin((math.floor(x / self.patch_size) - half) * self.patch_size,
                             (math.floor(z / self.patch_size) - half) * self.patch_size)

    @property
    def extent(self) -> float:
        return self.patches_per_side * self.patch_size

    # Drawing ----------------------------------------------------------------------------------

    def draw(self, eye=None):
        if self.kind == TERRAIN_NONE:
            return
        if self.follow_camera and eye is not None:
            self.center_on(eye[0], eye[2])
        self.ubo.bind()
        self.program.use()
        GL.glPatchParameteri(GL.GL_PATCH_VERTICES, 4)
        GL.glBindVertexArray(self.vao)
        if self.wireframe:
            GL.glPolygonMode(GL.GL_FRONT_AND_BACK, GL.GL_LINE)
        GL.glDrawArrays(GL.GL_PATCHES, 0, self.vertex_count)
        if self.wireframe:
            GL.glPolygonMode(GL.GL_FRONT_AND_BACK, GL.GL_FILL)
        GL.glBindVertexArray(0)

    def capture_vertices(self, max_vertices: int = 1 << 20) -> tuple[np.ndarray, np.ndarray]:
        """World positions and normals of every vertex the evaluation shader emits, three per
        triangle, read back by transform feedback with rasterisation off.  The tests compare them
        with Warp's heights and check that neighbouring patches share their edge vertices."""
        if self._feedback_program is None:
            self._feedback_program = load_program("terrain.vert", "terrain.tesc", "terrain.tese",
                                                  feedback_varyings=["te_world", "te_normal"])
        stride = 24
        tfb = GL.glGenBuffers(1)
        GL.glBindBuffer(GL.GL_TRANSFORM_FEEDBACK_BUFFER, tfb)
        GL.glBufferData(GL.GL_TRANSFORM_FEEDBACK_BUFFER, max_vertices * stride, None, GL.GL_STATIC_READ)
        query = int(np.atleast_1d(GL.glGenQueries(1))[0])
        self.ubo.bind()
        self._feedback_program.use()
        GL.glPatchParameteri(GL.GL_PATCH_VERTICES, 4)
        GL.glBindVertexArray(self.vao)
        GL.glEnable(GL.GL_RASTERIZER_DISCARD)
        GL.glBindBufferBase(GL.GL_TRANSFORM_FEEDBACK_BUFFER, 0, tfb)
        GL.glBeginQuery(GL.GL_TRANSFORM_FEEDBACK_PRIMITIVES_WRITTEN, query)
        GL.glBeginTransformFeedback(GL.GL_TRIANGLES)
        GL.glDrawArrays(GL.GL_PATCHES, 0, self.vertex_count)
        GL.glEndTransformFeedback()
        GL.glEndQuery(GL.GL_TRANSFORM_FEEDBACK_PRIMITIVES_WRITTEN)
        GL.glDisable(GL.GL_RASTERIZER_DISCARD)
        GL.glBindVertexArray(0)
        written = np.zeros(1, np.uint32)
        GL.glGetQueryObjectuiv(query, GL.GL_QUERY_RESULT, written)
        count = min(int(written[0]) * 3, max_vertices)
        raw = GL.glGetBufferSubData(GL.GL_TRANSFORM_FEEDBACK_BUFFER, 0, count * stride)
        GL.glBindBufferBase(GL.GL_TRANSFORM_FEEDBACK_BUFFER, 0, 0)
        GL.glDeleteBuffers(1, [tfb])
        GL.glDeleteQueries(1, [query])
        data = raw if isinstance(raw, np.ndarray) else np.frombuffer(bytes(raw), np.uint8)
        vertices = data.view(np.float32).reshape(-1, 6)[:count].copy()
        return vertices[:, :3], vertices[:, 3:]

    def delete(self):
        GL.glDeleteVertexArrays(1, [self.vao])
        GL.glDeleteBuffers(1, [self.vbo])
        self.ubo.delete()
        self.program.delete()
        if self._feedback_program is not None:
            self._feedback_program.delete()
