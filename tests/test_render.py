"""Pictures: knot diagrams tell the P-data truth; render writes non-empty PNG and GIF files."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest
from PIL import Image

from twisted.render import (
    RenderError,
    crossing_geometry,
    draw_knot_diagram,
    gl_top_views,
    p_data_of_drawing,
    render_configuration,
    render_goal,
    render_run,
    save_gif,
)
from twisted.store import open_store
from twisted.store.queries import add_configuration, start_run
from twisted.topology import parse_p_data, top

ONE = parse_p_data([[1, "O", 2, "+"], [2, "U", 1, "+"]])
TREFOIL_LIKE = parse_p_data(
    [
        [1, "O", 4, "-"],
        [2, "O", 5, "+"],
        [3, "U", 6, "+"],
        [4, "U", 1, "-"],
        [5, "U", 2, "+"],
        [6, "O", 3, "+"],
    ]
)
PNG = b"\x89PNG\r\n\x1a\n"


def _random_rope(rng: np.random.Generator) -> np.ndarray:
    angles = np.cumsum(rng.normal(0.0, 0.8, 21))
    pts = np.zeros((22, 3))
    pts[1:, 0] = np.cumsum(0.04 * np.cos(angles))
    pts[1:, 1] = np.cumsum(0.04 * np.sin(angles))
    pts[:, 2] = rng.uniform(0.0, 0.02, 22)
    return pts


def test_drawn_crossings_carry_the_p_data_numbers() -> None:
    rng = np.random.default_rng(0)
    crossings_seen = 0
    for _ in range(300):
        pts = _random_rope(rng)
        drawing = crossing_geometry(pts)
        assert p_data_of_drawing(drawing) == top(pts)
        crossings_seen += len(drawing)
    assert crossings_seen > 100  # the ropes were curly enough to test something


def test_knot_diagram_breaks_the_under_strand() -> None:
    rng = np.random.default_rng(1)
    pts = _random_rope(rng)
    while top(pts).cross < 2:
        pts = _random_rope(rng)
    fig, ax = plt.subplots()
    drawn = draw_knot_diagram(ax, pts)
    pieces = [line for line in ax.get_lines() if line.get_linewidth() == 4]
    assert len(drawn) == top(pts).cross
    assert len(pieces) == len(drawn) + 1  # one gap per crossing, in the under strand
    plt.close(fig)


def _label_boxes(fig: plt.Figure, ax: plt.Axes) -> list[tuple[float, float, float, float]]:
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    return [tuple(t.get_window_extent(renderer).extents) for t in ax.texts if t.get_text()[-1] in "+-"]


def test_visit_labels_do_not_cover_each_other_or_leave_the_panel() -> None:
    rng = np.random.default_rng(3)
    drawn = 0
    while drawn < 8:
        pts = _random_rope(rng)
        if not 2 <= top(pts).cross <= 5:
            continue
        for zoom in (False, True):
            fig, ax = plt.subplots(figsize=(5, 4))
            draw_knot_diagram(ax, pts, zoom=zoom)
            boxes = _label_boxes(fig, ax)
            assert len(boxes) == 2 * top(pts).cross
            x0, y0, x1, y1 = ax.bbox.extents
            for i, (a0, b0, a1, b1) in enumerate(boxes):
                assert x0 <= a0 and a1 <= x1 and y0 <= b0 and b1 <= y1, "a label outside its panel"
                for c0, d0, c1, d1 in boxes[i + 1 :]:
                    assert min(a1, c1) <= max(a0, c0) or min(b1, d1) <= max(b0, d0), "two labels overlap"
            plt.close(fig)
        drawn += 1


def test_goal_without_a_stored_rope_is_a_gauss_diagram(tmp_path: Path) -> None:
    out = render_goal(None, TREFOIL_LIKE, tmp_path / "goal.png")
    assert out.backend == "gauss"
    data = out.files[0].read_bytes()
    assert data[:8] == PNG and len(data) > 5000


def test_configuration_and_goal_from_the_store(sqlite_url: str, tmp_path: Path) -> None:
    from twisted.sim import Curve, RopeSim

    sim = RopeSim()
    curve = Curve(0, 0.05, 0.35, 0.3)
    for _ in range(20):  # find a curve that crosses the rope once (deterministic search)
        sim.reset()
        if sim.apply(curve).ok and sim.p_data().cross >= 1:
            break
        curve = Curve(curve.link, curve.z_max_m, curve.x_m + 0.05, curve.y_m - 0.03)
    p = sim.p_data()
    assert p.cross >= 1
    with open_store(sqlite_url) as store:
        with store.session(write=True) as session:
            run_id = start_run(session, "collect", {}).id
            config_id = add_configuration(
                session, run_id=run_id, p_data=p, q=sim.state(), points=sim.link_points()
            ).id
        out = render_configuration(store, config_id, tmp_path / "c.png", gl=False)
        assert out.backend.startswith("matplotlib") and out.files[0].read_bytes()[:8] == PNG
        goal = render_goal(store, p, tmp_path / "g.png")
        assert goal.backend == "knot" and goal.files[0].stat().st_size > 5000
        with pytest.raises(RenderError, match="configuration 999"):
            render_configuration(store, 999, tmp_path / "x.png", gl=False)


def test_run_renders_png_and_gif(sqlite_url: str, tmp_path: Path) -> None:
    from twisted.planner import PlannerOptions, start_search
    from twisted.sim import SimPool

    with open_store(sqlite_url) as store:
        with SimPool(1) as pool:
            search = start_search(store, ONE, PlannerOptions(planner="random-low", seed=0), pool)
            result = search.run(max_iterations=400)
        # any seed: about 3 % of random curves make this one crossing, and 400 iterations draw 1,200 curves
        assert result.solved
        out = render_run(store, result.run_id, tmp_path / "run.png", tmp_path / "run.gif", gl=False)
        png, gif = out.files
        assert png.read_bytes()[:8] == PNG and png.stat().st_size > 5000
        with Image.open(gif) as im:
            assert im.format == "GIF" and im.n_frames == len(
                result.path
            )  # the start, then one frame per curve
        with pytest.raises(RenderError, match="not a planner run"):
            render_run(store, 12345, tmp_path / "none.png")


def test_save_gif_pads_frames(tmp_path: Path) -> None:
    frames = [np.full((10, 12, 3), 40, np.uint8), np.full((14, 9, 3), 200, np.uint8)]
    path = save_gif(frames, tmp_path / "a.gif", frame_s=0.1)
    with Image.open(path) as im:
        assert im.n_frames == 2 and im.size == (12, 14)


@pytest.mark.slow
def test_mujoco_offscreen_top_view_when_opengl_works() -> None:
    from twisted.sim import Curve, RopeSim

    sim = RopeSim()
    straight = sim.state()
    sim.apply(Curve(0, 0.04, 0.2, 0.25))
    images, backend = gl_top_views([straight, sim.state()], width=160, height=120)
    if images is None:
        pytest.skip(f"no offscreen OpenGL here: {backend}")
    assert backend in ("egl", "osmesa")
    assert [im.shape for im in images] == [(120, 160, 3)] * 2
    assert images[0].std() > 5  # a rope on a table, not a blank frame
    assert np.abs(images[0].astype(int) - images[1].astype(int)).mean() > 0.5  # the rope moved
