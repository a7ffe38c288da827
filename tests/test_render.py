"""Viewer tests: shaders, tessellated heights against Warp, pixels, time travel, the panel's path.

The GL tests need an OpenGL 4.1 core context.  Without a display they start a private Xvfb
(Mesa's llvmpipe then provides OpenGL 4.5 core with tessellation); where there is no Xvfb
either, or no 4.1 context can be made, they skip with the reason.  Time travel and parameter
tests need no GL and run everywhere.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import warp as wp

from warp_sim.render_package import ensure_render_package

ensure_render_package()  # the checkout's render/ under its installed name, warp_sim_render
from warp_sim_render.controller import PARAMS, DemoController, builtin_scene  # noqa: E402
from warp_sim.terrain import FourierTerrain, PlaneTerrain, fourier_normal, fourier_sample  # noqa: E402

REPO = Path(__file__).resolve().parent.parent


# ----------------------------------------------------------------------------------------------
# GL fixtures


@pytest.fixture(scope="module")
def display():
    """The X display for the GL tests: $DISPLAY, else a private Xvfb for this module."""
    if not sys.platform.startswith("linux") or os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        yield os.environ.get("DISPLAY", "")
        return
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        pytest.skip("no display and no Xvfb for an OpenGL context (apt-get install xvfb, or run under xvfb-run)")
    read_fd, write_fd = os.pipe()
    proc = subprocess.Popen([xvfb, "-displayfd", str(write_fd), "-screen", "0", "1280x720x24", "-nolisten", "tcp"],
                            pass_fds=(write_fd,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(write_fd)
    with os.fdopen(read_fd) as pipe:
        number = pipe.readline().strip()  # Xvfb writes its display number once it accepts clients
    if not number:
        proc.kill()
        proc.wait()
        pytest.skip("Xvfb did not start, so there is no display for an OpenGL context")
    os.environ["DISPLAY"] = f":{number}"
    try:
        yield os.environ["DISPLAY"]
    finally:
        del os.environ["DISPLAY"]
        proc.terminate()
        proc.wait(timeout=10)


@pytest.fixture(scope="module")
def viewer(display):
    """A hidden 320x240 viewer (offscreen framebuffer, panel hidden) on the built-in scene."""
    pytest.importorskip("glfw", reason="the viewer needs pyGLFW (pip install -e .[viewer])")
    pytest.importorskip("OpenGL", reason="the viewer needs PyOpenGL (pip install -e .[viewer])")
    pytest.importorskip("imgui_bundle", reason="the viewer needs imgui-bundle (pip install -e .[viewer])")
    from warp_sim_render.viewer import Viewer
    from warp_sim_render.window import ContextError

    controller = DemoController(builtin_scene(), paused=True)
    try:
        v = Viewer(controller, 320, 240, visible=False, vsync=False, gui=True, samples=0)
    except ContextError as exc:
        pytest.skip(f"no OpenGL 4.1 core context: {exc}")
    v.gui.visible = False
    yield v
    v.close()


def gl_error_free():
    from OpenGL import GL

    errors = []
    while (err := GL.glGetError()) != GL.GL_NO_ERROR:
        errors.append(hex(int(err)))
    return errors


# ----------------------------------------------------------------------------------------------
# Shaders


def test_shaders_compile_and_link(viewer):
    """Every program links and its uniform blocks have the size of their Python std140 mirrors."""
    from warp_sim_render.shader import check_block_size, load_program
    from warp_sim_render.terrain_renderer import terrain_block
    from warp_sim_render.viewer import camera_block, light_block

    programs = [load_program("terrain.vert", "terrain.tesc", "terrain.tese", "terrain.frag"),
                load_program("body.vert", "body.frag"), load_program("debug.vert", "debug.frag")]
    mirrors = {"Camera": camera_block(), "Light": light_block(), "Terrain": terrain_block()}
    for program in programs:
        assert program.id > 0
        assert "Camera" in program.block_sizes
        for name, size in program.block_sizes.items():
            assert size == mirrors[name].nbytes, (program.paths, name)
            check_block_size(program, name, mirrors[name])
        program.delete()
    info = viewer.window.gl_info()
    major, minor = (int(v) for v in info["version"].split()[0].split(".")[:2])
    assert (major, minor) >= (4, 1)
    assert gl_error_free() == []


def test_bad_shader_names_file_and_line(viewer, tmp_path):
    """A compile error is raised as ShaderError naming the file and line, also inside an include."""
    from warp_sim_render.shader import Program, ShaderError

    common = REPO / "shaders" / "common.glsl"
    bad = tmp_path / "bad.frag"
    bad.write_text(f'#version 410 core\n#include "{common}"\nout vec4 color;\nvoid main() {{\n'
                   "    color = vec4(undeclared_value);\n}\n")
    with pytest.raises(ShaderError) as info:
        Program(bad)
    assert f"{bad.resolve()}:5" in str(info.value)
    assert info.value.path == bad.resolve() and info.value.line == 5

    helper = tmp_path / "helper.glsl"
    helper.write_text("float helper() {\n    return missing_name;\n}\n")
    main = tmp_path / "main.frag"
    main.write_text('#version 410 core\n#include "helper.glsl"\nout vec4 color;\nvoid main() { color = vec4(helper()); }\n')
    with pytest.raises(ShaderError) as info:
        Program(main)
    assert info.value.path == helper.resolve() and info.value.line == 2
    assert f"{helper.resolve()}:2" in str(info.value)

    with pytest.raises(ShaderError, match="not found"):
        missing = tmp_path / "missing.frag"
        missing.write_text('#version 410 core\n#include "nope.glsl"\nvoid main() {}\n')
        Program(missing)


# ----------------------------------------------------------------------------------------------
# Tessellated terrain against the physics


@wp.kernel
def sample_terrain(
    terrain_coef: wp.array(dtype=wp.vec2),
    terrain_terms: int,
    terrain_frequency: float,
    terrain_scale: wp.vec3,
    terrain_offset: wp.vec3,
    xz: wp.array(dtype=wp.vec2),
    height_out: wp.array(dtype=float),
    normal_out: wp.array(dtype=wp.vec3),
):
    i = wp.tid()
    s = fourier_sample(terrain_coef, terrain_terms, terrain_frequency, terrain_scale, terrain_offset,
                       xz[i][0], xz[i][1])
    height_out[i] = s.height
    normal_out[i] = fourier_normal(s.grad)


def warp_heights(terrain: FourierTerrain, x, z):
    u = terrain.glsl_uniforms()
    xz = wp.array(np.stack([x, z], 1).astype(np.float32), dtype=wp.vec2, device="cpu")
    h = wp.zeros(len(x), dtype=float, device="cpu")
    n = wp.zeros(len(x), dtype=wp.vec3, device="cpu")
    wp.launch(sample_terrain, dim=len(x), inputs=[
        wp.array(u["terrain_coef"], dtype=wp.vec2, device="cpu"), u["terrain_terms"], u["terrain_frequency"],
        wp.vec3(*u["terrain_scale"]), wp.vec3(*u["terrain_offset"]), xz], outputs=[h, n], device="cpu")
    return h.numpy(), n.numpy()


@pytest.fixture
def capture_terrain(viewer):
    """A small 8 x 8 patch grid with culling off, restoring the viewer's terrain afterwards."""
    from warp_sim_render.terrain_renderer import TerrainRenderer

    renderer = TerrainRenderer(patches_per_side=8, patch_size=4.0)
    renderer.set_culling(False)
    renderer.follow_camera = False
    yield renderer
    renderer.delete()
    viewer.terrain.ubo.bind()


