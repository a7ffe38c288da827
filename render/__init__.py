"""Interactive OpenGL 4.1 viewer for warp_sim (GLFW, PyOpenGL, imgui-bundle).

Importing this package imports no OpenGL: ``controller`` and ``history`` are GL-free, and the
GL modules (``window``, ``shader``, ``terrain_renderer``, ``body_renderer``, ``debug_draw``,
``gui``, ``viewer``) are imported only by whoever draws.  The GLSL sources are in ``shaders/``.
"""
