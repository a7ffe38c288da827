"""Find the viewer package, ``warp_sim_render``, in an installed or a source layout.

An install (wheel, ``pip install .`` or ``pip install -e .``) maps the repository's ``render/``
folder to the import name ``warp_sim_render`` (pyproject.toml), so the project claims no generic
top-level name such as ``render``.  A bare checkout on ``PYTHONPATH`` has no such mapping; there
``ensure_render_package`` registers ``<checkout>/render`` under the same name, so every caller
imports ``warp_sim_render.*`` whichever way the code got onto the path.  Importing this module
imports no OpenGL.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path

NAME = "warp_sim_render"


def source_render_dir() -> Path | None:
    """The checkout's ``render/`` folder, or None when this package is installed."""
    root = Path(__file__).resolve().parent.parent
    # pyproject.toml marks a checkout: site-packages may hold an unrelated "render" package
    if (root / "pyproject.toml").is_file() and (root / "render" / "__init__.py").is_file():
        return root / "render"
    return None


def ensure_render_package():
    """Import and return ``warp_sim_render`` (registering the checkout's ``render/`` if needed)."""
    if NAME in sys.modules:
        return sys.modules[NAME]
    # A checkout's own render/ wins over an installed copy of another version: this package
    # and its viewer must come from the same place.
    folder = source_render_dir()
    if folder is not None:
        init = folder / "__init__.py"
        spec = importlib.util.spec_from_file_location(NAME, init, submodule_search_locations=[str(init.parent)])
        module = importlib.util.module_from_spec(spec)
        sys.modules[NAME] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[NAME]
            raise
        return module
    return importlib.import_module(NAME)