TERRAINS = [
    FourierTerrain(),
    FourierTerrain(terms=8, frequency=0.7, amplitude=3.0, phase=1.2, seed=5, scale=(2.0, 1.5, 0.5),
                   offset=(3.0, -1.0, 2.0)),
    FourierTerrain(terms=16, frequency=0.2, amplitude=0.5, seed=9, offset=(40.0, 2.0, -25.0)),
    FourierTerrain(terms=3, frequency=1.3, amplitude=0.8, phase=-2.0, seed=3, scale=(0.5, 2.0, 0.75)),
]


@pytest.mark.parametrize("terrain", TERRAINS, ids=[f"terrain{i}" for i in range(len(TERRAINS))])
def test_tessellated_heights_match_warp(viewer, capture_terrain, terrain):
    """Heights and normals emitted by terrain.tese equal Warp's fourier_sample at the same (x, z).

    Tolerance: 1e-4 relative to the terrain's height range (sum |A| s.y), since heights cross zero;
    both sides evaluate the same float32 complex-power recurrence.  The float64 NumPy twin agrees
    to float32 rounding of the same order.
    """
    from warp_sim_render.terrain_renderer import TessellationSettings

    capture_terrain.set_grid_origin(terrain.offset[0] - 16.0, terrain.offset[2] - 16.0)
    capture_terrain.set_tessellation(TessellationSettings(0.0, 1.0, 12.0, 12.0))
    capture_terrain.set_terrain(terrain)
    positions, normals = capture_terrain.capture_vertices()
    assert len(positions) >= 64 * 12 * 12 * 2 * 3
    h_warp, n_warp = warp_heights(terrain, positions[:, 0], positions[:, 2])
    bound = terrain.max_height_deviation()
    scale = np.maximum(np.abs(h_warp), bound)
    assert np.max(np.abs(positions[:, 1] - h_warp) / scale) < 1e-4
    assert np.max(np.abs(positions[:, 1] - terrain.height(positions[:, 0], positions[:, 2])) / scale) < 1e-4
    assert np.max(np.abs(normals - n_warp)) < 1e-4
    assert gl_error_free() == []


