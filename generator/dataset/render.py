"""Render a ``Scene`` with MuJoCo's offscreen renderer: RGB, metric depth, visible (modal)
instance labels for whole mushrooms and caps, and amodal cap masks.

Amodal caps are rendered with only cap geoms visible (others moved to a hidden geom group).
Caps whose projected cap boxes do not overlap in the image share one segmentation pass, so a
scene needs a handful of passes, not one per mushroom.

One ``SceneRenderer`` per process: its OpenGL context is kept, and only the MuJoCo render
context is rebuilt for each new model.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from generator.camera import Intrinsics, camera_intrinsics, project, world_from_camera_cv
from generator.dataset.options import DatasetOptions
from generator.dataset.realism import apply_depth_realism, apply_rgb_realism, randomise_model
from generator.gl import open_renderer
from generator.mjcf import scene_to_spec
from generator.scene import Scene

CAMERA = "overhead"
_HIDDEN_GROUP = 5  # a geom group the default MjvOption does not draw
# Nothing here draws text: the smallest font atlas makes a render context cheaper to create.
_FONT_SCALE = mujoco.mjtFontScale.mjFONTSCALE_50


@dataclass
class Frame:
    """Everything rendered for one scene."""

    rgb: np.ndarray  # (H, W, 3) uint8
    depth: np.ndarray  # (H, W) float32 metres, planar z; 0 = invalid
    labels_mushroom: np.ndarray  # (H, W) uint16, 0 background, instance id + 1
    labels_cap: np.ndarray  # (H, W) uint16, visible cap pixels only
    amodal_caps: dict[int, np.ndarray]  # instance id -> (H, W) bool, cap as if nothing occluded it
    intrinsics: Intrinsics
    world_from_camera: np.ndarray  # (4, 4), OpenCV camera frame
    znear: float
    zfar: float
    realism: dict[str, Any] = field(default_factory=dict)


class SceneRenderer:
    """Reusable offscreen renderer for scenes of one image size. Close it (or use ``with``)."""

    def __init__(self, height: int, width: int) -> None:
        self.height, self.width = height, width
        self._renderer: mujoco.Renderer | None = None

    def __enter__(self) -> SceneRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def _bind(self, model: mujoco.MjModel) -> mujoco.Renderer:
        """A renderer for ``model``: the first call creates it, later ones swap its MuJoCo
        context and keep the OpenGL context (creating one costs ~0.15 s with EGL)."""
        r = self._renderer
        if r is None or not all(hasattr(r, a) for a in ("_mjr_context", "_gl_context", "_scene", "_model")):
            self.close()
            self._renderer = open_renderer(model, self.height, self.width, max_geom=model.ngeom + 64,
                                           font_scale=_FONT_SCALE)
            return self._renderer
        if r._gl_context:
            r._gl_context.make_current()
        r._mjr_context.free()
        r._model = model
        r._scene = mujoco.MjvScene(model=model, maxgeom=model.ngeom + 64)
        r._mjr_context = mujoco.MjrContext(model, _FONT_SCALE.value)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, r._mjr_context)
        r._mjr_context.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        return r

    def render(self, scene: Scene, options: DatasetOptions | None = None,
               rng: np.random.Generator | None = None, *, amodal: bool = True) -> Frame:
        """Render ``scene``; ``rng`` drives the realism options (required if any is on)."""
        options = options or DatasetOptions()
        cam_cfg = scene.config.camera
        if (cam_cfg.height, cam_cfg.width) != (self.height, self.width):
            raise ValueError(f"renderer is {self.width}x{self.height}, scene camera is {cam_cfg.width}x{cam_cfg.height}")
        if options.realism.any and rng is None:
            raise ValueError("realism options need an rng")
        # Static bodies (no free joints or root welds): the same poses, a faster compile.
        spec = scene_to_spec(scene, shadows=options.shadows, free_ids=set())
        spec.visual.map.znear = cam_cfg.znear / 1.0
        spec.visual.map.zfar = cam_cfg.zfar / 1.0
        if not options.shadows:
            spec.visual.quality.shadowsize = 0  # no shadow map: a cheaper render context
        model = spec.compile()
        # znear/zfar in MuJoCo are relative to the model extent; make them the configured metres.
        model.vis.map.znear = cam_cfg.znear / model.stat.extent
        model.vis.map.zfar = cam_cfg.zfar / model.stat.extent
        realism = randomise_model(model, options.realism, rng) if rng is not None else {}
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        cam = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, CAMERA)
        pose = world_from_camera_cv(data.cam_xpos[cam].copy(), data.cam_xmat[cam].reshape(3, 3).copy())
        intr = camera_intrinsics(cam_cfg)

        # geom id -> instance id, and which geoms are caps
        geom_instance = np.full(model.ngeom + 1, -1, dtype=np.int64)  # last entry: background (-1)
        cap_geom = np.zeros(model.ngeom + 1, dtype=bool)
        cap_ids: dict[int, int] = {}
        for inst in scene.instances:
            for part in ("cap", "stem"):
                g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"mushroom_{inst.id}_{part}")
                geom_instance[g] = inst.id
                cap_geom[g] = part == "cap"
                if part == "cap":
                    cap_ids[inst.id] = g

        r = self._bind(model)
        r.update_scene(data, CAMERA)
        rgb = r.render()
        object_id, geom, depth = self._render_ids_and_depth(r)
        inst_of_pixel = geom_instance[geom]  # -1 indexes the background entry
        labels_mushroom = (inst_of_pixel + 1).astype(np.uint16)
        labels_cap = np.where(cap_geom[geom], labels_mushroom, 0).astype(np.uint16)

        far = cam_cfg.zfar
        depth = np.where((object_id >= 0) & (depth < far * 0.999) & (depth > 0), depth, 0.0).astype(np.float32)
        # Depth draws before RGB draws (docs in generator/dataset/realism.py); an effect that is
        # off draws nothing, so older datasets reproduce.
        if options.realism.depth_any:
            depth, drawn = apply_depth_realism(depth, intr.fx, cam_cfg.preset, options.realism, rng)
            realism.update(drawn)
        if options.realism.rgb_any:
            rgb, drawn = apply_rgb_realism(rgb, options.realism, rng)
            realism.update(drawn)

        amodal_caps = self._render_amodal(r, model, data, scene, cap_ids, pose, intr) if amodal else {}
        return Frame(rgb, depth, labels_mushroom, labels_cap, amodal_caps, intr, pose,
                     cam_cfg.znear, cam_cfg.zfar, realism)

    def _render_ids_and_depth(self, r: mujoco.Renderer) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One segmentation render read back with its depth buffer (``mujoco.Renderer`` renders
        depth and segmentation separately, with the same flags, so this saves a pass).

        Returns per pixel the object id (-1 background), the geom id (-1 where no geom) and the
        metric depth as ``mujoco.Renderer`` computes it (float32 metres, 0 beyond the far plane)."""
        h, w = self.height, self.width
        ctx, scene, model = r._mjr_context, r.scene, r.model
        codes = np.empty((h, w, 3), dtype=np.uint8)
        zbuf = np.empty((h, w), dtype=np.float32)
        flags = scene.flags.copy()
        try:
            scene.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = True
            scene.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = True
            if r._gl_context:
                r._gl_context.make_current()
            rect = mujoco.MjrRect(0, 0, w, h)
            mujoco.mjr_render(rect, scene, ctx)
            mujoco.mjr_readPixels(codes, zbuf, rect, ctx)
        finally:
            np.copyto(scene.flags, flags)
        # OpenGL rows run bottom to top. A pixel's colour encodes its mjvGeom's segid + 1.
        codes, zbuf = codes[::-1], zbuf[::-1]
        code = codes[..., 0].astype(np.int64) | (codes[..., 1].astype(np.int64) << 8) | (codes[..., 2].astype(np.int64) << 16)
        geoms = scene.geoms[:scene.ngeom]
        object_of_code = np.full(scene.ngeom + 1, -1, dtype=np.int64)
        geom_of_code = np.full(scene.ngeom + 1, -1, dtype=np.int64)
        for g in geoms:
            if g.segid != -1:
                object_of_code[g.segid + 1] = g.objid
                if g.objtype == int(mujoco.mjtObj.mjOBJ_GEOM):
                    geom_of_code[g.segid + 1] = g.objid
        # Reversed-Z perspective depth to metres, in the float32 / float64 steps of
        # ``mujoco.Renderer`` so the values are bit for bit the same.
        near = np.float32(model.vis.map.znear * model.stat.extent)
        far = np.float32(model.vis.map.zfar * model.stat.extent)
        offset = np.float32(-0.5) * (-(far + near) / (far - near)) - np.float32(0.5)
        scale = np.float32(-0.5) * (-(np.float32(2) * far * near) / (far - near))
        depth = (scale / (zbuf.astype(np.float64) + offset)).astype(np.float32)
        return object_of_code[code], geom_of_code[code], depth

    def _render_amodal(self, r: mujoco.Renderer, model: mujoco.MjModel, data: mujoco.MjData, scene: Scene,
                       cap_ids: dict[int, int], pose: np.ndarray, intr: Intrinsics) -> dict[int, np.ndarray]:
        h, w = self.height, self.width
        rects: dict[int, tuple[int, int, int, int]] = {}
        for inst in scene.instances:
            uvz = project(inst.cap_obb.corners, pose, intr)
            if np.any(uvz[:, 2] <= 0):
                rects[inst.id] = (0, 0, w, h)
                continue
            u0, v0 = np.floor(uvz[:, :2].min(0)).astype(int) - 2
            u1, v1 = np.ceil(uvz[:, :2].max(0)).astype(int) + 3
            u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, w), min(v1, h)
            if u0 < u1 and v0 < v1:
                rects[inst.id] = (u0, v0, u1, v1)
        # Greedy colouring: caps in one group have disjoint image rectangles.
        groups: list[list[int]] = []
        group_rects: list[list[tuple[int, int, int, int]]] = []
        for iid, (u0, v0, u1, v1) in rects.items():
            for g, members in enumerate(group_rects):
                if all(u1 <= a0 or a1 <= u0 or v1 <= b0 or b1 <= v0 for a0, b0, a1, b1 in members):
                    groups[g].append(iid)
                    members.append((u0, v0, u1, v1))
                    break
            else:
                groups.append([iid])
                group_rects.append([(u0, v0, u1, v1)])
        saved = model.geom_group.copy()
        masks: dict[int, np.ndarray] = {}
        ctx, mjv_scene = r._mjr_context, r.scene
        full = mujoco.MjrRect(0, 0, w, h)
        try:
            for members in groups:
                model.geom_group[:] = _HIDDEN_GROUP
                model.geom_group[[cap_ids[i] for i in members]] = 0
                r.update_scene(data, CAMERA)
                mjv_scene.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = True
                mjv_scene.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = True
                segid = {g.objid: g.segid + 1 for g in mjv_scene.geoms[:mjv_scene.ngeom]
                         if g.objtype == int(mujoco.mjtObj.mjOBJ_GEOM)}
                if r._gl_context:
                    r._gl_context.make_current()
                mujoco.mjr_render(full, mjv_scene, ctx)
                # Read back each cap's rectangle only: resolving and reading the whole
                # multisampled frame costs more than drawing a few caps. Rows of OpenGL images
                # run bottom to top.
                for iid in members:
                    u0, v0, u1, v1 = rects[iid]
                    buf = np.empty((v1 - v0, u1 - u0, 3), dtype=np.uint8)
                    mujoco.mjr_readPixels(buf, None, mujoco.MjrRect(u0, h - v1, u1 - u0, v1 - v0), ctx)
                    code = buf[::-1].astype(np.int32)
                    code = code[..., 0] + (code[..., 1] << 8) + (code[..., 2] << 16)
                    crop = code == segid[cap_ids[iid]]
                    if crop.any():
                        m = np.zeros((h, w), dtype=bool)
                        m[v0:v1, u0:u1] = crop
                        masks[iid] = m
        finally:
            model.geom_group[:] = saved
            mjv_scene.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = False
            mjv_scene.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = False
        return dict(sorted(masks.items()))
