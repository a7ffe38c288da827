"""GLSL programs loaded from ``shaders/`` (``warp_sim_render/shaders`` when installed), std140 uniform buffers.

Shader files may ``#include "other.glsl"`` (resolved relative to the including file).  The
expanded source keeps a table of where each of its lines came from, so a compile error that the
driver reports at a line of the expanded text is mapped back to ``path:line`` and raised as
ShaderError (a table rather than ``#line`` directives: drivers disagree on their numbering).
"""

from __future__ import annotations

import ctypes
import re
from pathlib import Path
from typing import ClassVar

import numpy as np
from OpenGL import GL

def find_data_dir(name: str, checkout: str) -> Path:
    """A data folder shipped inside this package (installed), else the checkout's own copy."""
    here = Path(__file__).resolve().parent
    for candidate in (here / name, here.parent / checkout):
        if candidate.is_dir():
            return candidate
    return here / name  # missing: the read that needs it names this path


SHADER_DIR = find_data_dir("shaders", "shaders")

STAGES = {
    ".vert": GL.GL_VERTEX_SHADER,
    ".tesc": GL.GL_TESS_CONTROL_SHADER,
    ".tese": GL.GL_TESS_EVALUATION_SHADER,
    ".geom": GL.GL_GEOMETRY_SHADER,
    ".frag": GL.GL_FRAGMENT_SHADER,
}

# Binding points of the shared uniform blocks (same in every program).
BLOCK_BINDINGS = {"Camera": 0, "Light": 1, "Terrain": 2}

_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"\s*$')
# Driver log formats: Mesa "0:12(5): error", NVIDIA "0(12) : error", AMD/Intel "ERROR: 0:12: msg".
_LOG_LOCATIONS = (
    re.compile(r"^(?P<src>\d+):(?P<line>\d+)\(\d+\):\s*(?P<msg>.*)$"),
    re.compile(r"^(?P<src>\d+)\((?P<line>\d+)\)\s*:\s*(?P<msg>.*)$"),
    re.compile(r"^(?P<kind>ERROR|WARNING):\s*(?P<src>\d+):(?P<line>\d+):\s*(?P<msg>.*)$"),
)


class ShaderError(RuntimeError):
    """A shader failed to compile or a program failed to link.

    Attributes:
        path: the file the first error points at (or the stage's main file).
        line: its line number in that file, or None when the driver gave none.
        log: the driver's log rewritten to ``path:line: message`` lines.
    """

    def __init__(self, message: str, path: Path | None = None, line: int | None = None, log: str = ""):
        super().__init__(message)
        self.path = path
        self.line = line
        self.log = log


def preprocess(path: Path, stack: tuple = ()) -> tuple[str, list[tuple[Path, int]]]:
    """Expand includes; returns the source and, for each of its lines, the (file, line) it came from."""
    path = Path(path).resolve()
    if path in stack:
        raise ShaderError(f"{path}: recursive #include", path)
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise ShaderError(f"{path}: cannot read shader file ({exc.strerror})", path) from exc
    out, origin = [], []
    for number, text in enumerate(lines, start=1):
        match = _INCLUDE.match(text)
        if match:
            child = (path.parent / match.group(1)).resolve()
            if not child.is_file():
                raise ShaderError(f"{path}:{number}: included file {match.group(1)!r} not found", path, number)
            source, child_origin = preprocess(child, (*stack, path))
            out.extend(source.splitlines())
            origin.extend(child_origin)
        else:
            out.append(text)
            origin.append((path, number))
    return "\n".join(out) + "\n", origin


def _rewrite_log(log: str, origin: list[tuple[Path, int]]) -> tuple[str, Path | None, int | None]:
    """Map the driver's line numbers (in the expanded source) back to files and lines."""
    rewritten, first_path, first_line = [], None, None
    for raw in log.splitlines():
        text = raw.strip()
        if not text:
            continue
        for pattern in _LOG_LOCATIONS:
            match = pattern.match(text)
            if match:
                line = int(match.group("line"))
                where, file_line = origin[min(max(line, 1), len(origin)) - 1]
                kind = match.groupdict().get("kind")
                msg = f"{kind.lower()}: {match.group('msg')}" if kind else match.group("msg")
                rewritten.append(f"{where}:{file_line}: {msg}")
                if first_path is None and "error" in text.lower():
                    first_path, first_line = where, file_line
                break
        else:
            rewritten.append(text)
    return "\n".join(rewritten), first_path, first_line


