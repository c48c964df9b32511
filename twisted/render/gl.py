"""The rope seen from above, rendered by MuJoCo offscreen (EGL or OSMesa) in a child interpreter.

OpenGL is chosen when ``mujoco`` is imported, and in a headless shell the default (GLFW) fails, so
:func:`gl_top_views` starts ``python -m twisted.render`` (:mod:`twisted.render.__main__`) with
``MUJOCO_GL`` set, ``egl`` first, then ``osmesa``; when neither works the caller draws the link points.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["GL_BACKENDS", "gl_top_views"]

GL_BACKENDS = ("egl", "osmesa")


def gl_top_views(
    states: Sequence[npt.NDArray[np.float64]],
    *,
    friction_scale: float = 1.0,
    width: int = 640,
    height: int = 480,
    backends: Sequence[str] | None = None,
    timeout_s: float = 300.0,
) -> tuple[list[npt.NDArray[np.uint8]] | None, str]:
    """Render rope states (``RopeSim.state()`` vectors) from above with MuJoCo offscreen OpenGL.

    Returns ``(images, backend)``; ``images`` is None when no backend works, and then ``backend``
    says why (the caller draws the link points instead). Tried in order: ``MUJOCO_GL`` if set,
    then EGL, then OSMesa, each in a child interpreter so the choice does not depend on whether
    this process already imported MuJoCo.
    """
    if backends is None:
        env_gl = os.environ.get("MUJOCO_GL", "").lower().strip()
        backends = (
            [env_gl] + [b for b in GL_BACKENDS if b != env_gl] if env_gl in GL_BACKENDS else list(GL_BACKENDS)
        )
    errors = []
    with tempfile.TemporaryDirectory(prefix="twisted-render-") as tmp:
        src = Path(tmp) / "states.npz"
        np.savez(src, states=np.stack([np.asarray(s, dtype=np.float64) for s in states]))
        for backend in backends:
            dst = Path(tmp) / f"images-{backend}.npz"
            env = dict(os.environ, MUJOCO_GL=backend)
            env.pop("PYOPENGL_PLATFORM", None)  # let mujoco's egl/osmesa module pick the matching one
            cmd = [
                sys.executable,
                "-m",
                "twisted.render",  # twisted/render/__main__.py: _gl_worker
                str(src),
                str(dst),
                str(friction_scale),
                str(width),
                str(height),
            ]
            try:
                proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout_s)
            except subprocess.TimeoutExpired:
                errors.append(f"{backend}: timed out")
                continue
            if proc.returncode == 0 and dst.exists():
                with np.load(dst) as data:
                    return list(data["images"]), backend
            tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
            errors.append(f"{backend}: {tail}")
    return None, "; ".join(errors)


def _top_camera(points: npt.NDArray[np.float64], aspect: float) -> Any:
    import mujoco

    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre = (lo + hi) / 2
    cam.lookat[:] = [centre[0], centre[1], 0.0]
    half = max((hi[0] - lo[0]) / 2 / aspect, (hi[1] - lo[1]) / 2, 0.15) + 0.08
    cam.distance = half / np.tan(np.radians(45.0 / 2))  # MuJoCo's default vertical field of view is 45 deg
    cam.elevation = -90.0
    cam.azimuth = 90.0  # +x to the right, +y up in the image
    return cam


def _gl_worker(src: str, dst: str, friction_scale: float, width: int, height: int) -> None:
    """Child-process side of :func:`gl_top_views` (``MUJOCO_GL`` is already set here)."""
    import mujoco

    from twisted.sim import RopeSim

    sim = RopeSim(friction_scale=friction_scale)
    model, data = sim.model, sim.data
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    images = []
    with np.load(src) as f:
        states = f["states"]
    # one camera for every frame (a replay must not jump), framing all the states
    all_points = []
    for state in states:
        sim.set_state(state)
        all_points.append(sim.link_points())
    cam = _top_camera(np.concatenate(all_points), width / height)
    with mujoco.Renderer(model, height=height, width=width) as renderer:
        for state in states:
            sim.set_state(state)
            renderer.update_scene(data, camera=cam)
            images.append(renderer.render().copy())
    np.savez(dst, images=np.stack(images))