def test_plane_terrain_uses_the_same_pipeline(viewer, capture_terrain):
    """A tilted PlaneTerrain is drawn by the same shaders with its exact height and normal."""
    plane = PlaneTerrain(normal=(-0.3, 0.9, 0.2), offset=0.5)
    capture_terrain.set_grid_origin(-16.0, -16.0)
    capture_terrain.set_terrain(plane)
    positions, normals = capture_terrain.capture_vertices()
    assert len(positions) > 0
    np.testing.assert_allclose(positions[:, 1], plane.height(positions[:, 0], positions[:, 2]), atol=1e-5)
    np.testing.assert_allclose(normals, np.broadcast_to(plane.normal, normals.shape), atol=1e-6)


def test_patch_edges_match_between_neighbours(viewer, capture_terrain):
    """Outer levels come from edge midpoints: where levels differ between patches, every triangle
    edge on an interior patch boundary still has the identical edge on the other side (no cracks)."""
    from warp_sim_render.terrain_renderer import TessellationSettings

    terrain = FourierTerrain(terms=5, amplitude=1.0)
    capture_terrain.set_grid_origin(-16.0, -16.0)
    capture_terrain.set_terrain(terrain)
    capture_terrain.set_tessellation(TessellationSettings(2.0, 40.0, 1.0, 16.0))
    # The eye sits at a grid corner, so the patches' levels range from 16 down to a few.
    viewer.camera.look_at((-16.0, 2.0, -16.0), (0.0, 0.0, 0.0))
    viewer.upload()
    positions, _ = capture_terrain.capture_vertices()
    triangles = positions.reshape(-1, 3, 3).astype(np.float64)
    per_patch = np.bincount(
        (np.floor((triangles[:, :, 0].mean(1) + 16.0) / 4.0) * 8 + np.floor((triangles[:, :, 2].mean(1) + 16.0) / 4.0))
        .astype(int), minlength=64)
    assert len(set(per_patch.tolist())) > 5, "levels should vary from patch to patch"

    def boundary_edges(axis: int):
        sides = {}
        other = 2 - axis
        for tri in triangles:
            for a, b, c in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
                line = tri[a, axis]
                if tri[b, axis] != line or abs((line + 16.0) / 4.0 - round((line + 16.0) / 4.0)) > 1e-6:
                    continue
                if line in (-16.0, 16.0):
                    continue
                key = (round(line, 4), tuple(sorted((round(tri[a, other], 4), round(tri[b, other], 4)))))
                side = tri[c, axis] > line
                sides.setdefault(key, set()).add(side)
        return sides

    for axis in (0, 2):
        edges = boundary_edges(axis)
        assert len(edges) > 100
        unmatched = [k for k, s in edges.items() if s != {False, True}]
        assert unmatched == [], f"{len(unmatched)} boundary edges without a twin, e.g. {unmatched[:3]}"


