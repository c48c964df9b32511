"""Pictures of the rope: a top view (MuJoCo offscreen), knot diagrams, Gauss diagrams, plan replays.

Researchers look before they read. Three kinds of picture:

- **Knot diagram** of a rope given by its N_POINTS centreline points (22 on the default rope): the
  projection to the table as a line, broken where it passes *under* another strand, every crossing visit
  numbered as in P-data (``3O+`` = visit 3, over, positive crossing). Drawn from the same segment
  intersection test as :func:`twisted.topology.top`, so the numbers on the picture are the numbers in the
  state.
- **Gauss diagram** of a P-data state without a configuration (an unseen goal): the rope as a
  straight line from head to tail, visits 1..2n along it, one chord per crossing drawn as an
  arrow from its over visit to its under visit, coloured by sign. It is the exact content of the
  P-data; an actual planar layout of an arbitrary state is not computed here.
- **Top view** rendered by MuJoCo (EGL or OSMesa). OpenGL is chosen when ``mujoco`` is imported,
  and in a headless shell the default (GLFW) fails, so the offscreen rendering runs in a child
  interpreter started with ``MUJOCO_GL`` set (``egl`` first, then ``osmesa``). When neither works
  the knot diagram of the link points is the picture (the fallback).

The parts: :mod:`~twisted.render.geometry` (crossings, strand pieces and labels of a knot picture, no
plotting library), :mod:`~twisted.render.draw` (matplotlib drawings and PNG/GIF files),
:mod:`~twisted.render.gl` (the MuJoCo child) and :mod:`~twisted.render.stored` (pictures of what the
database holds: the only part that reads it). Everything is importable from ``twisted.render``.
"""

from twisted.render.draw import draw_gauss_diagram, draw_knot_diagram, figure_to_array, save_gif, save_png
from twisted.render.geometry import (
    ROPE_COLOUR,
    SIGN_COLOUR,
    CrossingDrawing,
    crossing_geometry,
    knot_zoom,
    p_data_of_drawing,
    rope_pieces,
    visit_labels,
)
from twisted.render.gl import GL_BACKENDS, gl_top_views
from twisted.render.stored import (
    Rendered,
    RenderError,
    find_drawing,
    render_configuration,
    render_goal,
    render_run,
    render_tightened,
)

__all__ = [
    "GL_BACKENDS",
    "ROPE_COLOUR",
    "SIGN_COLOUR",
    "CrossingDrawing",
    "RenderError",
    "Rendered",
    "crossing_geometry",
    "draw_gauss_diagram",
    "draw_knot_diagram",
    "figure_to_array",
    "find_drawing",
    "gl_top_views",
    "knot_zoom",
    "p_data_of_drawing",
    "render_configuration",
    "render_goal",
    "render_run",
    "render_tightened",
    "rope_pieces",
    "save_gif",
    "save_png",
    "visit_labels",
]
