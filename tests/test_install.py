"""The built wheel, installed into a fresh virtual environment, runs the demo.

An editable install or a checkout on PYTHONPATH finds shaders/ and render/ next to the package,
which hides packaging mistakes (data files left out of the wheel, a subpackage missing from the
package list).  This test builds the wheel from a copy of the checkout, installs it into a new
venv that sees this interpreter's site-packages (so warp, numpy and the viewer libraries are not
downloaded again), and from a temporary folder (so the checkout cannot be imported) takes a
screenshot with ``python -m warp_sim.demo`` under Xvfb.  No display, no Xvfb or no OpenGL 4.1
context: the screenshot part skips with the reason, the wheel checks still run.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent
# Outputs and caches of a checkout that must not leak into the wheel build
IGNORED = shutil.ignore_patterns(".git", "build", "dist", "*.egg-info", "__pycache__", ".pytest_cache",
                                 "*.npz", "results", "docs")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    pytest.importorskip("setuptools", reason="building the wheel needs setuptools in this interpreter")
    src = tmp_path_factory.mktemp("src") / "warp_sim"
    shutil.copytree(REPO, src, ignore=IGNORED)
    out = tmp_path_factory.mktemp("wheel")
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                           "-w", str(out), str(src)], capture_output=True, text=True, timeout=120, env=clean_env())
    if proc.returncode != 0 and "bdist_wheel" in proc.stdout + proc.stderr:
        pytest.skip("this setuptools needs the 'wheel' package to build wheels (pip install wheel)")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    (whl,) = out.glob("warp_sim-*.whl")
    return whl


@pytest.fixture(scope="module")
def venv_python(wheel, tmp_path_factory) -> Path:
    env_dir = tmp_path_factory.mktemp("venv")
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(env_dir)], check=True, timeout=120)
    python = env_dir / "bin" / "python"
    # --force-reinstall: an editable warp-sim of the same version outside the venv would
    # otherwise count as already installed
    proc = subprocess.run([str(python), "-m", "pip", "install", "-q", "--no-deps", "--force-reinstall", str(wheel)],
                          capture_output=True, text=True, timeout=120, env=clean_env())
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return python


def clean_env(**extra) -> dict:
    """This environment without PYTHONPATH: the venv's installed copy is what gets imported."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update(extra)
    return env


def test_wheel_contents(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"warp_sim", "warp_sim_render"}, f"the wheel claims top-level names {sorted(tops)}"
    for shader in sorted((REPO / "shaders").iterdir()):
        assert f"warp_sim_render/shaders/{shader.name}" in names, f"{shader.name} is not in the wheel"
    for scene in sorted((REPO / "examples" / "scenes").glob("*.toml")):
        assert f"warp_sim_render/scenes/{scene.name}" in names, f"{scene.name} is not in the wheel"
    # every subpackage of the checkout is listed in pyproject.toml's package list
    for init in sorted((REPO / "warp_sim").rglob("__init__.py")):
        rel = init.relative_to(REPO).as_posix()
        assert rel in names, f"{rel} is not in the wheel: add its package to [tool.setuptools] packages"


def test_installed_copy_is_imported(venv_python, tmp_path):
    code = "import warp_sim, warp_sim_render, warp_sim_render.controller as c; " \
           "print(warp_sim.__file__); print(warp_sim_render.__file__); print(c.SCENE_DIR)"
    proc = subprocess.run([str(venv_python), "-c", code], cwd=tmp_path, capture_output=True, text=True,
                          env=clean_env(), timeout=60)
    assert proc.returncode == 0, proc.stderr
    prefix = str(venv_python.parent.parent)
    paths = proc.stdout.split()
    assert all(p.startswith(prefix) for p in paths), f"imported from outside the venv: {paths}"
    assert (Path(paths[2]) / "mixed_rain.toml").is_file()


def start_xvfb():
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        pytest.skip("no display and no Xvfb for an OpenGL context (apt-get install xvfb)")
    read_fd, write_fd = os.pipe()
    proc = subprocess.Popen([xvfb, "-displayfd", str(write_fd), "-screen", "0", "1280x720x24", "-nolisten", "tcp"],
                            pass_fds=(write_fd,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(write_fd)
    with os.fdopen(read_fd) as pipe:
        number = pipe.readline().strip()
    if not number:
        proc.kill()
        proc.wait()
        pytest.skip("Xvfb did not start, so there is no display for an OpenGL context")
    return proc, f":{number}"


def test_installed_demo_takes_a_screenshot(venv_python, tmp_path):
    pytest.importorskip("glfw", reason="the demo needs pyGLFW (pip install .[viewer])")
    pytest.importorskip("OpenGL", reason="the demo needs PyOpenGL (pip install .[viewer])")
    pytest.importorskip("imgui_bundle", reason="the demo needs imgui-bundle (pip install .[viewer])")
    Image = pytest.importorskip("PIL.Image", reason="reading the PNG needs Pillow")
    xvfb, display = None, os.environ.get("DISPLAY")
    if not display:
        xvfb, display = start_xvfb()
    try:
        proc = subprocess.run([str(venv_python), "-m", "warp_sim.demo", "--screenshot", "out.png", "--frames", "2",
                               "--size", "640x360"], cwd=tmp_path, capture_output=True, text=True,
                              env=clean_env(DISPLAY=display), timeout=180)
    finally:
        if xvfb is not None:
            xvfb.terminate()
            xvfb.wait(timeout=10)
    if proc.returncode == 1 and any(w in proc.stderr for w in ("OpenGL", "GLFW", "framebuffer")):
        pytest.skip(f"no OpenGL 4.1 core context: {proc.stderr.strip().splitlines()[-1]}")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "ShaderError" not in proc.stderr
    image = np.asarray(Image.open(tmp_path / "out.png").convert("RGB"), dtype=np.float64)
    assert image.shape == (360, 640, 3)
    # terrain, sky, bodies and panel: many colours and real contrast, not a cleared framebuffer
    colours = np.unique(image.reshape(-1, 3), axis=0)
    assert len(colours) > 500, f"only {len(colours)} colours in the screenshot"
    assert image.std(axis=(0, 1)).min() > 10.0