def compile_shader(path: Path) -> int:
    path = Path(path)
    stage = STAGES.get(path.suffix)
    if stage is None:
        raise ShaderError(f"{path}: unknown shader stage suffix {path.suffix!r}", path)
    source, origin = preprocess(path)
    shader = GL.glCreateShader(stage)
    GL.glShaderSource(shader, source)
    GL.glCompileShader(shader)
    if not GL.glGetShaderiv(shader, GL.GL_COMPILE_STATUS):
        raw = GL.glGetShaderInfoLog(shader)
        raw = raw.decode(errors="replace") if isinstance(raw, bytes) else str(raw)
        GL.glDeleteShader(shader)
        log, where, line = _rewrite_log(raw, origin)
        where = where or path.resolve()
        location = f"{where}:{line}" if line else f"{where}"
        raise ShaderError(f"{location}: shader compile failed\n{log or raw.strip()}", where, line, log)
    return shader


class Program:
    """A linked GLSL program plus cached uniform locations."""

    def __init__(self, *paths, feedback_varyings: list[str] | None = None):
        self.paths = [Path(p) for p in paths]
        shaders = []
        try:
            for p in self.paths:
                shaders.append(compile_shader(p))
        except ShaderError:
            for s in shaders:
                GL.glDeleteShader(s)
            raise
        program = GL.glCreateProgram()
        for s in shaders:
            GL.glAttachShader(program, s)
        if feedback_varyings:
            names = (ctypes.c_char_p * len(feedback_varyings))(*[n.encode() for n in feedback_varyings])
            pointer = ctypes.cast(names, ctypes.POINTER(ctypes.POINTER(ctypes.c_char)))
            GL.glTransformFeedbackVaryings(program, len(feedback_varyings), pointer, GL.GL_INTERLEAVED_ATTRIBS)
        GL.glLinkProgram(program)
        for s in shaders:
            GL.glDetachShader(program, s)
            GL.glDeleteShader(s)
        if not GL.glGetProgramiv(program, GL.GL_LINK_STATUS):
            raw = GL.glGetProgramInfoLog(program)
            raw = raw.decode(errors="replace") if isinstance(raw, bytes) else str(raw)
            GL.glDeleteProgram(program)
            names = ", ".join(str(p) for p in self.paths)
            raise ShaderError(f"link failed for {names}\n{raw.strip()}", self.paths[0], None, raw)
        self.id = program
        self._locations: dict[str, int] = {}
        self.block_sizes: dict[str, int] = {}
        for name, binding in BLOCK_BINDINGS.items():
            index = GL.glGetUniformBlockIndex(program, name)
            if index != GL.GL_INVALID_INDEX:
                GL.glUniformBlockBinding(program, index, binding)
                size = np.zeros(1, np.int32)
                GL.glGetActiveUniformBlockiv(program, index, GL.GL_UNIFORM_BLOCK_DATA_SIZE, size)
                self.block_sizes[name] = int(size[0])

    def use(self):
        GL.glUseProgram(self.id)

    def location(self, name: str) -> int:
        if name not in self._locations:
            self._locations[name] = GL.glGetUniformLocation(self.id, name)
        return self._locations[name]

    def set_int(self, name: str, value: int):
        GL.glUniform1i(self.location(name), int(value))

    def set_float(self, name: str, value: float):
        GL.glUniform1f(self.location(name), float(value))

    def delete(self):
        GL.glDeleteProgram(self.id)