# ----------------------------------------------------------------------------------------------
# Pixels


def test_screenshot_shows_terrain_and_bodies(viewer):
    """Bodies are drawn where the camera projects them, in their shape's colour, and the ground
    around them is terrain, not the clear (sky) colour."""
    from warp_sim_render.viewer import SKY

    c = viewer.controller
    c.reset()
    viewer.bodies.color_mode = 0
    viewer.camera.mode = "fly"
    viewer.frame_scene()
    viewer.render()
    image = viewer.read_pixels()
    height, width, _ = image.shape
    assert image.shape == (240, 320, 3)
    positions = c.sim.state.body_pos.numpy()
    shapes = c.sim.model.host["body_shape"]
    pixels = viewer.camera.project(positions, width, height)
    checked = 0
    for (px, py), shape in zip(pixels, shapes):
        if not (0 <= px < width and 0 <= py < height):
            continue
        r, g, b = image[int(py), int(px)].astype(int)
        if shape == 0:
            assert r > g > b and r - b > 60, (px, py, (r, g, b))  # orange sphere
        else:
            assert b > r and b > g, (px, py, (r, g, b))  # blue box
        checked += 1
    assert checked == len(positions)

    # Terrain: ground points around the pile, on screen and clear of every body's pixel.
    centre = positions.mean(axis=0)
    terrain = c.sim.model.terrain
    ground = [(centre[0] + dx, 0.0, centre[2] + dz) for dx in (-5.0, 0.0, 5.0) for dz in (-5.0, 0.0, 5.0)]
    ground = [(x, float(terrain.height(x, z)), z) for x, _, z in ground]
    sky = np.array(SKY) * 255
    seen = 0
    for px, py in viewer.camera.project(ground, width, height):
        if not (0 <= px < width and 0 <= py < height) or np.min(np.hypot(*(pixels - (px, py)).T)) < 25:
            continue
        r, g, b = image[int(py), int(px)].astype(int)
        assert np.abs(np.array([r, g, b]) - sky).max() > 40 and g > b, (px, py, (r, g, b))
        seen += 1
    assert seen >= 3



def test_boxes_stretch_with_raw_matrix_rotation(viewer):
    """Instances are built from body_rot (not the quaternion), so a non-orthonormal matrix shows."""
    c = viewer.controller
    c.reset()
    rot = c.sim.state.body_rot.numpy()
    rot[:] = rot @ np.diag([1.5, 1.0, 1.0]).astype(np.float32)
    c.sim.state.body_rot.assign(rot)
    viewer.upload()
    instances = viewer.bodies.read_instances()
    first_box = viewer.bodies.batches[1].first
    body = int(viewer.bodies.order[first_box])
    size = c.sim.model.host["body_size"][body]
    axis_x = instances[first_box, 0:3]
    np.testing.assert_allclose(np.linalg.norm(axis_x), 1.5 * size[0], rtol=1e-5)
    np.testing.assert_allclose(instances[first_box, [3, 7, 11]], c.sim.state.body_pos.numpy()[body], rtol=1e-6)
    c.reset()


def test_record_writes_a_frame_sequence(viewer, tmp_path):
    """--record: every frame of the loop is written as a numbered PNG of the viewer's size."""
    from PIL import Image

    count = viewer.run(frames=3, record_dir=tmp_path / "frames")
    files = sorted((tmp_path / "frames").glob("frame_*.png"))
    assert count == 3 and [f.name for f in files] == ["frame_00000.png", "frame_00001.png", "frame_00002.png"]
    assert Image.open(files[0]).size == (320, 240)


