"""Viewer: the window, the renderers, the camera, the panel and the frame loop.

One frame:

    poll input -> panel (may call DemoController.set_param) -> physics (play or held arrows)
    -> upload (camera/light blocks, body instances, debug geometry) -> draw terrain, bodies,
    debug -> panel -> swap (or read pixels for --screenshot / --record)

Terrain and model changes reach the renderers through controller events, inside the set_param
call that made them, so the frame that changes a parameter already draws its result.
A hidden window renders into an offscreen framebuffer, which is what --screenshot reads.
"""

from __future__ import annotations

import time
from pathlib import Path

import glfw
import numpy as np
import warp as wp
from OpenGL import GL

from warp_sim.terrain import FourierTerrain, PlaneTerrain

from .body_renderer import COLOR_MODES, BodyRenderer
from .camera import Camera
from .debug_draw import DebugDraw, DebugOptions
from .shader import BLOCK_BINDINGS, Std140Block, UniformBuffer
from .terrain_renderer import TerrainRenderer, TessellationSettings
from .window import RenderTarget, Window, read_pixels, resolve, save_png

SKY = (0.62, 0.75, 0.90)
HOLD_DELAY = 0.35  # [s] an arrow key held longer than this steps every frame


def camera_block() -> Std140Block:
    return Std140Block([("camera_view", "mat4", 1), ("camera_projection", "mat4", 1),
                        ("camera_view_projection", "mat4", 1), ("camera_eye", "vec4", 1),
                        ("camera_viewport", "vec4", 1)])


def light_block() -> Std140Block:
    return Std140Block([("light_direction", "vec4", 1), ("light_color", "vec4", 1),
                        ("light_specular", "vec4", 1), ("sky_color", "vec4", 1)])


def ground_height(terrain, x: float, z: float) -> float:
    """The terrain's base height near (x, z): Fourier offset y, plane height, or 0."""
    if isinstance(terrain, FourierTerrain):
        return float(terrain.offset[1])
    if isinstance(terrain, PlaneTerrain) and abs(terrain.normal[1]) > 1e-3:
        return float(terrain.height(x, z))
    return 0.0


