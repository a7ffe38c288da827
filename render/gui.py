"""imgui panel (imgui-bundle, its pure-Python GLFW + OpenGL 3 backend) and implot live plots.

The panel only reads state and calls DemoController functions (set_param, seek, reset, ...), so
everything it can do is also reachable from the tests.  Material sliders apply when released (a
material change rebuilds the model and resets the run); every other slider applies while dragged.
Input events arrive from the viewer, which forwards them here first and skips its own handling
when imgui wants the mouse or keyboard.
"""

from __future__ import annotations

import math

import numpy as np
from imgui_bundle import imgui, implot
from imgui_bundle.python_backends.glfw_backend import GlfwRenderer

from .controller import PARAMS, list_scenes, load_demo_scene
from .plot_limits import axis_limits

PANEL_WIDTH = 380.0
LABEL_WIDTH = 130.0  # room right of each widget for its label ("solver iterations" was cut off)
PLOT_HEIGHT = 120.0
NOTE_COLOR = (1.0, 0.8, 0.3, 1.0)
DIM_COLOR = (0.7, 0.7, 0.7, 1.0)


class Gui:
    def __init__(self, window, controller, viewer):
        self.window = window
        self.controller = controller
        self.viewer = viewer
        self.context = imgui.create_context()
        self.plot_context = implot.create_context()
        imgui.get_io().set_ini_filename(None)  # no imgui.ini beside the user's files
        imgui.style_colors_dark()
        self.backend = GlfwRenderer(window.handle, attach_callbacks=False)
        self.visible = True
        self.show_plots = True
        self._pending: dict[str, object] = {}
        self._in_frame = False
        self._scenes = list_scenes()
        self._scene_counts: dict = {}

    # Input forwarding -------------------------------------------------------------------------

    def key(self, key, action, mods):
        self.backend.keyboard_callback(self.window.handle, key, 0, action, mods)

    def char(self, codepoint):
        self.backend.char_callback(self.window.handle, codepoint)

    def mouse_button(self, button, action, mods):
        self.backend.mouse_button_callback(self.window.handle, button, action, mods)

    def cursor(self, x, y):
        imgui.get_io().add_mouse_pos_event(x, y)

    def scroll(self, dx, dy):
        self.backend.scroll_callback(self.window.handle, dx, dy)

    @property
    def wants_mouse(self) -> bool:
        return self.visible and imgui.get_io().want_capture_mouse

    @property
    def wants_keyboard(self) -> bool:
        return self.visible and imgui.get_io().want_capture_keyboard

    # Frame ------------------------------------------------------------------------------------

    def new_frame(self):
        self.backend.process_inputs()
        imgui.new_frame()
        self._in_frame = True
        if self.visible:
            self.build()

    def render(self):
        """Draw the panel built by the last new_frame (nothing if no frame was started)."""
        if not self._in_frame:
            return
        self._in_frame = False
        imgui.render()
        if self.visible:
            self.backend.render(imgui.get_draw_data())

    def shutdown(self):
        self.backend.shutdown()
        implot.destroy_context(self.plot_context)
        imgui.destroy_context(self.context)

    # Widgets ----------------------------------------------------------------------------------

    def _float(self, name: str, lo: float | None = None, hi: float | None = None, fmt: str = "%.3f",
               log: bool = False, on_release: bool = False):
        spec = PARAMS[name]
        c = self.controller
        value = self._pending.get(name, c.get_param(name))
        flags = imgui.SliderFlags_.logarithmic if log else 0
        label = spec.label or name.replace("_", " ")
        changed, value = imgui.slider_float(label, float(value), spec.lo if lo is None else lo,
                                            spec.hi if hi is None else hi, fmt, flags)
        self._apply(name, changed, value, on_release)

    def _int(self, name: str, lo: int | None = None, hi: int | None = None):
        spec = PARAMS[name]
        label = spec.label or name.replace("_", " ")
        changed, value = imgui.slider_int(label, int(self.controller.get_param(name)),
                                          int(spec.lo if lo is None else lo), int(spec.hi if hi is None else hi))
        self._apply(name, changed, value, False)

    def _vec3(self, name: str, speed: float = 0.05):
        spec = PARAMS[name]
        label = spec.label or name
        changed, value = imgui.drag_float3(label, [float(v) for v in self.controller.get_param(name)], speed,
                                           spec.lo, spec.hi)
        self._apply(name, changed, value, False)

    def _choice(self, name: str):
        spec = PARAMS[name]
        current = self.controller.get_param(name)
        index = spec.choices.index(current) if current in spec.choices else 0
        changed, index = imgui.combo(spec.label or name.replace("_", " "), index, list(spec.choices))
        if changed:
            self.controller.set_param(name, spec.choices[index])

    def _bool(self, name: str, label: str | None = None):
        changed, value = imgui.checkbox(label or name.replace("_", " "), bool(self.controller.get_param(name)))
        if changed:
            self.controller.set_param(name, value)

    def _apply(self, name, changed, value, on_release):
        if not on_release:
            if changed:
                self.controller.set_param(name, value)
            return
        if changed:
            self._pending[name] = value
        if imgui.is_item_deactivated_after_edit() and name in self._pending:
            self.controller.set_param(name, self._pending.pop(name))
        elif not imgui.is_item_active():
            self._pending.pop(name, None)

    # Panel ------------------------------------------------------------------------------------

    def build(self):
        c = self.controller
        sim = c.sim
        io = imgui.get_io()
        imgui.set_next_window_pos((10, 10), imgui.Cond_.first_use_ever)
        # The window fits the display; the sections below the controls scroll inside it.
        imgui.set_next_window_size((PANEL_WIDTH, max(200.0, io.display_size.y - 20)), imgui.Cond_.first_use_ever)
        imgui.begin("warp_sim")
        imgui.push_item_width(-LABEL_WIDTH)  # widgets leave room for their labels
        # the first frame has no frame time yet (1000 / 0 would read as a million fps)
        fps = f"{1000.0 / self.viewer.frame_ms:5.1f}" if self.viewer.frames_done >= 2 and self.viewer.frame_ms > 0 \
            else "  -- "
        if getattr(c, "replay_mode", False):
            imgui.text(f"{fps} fps  render {self.viewer.render_ms:6.2f} ms")
            self._replay_panel()
            imgui.pop_item_width()
            imgui.end()
            return
        imgui.text(f"{fps} fps  physics {c.last_physics_ms:6.2f} ms  render {self.viewer.render_ms:6.2f} ms")
        imgui.text(f"step {sim.step_count}  t = {sim.time:.3f} s  bodies {c.body_count}  contacts "
                   f"{self.viewer.contact_count}")
        if imgui.button("Pause" if not c.paused else "Play"):
            c.toggle_pause()
        imgui.same_line()
        if imgui.button("< step"):
            c.step_backward()
        imgui.same_line()
        if imgui.button("step >"):
            c.step_forward()
        imgui.same_line()
        if imgui.button("Reset"):
            c.reset()
        imgui.same_line()
        if imgui.button("Replay"):
            c.replay()
        imgui.same_line()
        if imgui.button("Rebuild"):
            c.rebuild()
        h = c.history
        changed, step = imgui.slider_int("timeline", sim.step_count, h.origin, max(h.head, h.origin + 1))
        if changed:
            c.paused = True
            c.seek(step)
        imgui.text_colored(DIM_COLOR, f"keyframes {len(h.keyframes)} every {h.interval} steps, "
                                      f"{h.keyframe_bytes() / 2**20:.1f} MiB")
        for note in c.recent_notes():
            imgui.text_colored(NOTE_COLOR, note)
        imgui.begin_child("sections", imgui.ImVec2(0, 0))  # scrolls when the open sections are taller
        imgui.push_item_width(-LABEL_WIDTH)
        if imgui.collapsing_header("Plots", imgui.TreeNodeFlags_.default_open):
            self._plots()

        if imgui.collapsing_header("Scene"):
            self._scene_picker()
        if imgui.collapsing_header("Physics", imgui.TreeNodeFlags_.default_open):
            self._float("dt", 1e-4, 0.05, "%.5f", log=True)
            self._int("substeps", 1, 32)
            self._bool("auto_substeps")
            plan = getattr(sim, "substep_plan", None)
            if plan is not None and plan.substeps != plan.requested:  # auto_substeps raised it (column_sag.py)
                imgui.text_colored(DIM_COLOR, f"running {plan.substeps} substeps: {plan.reason()}")
            self._vec3("gravity", 0.1)
            self._bool("face_search")
            self._bool("still_contacts")
            self._choice("integrator")
            self._choice("rotation")
            self._int("iterations", 1, 32)
            self._int("relax_iterations", 0, 16)
        if imgui.collapsing_header("Material (rebuilds and resets)"):
            self._choice("friction_model")
            if c.material.friction_model == "slipperiness":
                self._float("slipperiness", on_release=True)
            else:
                self._float("friction", on_release=True)
            self._float("restitution", on_release=True)
            self._float("rolling_resistance", on_release=True)
        if imgui.collapsing_header("Terrain"):
            if c.get_param("amplitude") is None:
                imgui.text_colored(DIM_COLOR, f"{sim.model.terrain.kind} terrain: nothing to edit")
            else:
                self._float("amplitude", 0.0, 5.0)
                self._float("frequency", 0.01, 2.0, log=True)
                self._float("phase", -math.pi, math.pi)
                self._int("terms", 1, 16)
                changed, seed = imgui.input_int("seed", int(c.get_param("seed")))
                if changed:
                    c.set_param("seed", seed)
                self._vec3("scale", 0.02)
        if imgui.collapsing_header("Tessellation"):
            self._float("tess_min_depth", 0.0, 200.0, "%.1f")
            self._float("tess_max_depth", 1.0, 1000.0, "%.1f", log=True)
            self._float("tess_min_level", fmt="%.1f")
            self._float("tess_max_level", fmt="%.1f")
            self._bool("wireframe")
            changed, cull = imgui.checkbox("frustum culling", self.viewer.terrain.cull)
            if changed:
                self.viewer.terrain.set_culling(cull)
        if imgui.collapsing_header("View"):
            self._choice("color_mode")
            self._int("steps_per_frame", 1, 20)
            self._bool("vsync")
            cam = self.viewer.camera
            changed, orbit = imgui.checkbox("orbit camera (C)", cam.mode == "orbit")
            if changed:
                cam.set_mode("orbit" if orbit else "fly")
            imgui.text_colored(DIM_COLOR, f"camera speed {cam.speed:.1f} m/s (scroll)")
            for name in ("show_checkpoints", "show_contacts", "show_normals", "show_velocities",
                         "show_penetration"):
                self._bool(name, name.replace("show_", "").replace("_", " "))
            self._bool("debug_on_top", "markers show through terrain")
        imgui.pop_item_width()
        imgui.end_child()
        imgui.pop_item_width()
        imgui.end()

    def _replay_panel(self):
        """Play, pause, scrub and speed for a recorded run (render/replay.py), then plots and view."""
        c = self.controller
        p = c.playback
        imgui.text(f"replay {c.path.name}: {c.body_count} bodies")
        imgui.text(f"frame {p.frame + 1} of {c.frame_count}  t = {p.time:.3f} of {p.end:.3f} s")
        if imgui.button("Pause" if p.playing else "Play"):
            c.toggle_pause()
        imgui.same_line()
        if imgui.button("|<"):
            c.reset()
        imgui.same_line()
        if imgui.button("< frame"):
            c.paused = True
            c.step_backward()
        imgui.same_line()
        if imgui.button("frame >"):
            c.paused = True
            c.step_forward()
        changed, t = imgui.slider_float("time [s]", p.time, p.start, max(p.end, p.start + 1e-6), "%.3f")
        if changed:
            c.paused = True
            c.seek_time(t)
        changed, frame = imgui.slider_int("frame", p.frame, 0, max(c.frame_count - 1, 1))
        if changed:
            c.paused = True
            c.seek(frame)
        speeds = list(p.SPEEDS)
        index = speeds.index(p.speed) if p.speed in speeds else speeds.index(1.0)
        changed, index = imgui.combo("speed", index, [f"{v:g}x" for v in speeds])
        if changed:
            p.speed = speeds[index]
        _, p.loop = imgui.checkbox("loop", p.loop)
        for note in c.recent_notes():
            imgui.text_colored(NOTE_COLOR, note)
        imgui.begin_child("sections", imgui.ImVec2(0, 0))
        imgui.push_item_width(-LABEL_WIDTH)
        if imgui.collapsing_header("Plots (recorded)", imgui.TreeNodeFlags_.default_open):
            self._plots()
        if imgui.collapsing_header("View", imgui.TreeNodeFlags_.default_open):
            self._choice("color_mode")
            self._bool("wireframe")
            self._bool("vsync")
            cam = self.viewer.camera
            changed, orbit = imgui.checkbox("orbit camera (C)", cam.mode == "orbit")
            if changed:
                cam.set_mode("orbit" if orbit else "fly")
        imgui.pop_item_width()
        imgui.end_child()

    def _scene_picker(self):
        c = self.controller
        imgui.text(f"{c.scene.name}: {c.body_count} bodies")
        current = c.scene_path.name if c.scene_path else "(built-in)"
        if imgui.begin_combo("scene", current):
            for path in self._scenes:
                label = f"{path.name}  ({self._scene_count(path)} bodies)"
                selected, _ = imgui.selectable(label, c.scene_path is not None and path == c.scene_path)
                if selected:
                    c.load_scene(path)
            imgui.end_combo()

    def _scene_count(self, path) -> str:
        """Body count of a scene file, read once when the picker first shows it."""
        if path not in self._scene_counts:
            try:
                self._scene_counts[path] = str(load_demo_scene(path).body_count)
            except (ValueError, OSError):  # a broken file is reported when it is picked
                self._scene_counts[path] = "?"
        return self._scene_counts[path]

    def _plots(self):
        data = self.controller.stats.arrays()
        if len(data["frame"]) < 2:
            imgui.text_colored(DIM_COLOR, "plots start with the second frame")
            return
        x = data["frame"]
        energy = data["kinetic_energy"]
        # physics and render time differ twentyfold: each gets its own axis (physics left, render right)
        if getattr(self.controller, "replay_mode", False):  # nothing is simulated in a replay
            self._plot("##times", x, [("render ms", data["render_ms"])], [])
        else:
            self._plot("##times", x, [("physics ms", data["physics_ms"])], [("render ms", data["render_ms"])])
        self._plot("##counts", x, [("contacts", data["contacts"])],
                   [("kinetic energy J", energy)] if np.isfinite(energy).any() else [])
        self._plot("##awake", x, [("awake bodies", data["awake"])], [])

    def _plot(self, plot_id: str, x, left: list, right: list):
        """One live plot: a legend above the data (never over it) and limits from axis_limits."""
        if not implot.begin_plot(plot_id, imgui.ImVec2(-1, PLOT_HEIGHT)):
            return
        implot.setup_legend(implot.Location_.north, implot.LegendFlags_.outside | implot.LegendFlags_.horizontal)
        implot.setup_axis(implot.ImAxis_.x1, "", implot.AxisFlags_.no_tick_labels | implot.AxisFlags_.auto_fit)
        implot.setup_axis(implot.ImAxis_.y1, "")
        lo, hi = axis_limits(np.concatenate([v for _, v in left]))
        implot.setup_axis_limits(implot.ImAxis_.y1, lo, hi, implot.Cond_.always)
        if right:
            implot.setup_axis(implot.ImAxis_.y2, "", implot.AxisFlags_.opposite)
            lo, hi = axis_limits(np.concatenate([v for _, v in right]))
            implot.setup_axis_limits(implot.ImAxis_.y2, lo, hi, implot.Cond_.always)
        for label, values in left:
            implot.set_axes(implot.ImAxis_.x1, implot.ImAxis_.y1)
            implot.plot_line(label, x, np.nan_to_num(np.asarray(values, np.float64)))
        for label, values in right:
            implot.set_axes(implot.ImAxis_.x1, implot.ImAxis_.y2)
            implot.plot_line(label, x, np.nan_to_num(np.asarray(values, np.float64)))
        implot.end_plot()