# ----------------------------------------------------------------------------------------------
# The panel's path


def test_gui_parameter_path_updates_physics_and_terrain_block(viewer):
    """set_param (what the panel calls) changes the simulation; a terrain change reaches the
    Terrain uniform block within the same call; bad values are clamped or refused with a note."""
    from warp_sim_render.terrain_renderer import MAX_TERMS

    c = viewer.controller
    c.reset()
    c.set_param("amplitude", 0.9)
    terrain = c.sim.model.terrain
    assert terrain.amplitude == pytest.approx(0.9)
    np.testing.assert_array_equal(c.sim.model.terrain_coef.numpy(), terrain.complex_coefficients())
    raw = viewer.terrain.ubo.read_back()
    offset = viewer.terrain.block.offsets["terrain_coef"][0]
    gl_coef = raw[offset: offset + MAX_TERMS * MAX_TERMS * 8].view(np.float32).reshape(-1, 2)
    k = terrain.terms
    np.testing.assert_array_equal(gl_coef[: k * k], terrain.complex_coefficients())

    assert c.set_param("terms", 99) == 32 and any("clamped" in n for n in c.recent_notes())
    assert c.set_param("frequency", float("nan")) == c.sim.model.terrain.frequency
    assert c.set_param("integrator", "bogus") == c.sim.config.integrator
    with pytest.raises(ValueError, match="unknown parameter"):
        c.set_param("no_such_thing", 1)
    c.set_param("terms", 5)
    c.set_param("amplitude", 0.5)
    assert c.set_param("face_search", False) is False and c.sim.config.face_search is False
    assert c.set_param("face_search", "yes") is False  # only real booleans are taken
    c.set_param("face_search", True)
    assert c.set_param("still_contacts", False) is False and c.sim.config.still_contacts is False
    c.set_param("still_contacts", True)

    c.set_param("tess_max_level", 20.0)
    assert viewer.terrain.block.get("terrain_tess")[3] == pytest.approx(20.0)
    c.set_param("tess_min_level", 30.0)  # above max: adjusted, not an error
    assert c.view.tess_min_level == c.view.tess_max_level == 20.0
    c.set_param("tess_min_level", 1.0)
    c.set_param("tess_max_level", 12.0)

    c.set_param("restitution", 0.7)  # material: rebuild + reset, the renderer follows the new model
    assert np.allclose(c.sim.model.host["body_restitution"], 0.7) and c.sim.step_count == 0
    assert sum(b.count for b in viewer.bodies.batches) == c.body_count

    # Panel frame with every debug toggle on, after a few steps so contacts exist.
    for name in ("show_checkpoints", "show_contacts", "show_normals", "show_velocities", "show_penetration"):
        c.set_param(name, True)
    c.set_param("color_mode", "speed")
    c.set_param("wireframe", True)
    c.step_forward(120)
    viewer.gui.visible = True
    viewer.frame()
    viewer.gui.visible = False
    assert viewer.contact_count > 0
    for name in ("show_checkpoints", "show_contacts", "show_normals", "show_velocities", "show_penetration",
                 "wireframe"):
        c.set_param(name, False)
    c.set_param("color_mode", "shape")
    c.set_param("restitution", 0.1)
    assert gl_error_free() == []


def test_set_param_changes_the_simulation():
    """Gravity through set_param changes the fall; out-of-range values are clamped with a note."""
    c = DemoController(builtin_scene(), paused=True)
    c.step_forward(5)
    v_default = c.sim.state.body_vel.numpy()[:, 1].copy()
    c.reset()
    assert c.set_param("gravity", (0.0, -19.62, 0.0)) == (0.0, -19.62, 0.0)
    c.step_forward(5)
    v_double = c.sim.state.body_vel.numpy()[:, 1]
    np.testing.assert_allclose(v_double, 2.0 * v_default, rtol=1e-4)  # still in free fall
    assert c.set_param("gravity", (0.0, -500.0, 0.0)) == (0.0, -100.0, 0.0)
    assert c.set_param("substeps", 0) == 1
    assert c.set_param("dt", 5.0) == PARAMS["dt"].hi
    assert len(c.recent_notes()) == 3


