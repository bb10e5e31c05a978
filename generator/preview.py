"""Pictures of a scene for people: the overhead camera's view and an oblique view, each under its
title, below the scene's own (mushrooms placed, seed)."""

from __future__ import annotations

import mujoco
import numpy as np

from generator.config import require_image_side  # noqa: E402
from generator.files import save_rgb_png  # noqa: E402
from generator.gl import open_renderer
from generator.image_text import with_title  # noqa: E402
from generator.mjcf import scene_to_model  # noqa: E402
from generator.scene import Scene  # noqa: E402


def render_views(scene: Scene, width: int = 640, height: int = 480) -> np.ndarray:
    """The overhead camera's RGB image beside an oblique view, each under a title bar, below the
    scene's title, as one (H + bars, 2W, 3) uint8 image."""
    require_image_side("width", width)
    require_image_side("height", height)
    model = scene_to_model(scene, shadows=True)
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    oblique = mujoco.MjvCamera()
    oblique.lookat[:] = [0.0, 0.0, float(np.median(scene.terrain.heights))]
    oblique.distance, oblique.azimuth, oblique.elevation = 0.55, 60.0, -35.0
    with open_renderer(model, height, width) as renderer:
        renderer.update_scene(data, camera="overhead")
        top = renderer.render()
        renderer.update_scene(data, camera=oblique)
        side = renderer.render()
    cam = scene.config.camera
    panels = np.concatenate([
        with_title(top, f"overhead camera ({cam.preset.upper()}-like, {cam.height_above_soil:g} m above the soil)"),
        with_title(side, f"oblique view ({oblique.distance:g} m away, {-oblique.elevation:g} deg down)")], axis=1)
    return with_title(panels, f"Generated bed: {len(scene.instances)} mushrooms "
                              f"(species: {scene.config.placement.species}), seed {scene.seed}", scale=0.9)


def save_preview(scene: Scene, path: str, width: int = 640, height: int = 480) -> None:
    """Write ``render_views`` as a PNG."""
    save_rgb_png(path, render_views(scene, width, height))