def load_program(*names: str, shader_dir: Path = SHADER_DIR, feedback_varyings=None) -> Program:
    """``load_program("terrain.vert", "terrain.tesc", ...)`` from the shader folder."""
    return Program(*[Path(shader_dir) / n for n in names], feedback_varyings=feedback_varyings)


class Std140Block:
    """Host mirror of a std140 uniform block made only of vec4 / ivec4 / mat4 members (and arrays
    of them), so every member is 16-byte aligned and the layout is sequential."""

    _WIDTH: ClassVar[dict[str, int]] = {"vec4": 1, "ivec4": 1, "mat4": 4}

    def __init__(self, fields: list[tuple[str, str, int]]):
        self.offsets: dict[str, tuple[int, str, int]] = {}
        offset = 0
        for name, kind, count in fields:
            self.offsets[name] = (offset, kind, count)
            offset += 16 * self._WIDTH[kind] * count
        self.data = np.zeros(offset, dtype=np.uint8)

    @property
    def nbytes(self) -> int:
        return self.data.nbytes

    def set(self, name: str, value):
        offset, kind, count = self.offsets[name]
        size = 16 * self._WIDTH[kind] * count
        dtype = np.int32 if kind == "ivec4" else np.float32
        flat = np.zeros(size // 4, dtype=dtype)
        if kind == "mat4":
            # numpy matrices are row-major; std140 stores columns.
            values = np.asarray(value, dtype=np.float32).reshape(count, 4, 4).transpose(0, 2, 1).ravel()
        else:
            values = np.asarray(value, dtype=dtype).ravel()
        flat[: min(values.size, flat.size)] = values[: flat.size]
        self.data[offset: offset + size] = flat.view(np.uint8)

    def get(self, name: str) -> np.ndarray:
        offset, kind, count = self.offsets[name]
        size = 16 * self._WIDTH[kind] * count
        dtype = np.int32 if kind == "ivec4" else np.float32
        return self.data[offset: offset + size].view(dtype).copy()


class UniformBuffer:
    """A GL uniform buffer bound to a fixed binding point, filled from a Std140Block."""

    def __init__(self, binding: int, block: Std140Block):
        self.binding = binding
        self.block = block
        self.id = GL.glGenBuffers(1)
        GL.glBindBuffer(GL.GL_UNIFORM_BUFFER, self.id)
        GL.glBufferData(GL.GL_UNIFORM_BUFFER, block.nbytes, None, GL.GL_DYNAMIC_DRAW)
        GL.glBindBuffer(GL.GL_UNIFORM_BUFFER, 0)
        GL.glBindBufferBase(GL.GL_UNIFORM_BUFFER, binding, self.id)

    def upload(self):
        GL.glBindBuffer(GL.GL_UNIFORM_BUFFER, self.id)
        GL.glBufferSubData(GL.GL_UNIFORM_BUFFER, 0, self.block.nbytes, self.block.data)
        GL.glBindBuffer(GL.GL_UNIFORM_BUFFER, 0)
        self.bind()

    def bind(self):
        GL.glBindBufferBase(GL.GL_UNIFORM_BUFFER, self.binding, self.id)

    def read_back(self) -> np.ndarray:
        """The buffer's bytes as the GL sees them (tests)."""
        GL.glBindBuffer(GL.GL_UNIFORM_BUFFER, self.id)
        raw = GL.glGetBufferSubData(GL.GL_UNIFORM_BUFFER, 0, self.block.nbytes)
        GL.glBindBuffer(GL.GL_UNIFORM_BUFFER, 0)
        return np.frombuffer(bytes(raw), dtype=np.uint8) if not isinstance(raw, np.ndarray) else raw.view(np.uint8)

    def delete(self):
        GL.glDeleteBuffers(1, [self.id])


def check_block_size(program: Program, name: str, block: Std140Block):
    """Raise if the GLSL declaration of a block and its Python mirror disagree in size."""
    size = program.block_sizes.get(name)
    if size is not None and size != block.nbytes:
        raise ShaderError(f"uniform block {name}: GLSL size {size} bytes, Python mirror {block.nbytes} bytes",
                          program.paths[0])