def test_gui_values_that_raised_or_were_misread_leave_a_note():
    """The controller never raises on a value: 10**400 overflowed float(), "false" turned the
    switch on (bool("false") is True), seek("a") and a scene with dt = 1e-300 raised."""
    c = DemoController(builtin_scene(), paused=True)
    substeps, auto = c.sim.config.substeps, c.sim.config.auto_substeps
    assert c.set_param("substeps", 10**400) == substeps
    assert c.set_param("gravity", (0.0, -(10**400), 0.0)) == tuple(c.sim.config.gravity)
    assert c.set_param("auto_substeps", "false") == auto
    c.seek("a")
    notes = c.recent_notes()
    assert any("not a finite number" in n for n in notes) and any("not true or false" in n for n in notes)
    assert any("seek" in n for n in notes)


def test_a_scene_with_a_step_too_small_to_run_is_a_note(tmp_path):
    c = DemoController(builtin_scene(), paused=True)
    path = tmp_path / "tiny_dt.toml"
    path.write_text('[sim]\ndt = 1e-300\n[[body]]\nshape = "sphere"\nradius = 0.1\n')
    assert c.load_scene(path) is False
    assert any("dt must be a number in [1e-06, 1]" in n for n in c.recent_notes())


def test_auto_substeps_switch_reaches_the_substep_plan():
    """The Physics panel's auto substeps box: the shipped rain plans more substeps for its
    landings (column_sag.py); off, it runs exactly the substeps asked for."""
    from pathlib import Path

    c = DemoController(builtin_scene(), paused=True)
    assert c.load_scene(Path(__file__).resolve().parents[1] / "examples" / "scenes" / "mixed_rain.toml")
    assert c.sim.substeps > c.sim.config.substeps and c.sim.substep_plan.reason()
    assert c.set_param("auto_substeps", False) is False
    assert c.sim.substeps == c.sim.config.substeps
    assert c.set_param("auto_substeps", True) is True and c.sim.substeps > c.sim.config.substeps


def test_scene_picker_loads_every_example_scene(viewer):
    """Each examples/scenes/*.toml loads through the picker's path and draws a frame."""
    from warp_sim_render.controller import list_scenes

    c = viewer.controller
    scenes = list_scenes()
    if not scenes:
        pytest.skip("no example scenes")
    try:
        for path in scenes:
            assert c.load_scene(path), c.recent_notes()
            c.step_forward(2)
            viewer.frame()
            assert sum(b.count for b in viewer.bodies.batches) == c.body_count
            assert not any("stopped" in n for n in c.recent_notes()), c.recent_notes()
    finally:
        c.load_scene(None)
    assert c.scene.name == "built-in mix"
    assert gl_error_free() == []


# ----------------------------------------------------------------------------------------------
# Time travel


def state_arrays(sim):
    return [a.numpy().copy() for a in sim.state.fields()]


def assert_same_state(a, b):
    for x, y in zip(a, b):
        assert np.array_equal(x, y)


def test_time_travel_is_bit_exact():
    """Forward 200, back 100 (one step at a time), forward 100 reproduces the first run exactly."""
    c = DemoController(builtin_scene(), paused=True, history_interval=16)
    reference = {}
    for step in range(1, 201):
        c.step_forward()
        if step in (100, 150, 200):
            reference[step] = state_arrays(c.sim)
    for _ in range(100):
        c.step_backward()
    assert c.sim.step_count == 100
    assert_same_state(state_arrays(c.sim), reference[100])
    for _ in range(100):
        c.step_forward()
    assert_same_state(state_arrays(c.sim), reference[200])
    c.seek(150)
    assert_same_state(state_arrays(c.sim), reference[150])


