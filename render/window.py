"""GLFW window with an OpenGL 4.1 core, forward-compatible context; offscreen render targets.

The framebuffer size (pixels) and the window size (screen units) differ on high-DPI displays:
viewports and projections use the framebuffer size, mouse input arrives in window units.
"""

from __future__ import annotations

import glfw  # before imgui_bundle, so the pure-Python imgui backend shares this GLFW
import numpy as np
from OpenGL import GL

GL_VERSION = (4, 1)


class ContextError(RuntimeError):
    """No OpenGL 4.1 core context could be created (no display, old driver)."""


class Window:
    """A GLFW window; input callbacks are forwarded to one ``handler`` object.

    The handler may define ``on_key(key, action, mods)``, ``on_char(codepoint)``,
    ``on_mouse_button(button, action, mods)``, ``on_cursor(x, y)``, ``on_scroll(dx, dy)`` and
    ``on_resize(fb_width, fb_height)``; missing methods are skipped.
    """

    def __init__(self, width: int = 1280, height: int = 720, title: str = "warp_sim", visible: bool = True,
                 vsync: bool = True, samples: int = 4):
        if not glfw.init():
            raise ContextError("GLFW could not initialise (is DISPLAY set? run under xvfb-run when headless)")
        glfw.default_window_hints()
        glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, GL_VERSION[0])
        glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, GL_VERSION[1])
        glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
        glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
        glfw.window_hint(glfw.VISIBLE, bool(visible))
        glfw.window_hint(glfw.SAMPLES, samples if visible else 0)
        glfw.window_hint(glfw.SCALE_TO_MONITOR, True)
        self.handle = glfw.create_window(int(width), int(height), title, None, None)
        if not self.handle:
            raise ContextError(f"could not create an OpenGL {GL_VERSION[0]}.{GL_VERSION[1]} core window")
        glfw.make_context_current(self.handle)
        self.visible = visible
        self.handler = None
        self._vsync = None
        self.vsync = vsync
        glfw.set_key_callback(self.handle, lambda _w, key, _sc, action, mods: self._emit("on_key", key, action, mods))
        glfw.set_char_callback(self.handle, lambda _w, cp: self._emit("on_char", cp))
        glfw.set_mouse_button_callback(self.handle, lambda _w, b, action, mods: self._emit("on_mouse_button", b,
                                                                                          action, mods))
        glfw.set_cursor_pos_callback(self.handle, lambda _w, x, y: self._emit("on_cursor", x, y))
        glfw.set_scroll_callback(self.handle, lambda _w, dx, dy: self._emit("on_scroll", dx, dy))
        glfw.set_framebuffer_size_callback(self.handle, lambda _w, fw, fh: self._emit("on_resize", fw, fh))

    def _emit(self, name, *args):
        method = getattr(self.handler, name, None)
        if method is not None:
            method(*args)

    @staticmethod
    def gl_info() -> dict:
        def text(name):
            value = GL.glGetString(name)
            return value.decode() if isinstance(value, bytes) else str(value)

        return {"version": text(GL.GL_VERSION), "renderer": text(GL.GL_RENDERER),
                "glsl": text(GL.GL_SHADING_LANGUAGE_VERSION)}

    @property
    def vsync(self) -> bool:
        return self._vsync

    @vsync.setter
    def vsync(self, on: bool):
        self._vsync = bool(on)
        glfw.swap_interval(1 if on else 0)

    @property
    def framebuffer_size(self) -> tuple[int, int]:
        return glfw.get_framebuffer_size(self.handle)

    @property
    def window_size(self) -> tuple[int, int]:
        return glfw.get_window_size(self.handle)

    @property
    def content_scale(self) -> tuple[float, float]:
        """Framebuffer pixels per window unit (2 on a typical high-DPI display)."""
        (fw, fh), (ww, wh) = self.framebuffer_size, self.window_size
        return (fw / ww if ww else 1.0, fh / wh if wh else 1.0)

    def should_close(self) -> bool:
        return bool(glfw.window_should_close(self.handle))

    def close(self):
        glfw.set_window_should_close(self.handle, True)

    def key_down(self, key: int) -> bool:
        return glfw.get_key(self.handle, key) == glfw.PRESS

    def mouse_down(self, button: int) -> bool:
        return glfw.get_mouse_button(self.handle, button) == glfw.PRESS

    def cursor(self) -> tuple[float, float]:
        return glfw.get_cursor_pos(self.handle)

    def set_title(self, title: str):
        glfw.set_window_title(self.handle, title)

    @staticmethod
    def poll_events():
        glfw.poll_events()

    @staticmethod
    def time() -> float:
        return glfw.get_time()

    def swap_buffers(self):
        glfw.swap_buffers(self.handle)

    def destroy(self):
        if self.handle:
            glfw.destroy_window(self.handle)
            self.handle = None


class RenderTarget:
    """An offscreen colour + depth framebuffer (hidden windows have no reliable back buffer)."""

    def __init__(self, width: int, height: int, samples: int = 0):
        self.width, self.height, self.samples = int(width), int(height), int(samples)
        self.fbo = GL.glGenFramebuffers(1)
        self.color = GL.glGenRenderbuffers(1)
        self.depth = GL.glGenRenderbuffers(1)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, self.fbo)
        for buffer, fmt, attachment in ((self.color, GL.GL_RGBA8, GL.GL_COLOR_ATTACHMENT0),
                                        (self.depth, GL.GL_DEPTH_COMPONENT24, GL.GL_DEPTH_ATTACHMENT)):
            GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, buffer)
            if self.samples:
                GL.glRenderbufferStorageMultisample(GL.GL_RENDERBUFFER, self.samples, fmt, self.width, self.height)
            else:
                GL.glRenderbufferStorage(GL.GL_RENDERBUFFER, fmt, self.width, self.height)
            GL.glFramebufferRenderbuffer(GL.GL_FRAMEBUFFER, attachment, GL.GL_RENDERBUFFER, buffer)
        status = GL.glCheckFramebufferStatus(GL.GL_FRAMEBUFFER)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
        if status != GL.GL_FRAMEBUFFER_COMPLETE:
            raise ContextError(f"offscreen framebuffer incomplete (status 0x{int(status):x})")

    def bind(self):
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, self.fbo)
        GL.glViewport(0, 0, self.width, self.height)

    def delete(self):
        GL.glDeleteFramebuffers(1, [self.fbo])
        GL.glDeleteRenderbuffers(2, [self.color, self.depth])


def read_pixels(width: int, height: int, framebuffer: int = 0) -> np.ndarray:
    """RGB pixels of a framebuffer as (height, width, 3) uint8, top row first."""
    GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, framebuffer)
    if framebuffer == 0:
        GL.glReadBuffer(GL.GL_BACK)
    GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
    raw = GL.glReadPixels(0, 0, width, height, GL.GL_RGB, GL.GL_UNSIGNED_BYTE)
    GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, 0)
    pixels = np.frombuffer(bytes(raw) if not isinstance(raw, np.ndarray) else raw.tobytes(), dtype=np.uint8)
    return pixels.reshape(height, width, 3)[::-1].copy()


def resolve(source: RenderTarget, target: RenderTarget):
    """Blit a multisampled target into a single-sampled one (for reading pixels)."""
    GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, source.fbo)
    GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, target.fbo)
    GL.glBlitFramebuffer(0, 0, source.width, source.height, 0, 0, target.width, target.height,
                         GL.GL_COLOR_BUFFER_BIT, GL.GL_NEAREST)
    GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)


def save_png(path, pixels: np.ndarray):
    from PIL import Image

    Image.fromarray(pixels, "RGB").save(path)