class Viewer:
    def __init__(self, controller, width: int = 1280, height: int = 720, visible: bool = True,
                 vsync: bool = True, gui: bool = True, samples: int = 4, title: str = "warp_sim demo"):
        self.controller = controller
        self.window = Window(width, height, title, visible=visible, vsync=vsync, samples=samples)
        self.window.handler = self
        controller.view.vsync = vsync
        self.offscreen = None
        self.resolved = None
        if not visible:
            self.offscreen = RenderTarget(width, height, samples)
            self.resolved = RenderTarget(width, height) if samples else self.offscreen

        self.camera = Camera()
        self.camera_block = camera_block()
        self.camera_ubo = UniformBuffer(BLOCK_BINDINGS["Camera"], self.camera_block)
        self.light_block = light_block()
        self.light_ubo = UniformBuffer(BLOCK_BINDINGS["Light"], self.light_block)
        self.terrain = TerrainRenderer()
        self.bodies = BodyRenderer()
        self.debug = DebugDraw()
        self.set_light()

        self.gui = None
        if gui:
            from .gui import Gui

            self.gui = Gui(self.window, controller, self)
        self.frame_ms = self.render_ms = self.upload_ms = self.draw_ms = 0.0
        self.frames_done = 0  # frame_ms means something from the second frame on
        self.contact_count = 0
        self.sync_timings = True  # glFinish before reading the clock, so draw time is real
        self.profile_passes = False  # also glFinish after each pass, filling pass_ms (benchmarks)
        self.pass_ms = {"terrain": 0.0, "bodies": 0.0, "debug": 0.0}
        self._last_cursor = None
        self._held = {}
        self._last_time = time.perf_counter()
        controller.add_listener(self.on_event)
        self.on_event("scene")
        self.on_event("tessellation")
        self.on_event("view")

    # Controller events ------------------------------------------------------------------------

    def on_event(self, event: str):
        c = self.controller
        if event in ("model", "scene"):
            self.bodies.set_model(c.sim.model)
            self.terrain.set_terrain(c.sim.model.terrain)
            if event == "scene":
                self.frame_scene()
        elif event == "terrain":
            self.terrain.set_terrain(c.sim.model.terrain)
        elif event == "tessellation":
            v = c.view
            self.terrain.set_tessellation(TessellationSettings(v.tess_min_depth, v.tess_max_depth,
                                                               v.tess_min_level, v.tess_max_level))
        elif event == "view":
            v = c.view
            if self.window.vsync != v.vsync:
                self.window.vsync = v.vsync
            self.terrain.wireframe = v.wireframe
            self.bodies.color_mode = COLOR_MODES[v.color_mode]

    def frame_scene(self):
        """Aim the camera at the bodies' initial layout and size the terrain grid and fog to it."""
        pos = self.controller.sim.model.host["body_pos"]
        lo, hi = pos.min(axis=0) - 1.0, pos.max(axis=0) + 1.0
        center = 0.5 * (lo + hi)
        lo[1] = min(lo[1], ground_height(self.controller.sim.model.terrain, center[0], center[2]))
        self.camera.frame_bounds(lo, hi)
        span = float(np.max(hi - lo))
        self.terrain.patch_size = max(2.0, 4.0 * span / self.terrain.patches_per_side)
        self.terrain.set_grid_origin(0.0, 0.0)
        self.camera.far = max(1000.0, 2.0 * self.terrain.extent)
        self.set_light(fog_range=0.5 * self.terrain.extent)

    def set_light(self, direction=(0.45, 0.8, 0.35), fog_range: float = 128.0):
        b = self.light_block
        d = np.asarray(direction, np.float64)
        b.set("light_direction", (*(d / np.linalg.norm(d)), 0.0))
        b.set("light_color", (1.0, 0.97, 0.9, 0.38))
        b.set("light_specular", (0.5, 48.0, 0.0, 0.0))
        # Squared-exponential fog reaching 90 % at fog_range hides the edge of the patch grid.
        b.set("sky_color", (*SKY, 1.5174 / max(fog_range, 1e-3)))
        self.light_ubo.upload()

    # Input ------------------------------------------------------------------------------------

    def on_key(self, key, action, mods):
        if self.gui:
            self.gui.key(key, action, mods)
            if self.gui.wants_keyboard:
                return
        c = self.controller
        if action == glfw.PRESS:
            if key == glfw.KEY_SPACE:
                c.toggle_pause()
            elif key == glfw.KEY_RIGHT:
                c.paused = True
                c.step_forward()
                self._held[key] = time.perf_counter()
            elif key == glfw.KEY_LEFT:
                c.paused = True
                c.step_backward()
                self._held[key] = time.perf_counter()
            elif key == glfw.KEY_R:
                c.reset()
            elif key == glfw.KEY_C:
                self.camera.set_mode("fly" if self.camera.mode == "orbit" else "orbit")
            elif key == glfw.KEY_F1 and self.gui:
                self.gui.visible = not self.gui.visible
            elif key == glfw.KEY_G:
                c.set_param("wireframe", not c.view.wireframe)
            elif key == glfw.KEY_V:
                c.set_param("vsync", not c.view.vsync)
            elif key == glfw.KEY_ESCAPE:
                self.window.close()
        elif action == glfw.RELEASE:
            self._held.pop(key, None)

    def on_char(self, codepoint):
        if self.gui:
            self.gui.char(codepoint)

    def on_mouse_button(self, button, action, mods):
        if self.gui:
            self.gui.mouse_button(button, action, mods)
        self._last_cursor = None

    def on_cursor(self, x, y):
        if self.gui:
            self.gui.cursor(x, y)
        if self.window.mouse_down(glfw.MOUSE_BUTTON_RIGHT) and not (self.gui and self.gui.wants_mouse):
            if self._last_cursor is not None:
                self.camera.rotate(x - self._last_cursor[0], y - self._last_cursor[1])
            self._last_cursor = (x, y)
        else:
            self._last_cursor = None

    def on_scroll(self, dx, dy):
        if self.gui:
            self.gui.scroll(dx, dy)
            if self.gui.wants_mouse:
                return
        self.camera.scroll(dy)

    def process_held_keys(self, dt: float):
        if self.gui and self.gui.wants_keyboard:
            return
        w = self.window

        def axis(plus, minus):
            return float(w.key_down(plus)) - float(w.key_down(minus))

        forward, right, up = axis(glfw.KEY_W, glfw.KEY_S), axis(glfw.KEY_D, glfw.KEY_A), axis(glfw.KEY_E, glfw.KEY_Q)
        if forward or right or up:
            boost = 4.0 if w.key_down(glfw.KEY_LEFT_SHIFT) else 1.0
            self.camera.move(forward, right, up, dt, boost)
        now = time.perf_counter()
        c = self.controller
        for key, pressed in list(self._held.items()):
            if not w.key_down(key):
                self._held.pop(key)
            elif now - pressed > HOLD_DELAY:
                count = c.view.steps_per_frame
                c.step_forward(count) if key == glfw.KEY_RIGHT else c.step_backward(count)

    # Drawing ----------------------------------------------------------------------------------

    @property
    def size(self) -> tuple[int, int]:
        if self.offscreen is not None:
            return self.offscreen.width, self.offscreen.height
        return self.window.framebuffer_size

    def upload(self):
        """Everything the draw calls read: uniform blocks, body instances, debug geometry."""
        width, height = self.size
        cam = self.camera
        aspect = width / max(height, 1)
        b = self.camera_block
        b.set("camera_view", cam.view_matrix())
        b.set("camera_projection", cam.projection_matrix(aspect))
        b.set("camera_view_projection", cam.view_projection(aspect))
        b.set("camera_eye", (*cam.eye(), 1.0))
        b.set("camera_viewport", (width, height, cam.near, cam.far))
        self.camera_ubo.upload()
        sim = self.controller.sim
        self.bodies.update(sim.model, sim.state)
        v = self.controller.view
        options = DebugOptions(v.show_checkpoints, v.show_contacts, v.show_normals, v.show_velocities,
                               v.show_penetration, v.debug_on_top)
        self.debug.add_simulation(sim, options)

    def draw(self):
        width, height = self.size
        if self.offscreen is not None:
            self.offscreen.bind()
        else:
            GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
            GL.glViewport(0, 0, width, height)
        GL.glClearColor(*SKY, 1.0)
        GL.glClear(GL.GL_COLOR_BUFFER_BIT | GL.GL_DEPTH_BUFFER_BIT)
        GL.glEnable(GL.GL_DEPTH_TEST)
        if self.offscreen is None or self.offscreen.samples:
            GL.glEnable(GL.GL_MULTISAMPLE)
        passes = (("terrain", lambda: self.terrain.draw(self.camera.eye())), ("bodies", self.bodies.draw),
                  ("debug", self.debug.flush))
        for name, draw in passes:
            if self.profile_passes:
                start = time.perf_counter()
                draw()
                GL.glFinish()
                self.pass_ms[name] = (time.perf_counter() - start) * 1e3
            else:
                draw()

    def render(self):
        """Upload and draw one image (no input, no physics); fills the timing fields."""
        start = time.perf_counter()
        self.upload()
        if self.sync_timings:
            wp.synchronize_device(self.controller.sim.device)
        mid = time.perf_counter()
        self.draw()
        if self.gui:
            self.gui.render()
        if self.sync_timings:
            GL.glFinish()
        end = time.perf_counter()
        self.upload_ms, self.draw_ms = (mid - start) * 1e3, (end - mid) * 1e3
        self.render_ms = self.upload_ms + self.draw_ms

    def read_pixels(self) -> np.ndarray:
        """The last rendered image, (height, width, 3) uint8."""
        width, height = self.size
        if self.offscreen is None:
            return read_pixels(width, height, 0)
        if self.resolved is not self.offscreen:
            resolve(self.offscreen, self.resolved)
        return read_pixels(width, height, self.resolved.fbo)

    def screenshot(self, path):
        save_png(path, self.read_pixels())

    def frame(self, measure: bool = True):
        """One interactive frame."""
        now = time.perf_counter()
        dt, self._last_time = min(now - self._last_time, 0.1), now
        self.window.poll_events()
        if self.gui:
            self.gui.new_frame()
        self.process_held_keys(dt)
        self.controller.update()
        self.contact_count = self.controller.sim.contact_count()
        if self.gui is None:
            self._title()
        self.render()
        if measure:
            self.controller.measure(self.render_ms, with_energy=self.controller.body_count <= 200_000)
        self.frame_ms = (time.perf_counter() - now) * 1e3
        self.frames_done += 1

    def _title(self):
        c = self.controller
        if self.window.visible and c.sim.step_count % 30 == 0 and self.frames_done >= 2:
            self.window.set_title(f"warp_sim demo  step {c.sim.step_count}  {1000.0 / max(self.frame_ms, 1e-3):.0f} fps")

    def run(self, frames: int | None = None, record_dir=None, screenshot=None):
        """Frame loop until the window closes or ``frames`` frames are done.

        ``record_dir`` writes every frame as frame_00000.png ...; ``screenshot`` writes the last.
        """
        record = Path(record_dir) if record_dir else None
        if record:
            record.mkdir(parents=True, exist_ok=True)
        count = 0
        while not self.window.should_close() and (frames is None or count < frames):
            self.frame()
            if record:
                self.screenshot(record / f"frame_{count:05d}.png")
            if screenshot and frames is not None and count == frames - 1:
                self.screenshot(screenshot)
            if self.offscreen is None:
                self.window.swap_buffers()
            count += 1
        return count

    def close(self):
        if self.gui:
            self.gui.shutdown()
            self.gui = None
        self.terrain.delete()
        self.bodies.delete()
        self.debug.delete()
        for target in {id(t): t for t in (self.offscreen, self.resolved) if t is not None}.values():
            target.delete()
        self.window.destroy()