def test_parameter_change_in_the_past_forks_the_timeline():
    """A change at a past step drops the future; replays honour the settings in force at each step."""
    c = DemoController(builtin_scene(), paused=True, history_interval=16)
    c.step_forward(60)
    at_40 = None
    c.seek(40)
    at_40 = state_arrays(c.sim)
    c.set_param("gravity", (0.0, -3.0, 0.0))
    assert c.history.head == 40 and max(c.history.keyframes) == 40
    c.step_forward(30)
    forked_70 = state_arrays(c.sim)
    c.seek(10)
    assert c.sim.config.gravity == (0.0, -9.81, 0.0)
    c.seek(40)
    assert_same_state(state_arrays(c.sim), at_40)
    c.seek(70)
    assert c.sim.config.gravity == (0.0, -3.0, 0.0)
    assert_same_state(state_arrays(c.sim), forked_70)


def test_history_respects_memory_budget():
    """Past the budget the keyframe interval doubles and the kept keyframes stay evenly spaced."""
    c = DemoController(builtin_scene(), paused=True, history_interval=4, history_budget_mb=0.05)
    c.step_forward(400)
    h = c.history
    largest = max(sum(a.capacity for a in s["arrays"]) for s in h.keyframes.values())
    assert h.keyframe_bytes() <= 0.05 * (1 << 20) + largest
    assert h.interval > 4
    c.seek(123)
    assert c.sim.step_count == 123


# ----------------------------------------------------------------------------------------------
# Entry point and import hygiene


def test_physics_never_imports_opengl():
    """The physics package, the scene loader and the GL-free viewer modules import no GL."""
    code = ("import sys, warp_sim, warp_sim.demo, render, render.controller, render.history\n"
            "import warp_sim.scene\n"
            "bad = [m for m in ('OpenGL', 'glfw', 'imgui_bundle') if m in sys.modules]\n"
            "assert not bad, bad\n")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=REPO)


def test_demo_screenshot_cli(viewer, tmp_path):
    """python -m warp_sim.demo --screenshot writes a PNG of the requested size from a hidden window."""
    from PIL import Image

    out = tmp_path / "shot.png"
    scene = REPO / "examples" / "scenes" / "balls_on_terrain.toml"
    args = [sys.executable, "-m", "warp_sim.demo", "--screenshot", str(out), "--frames", "3", "--size", "160x120",
            "--samples", "0"]
    if scene.is_file():
        args.insert(3, str(scene))
    result = subprocess.run(args, check=False, cwd=REPO, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    image = np.asarray(Image.open(out))
    assert image.shape == (120, 160, 3)
    assert image.std() > 5  # not a blank frame


def test_demo_replays_a_recorded_run(display, tmp_path):
    """`--replay run.npz` draws the recorded bodies on the recorded terrain (a subprocess: its own
    GL context), and at the run's last frame the picture differs from its first."""
    pytest.importorskip("imgui_bundle", reason="the demo needs imgui-bundle (pip install -e .[viewer])")
    from PIL import Image

    from warp_sim.cli import main as cli_main

    run = tmp_path / "run.npz"
    assert cli_main(["run", str(REPO / "examples" / "scenes" / "bounce.toml"), "--out", str(run),
                     "--duration", "1", "--record-every", "6", "--quiet"]) == 0
    env = {**os.environ, "DISPLAY": display, "PYTHONPATH": str(REPO)}
    images = []
    for frames in (1, 40):  # headless replays advance 1/60 s a frame: 40 frames end past 0.65 s
        out = tmp_path / f"replay_{frames}.png"
        done = subprocess.run([sys.executable, "-m", "warp_sim.demo", "--replay", str(run), "--screenshot", str(out),
                               "--frames", str(frames), "--size", "320x240", "--no-gui"], env=env,
                              capture_output=True, text=True, timeout=300)
        if done.returncode == 1 and "OpenGL" in done.stderr:
            pytest.skip(f"no OpenGL 4.1 core context: {done.stderr.strip()}")
        assert done.returncode == 0, done.stderr
        images.append(np.asarray(Image.open(out).convert("RGB"), dtype=np.float64))
    assert images[0].std() > 10.0
    changed = np.any(np.abs(images[0] - images[1]) > 30, axis=2).mean()
    assert changed > 0.001, "the replay did not move the ball"
