"""Export a ``Scene`` as a MuJoCo model: heightfield soil, mushroom bodies, lights, RGB-D camera.

Names in the model (the environment and the dataset writer rely on them):
``terrain`` (hfield geom), ``overhead`` (camera), and per mushroom ``i``: body ``mushroom_i``
with free joint ``mushroom_i_joint``, geoms ``mushroom_i_cap`` / ``mushroom_i_stem``, site
``mushroom_i_cap_top`` and weld equality ``mushroom_i_root`` that holds it to the soil.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import cv2
import mujoco
import numpy as np

from generator.camera import camera_intrinsics, camera_rotation_mujoco
from generator.config import Species
from generator.files import write_atomic
from generator.mushroom_models import COLOURS, model_library
from generator.scene import Scene

SOIL_TEXTURE = "soil.png"
TERRAIN_THICKNESS = 0.05  # m of heightfield below its lowest point
ROOT_SOLREF = [0.004, 1.0]  # 2 x the timestep
ROOT_SOLIMP = [0.99, 0.999, 0.001, 0.5, 2.0]


def soil_texture(seed: int, size: int = 256) -> np.ndarray:
    """A seeded peat-casing texture (RGB uint8): brown noise at several scales with light grit."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 7]))
    img = np.zeros((size, size), dtype=np.float32)
    for cells, weight in ((8, 0.5), (32, 0.3), (128, 0.2)):
        small = rng.random((cells, cells)).astype(np.float32)
        img += weight * cv2.resize(small, (size, size), interpolation=cv2.INTER_CUBIC)
    base = np.array([0.30, 0.22, 0.16]) * rng.uniform(0.8, 1.2)
    rgb = np.clip(base[None, None, :] * (0.55 + 0.9 * img[..., None]), 0, 1)
    grit = rng.random((size, size)) > 0.985
    rgb[grit] = np.array([0.75, 0.72, 0.66])
    return (rgb * 255).astype(np.uint8)


@cache
def _parts(species: Species, model_id: int) -> tuple[tuple[str, list[float], list[int], float, float], ...]:
    """Cap and stem of a library model: name, flat vertex and face lists, part and total volume.
    Cached: converting the meshes again for every instance dominated building a spec."""
    model = model_library(species)[model_id]
    meshes = {"cap": model.cap_mesh, "stem": model.stem_mesh}
    total = sum(mesh.volume for mesh in meshes.values())
    return tuple((part, np.asarray(mesh.vertices).ravel().tolist(), np.asarray(mesh.faces).ravel().tolist(),
                  mesh.volume, total) for part, mesh in meshes.items())


def _quat(rotation: np.ndarray) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(rotation, dtype=float).ravel())
    return q


def scene_to_spec(scene: Scene, *, mushroom_collisions: bool = False, shadows: bool = False,
                  free_ids: set[int] | None = None) -> mujoco.MjSpec:
    """Build the scene's ``MjSpec``. Mushroom geoms collide only if ``mushroom_collisions``
    (welded mushrooms need no contacts; the environment switches them on where it needs them).
    ``free_ids``: if given, only these mushrooms get a free joint and a root weld; the others are
    static bodies fixed to the world (no degrees of freedom: a much faster simulation)."""
    spec = mujoco.MjSpec()
    spec.modelname = f"sms3d_scene_{scene.seed}"
    spec.option.timestep = 0.002
    spec.compiler.degree = False
    cam_cfg = scene.config.camera
    spec.visual.global_.offwidth = max(640, cam_cfg.width)
    spec.visual.global_.offheight = max(480, cam_cfg.height)
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.3, 0.3, 0.3]

    png = cv2.imencode(".png", cv2.cvtColor(soil_texture(scene.seed), cv2.COLOR_RGB2BGR))[1].tobytes()
    spec.assets = {SOIL_TEXTURE: png}
    spec.add_texture(name="sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX, builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
                     rgb1=[0.55, 0.55, 0.5], rgb2=[0.15, 0.15, 0.15], width=64, height=64)
    spec.add_texture(name="soil", type=mujoco.mjtTexture.mjTEXTURE_2D, file=SOIL_TEXTURE)
    soil = spec.add_material(name="soil", rgba=[1, 1, 1, 1], texrepeat=[1, 1], specular=0.05, shininess=0.05)
    soil.textures[int(mujoco.mjtTextureRole.mjTEXROLE_RGB)] = "soil"
    for species, colours in COLOURS.items():
        for part, rgba in colours.items():
            spec.add_material(name=f"{species}_{part}", rgba=list(rgba), specular=0.2, shininess=0.3)

    heights = scene.terrain.heights
    lo, hi = float(heights.min()), float(heights.max())
    span = max(hi - lo, 1e-6)
    spec.add_hfield(
        name="terrain", nrow=heights.shape[0], ncol=heights.shape[1],
        size=[scene.terrain.size_x / 2, scene.terrain.size_y / 2, span, TERRAIN_THICKNESS],
        userdata=((heights - lo) / span).astype(np.float32).ravel().tolist(),
    )
    world = spec.worldbody
    world.add_geom(name="terrain", type=mujoco.mjtGeom.mjGEOM_HFIELD, hfieldname="terrain",
                   pos=[0, 0, lo], material="soil", friction=[1.0, 0.005, 0.0001])
    world.add_light(name="key", pos=[0.3, -0.3, 1.2], dir=[-0.25, 0.25, -1], diffuse=[0.6, 0.6, 0.6],
                    castshadow=shadows)
    world.add_light(name="fill", pos=[-0.4, 0.2, 1.0], dir=[0.4, -0.2, -1], diffuse=[0.25, 0.25, 0.25],
                    castshadow=False)

    intr = camera_intrinsics(cam_cfg)
    camera_z = float(np.median(heights)) + cam_cfg.height_above_soil
    world.add_camera(name="overhead", pos=[0, 0, camera_z], quat=_quat(camera_rotation_mujoco(cam_cfg.tilt_deg)),
                     fovy=intr.fovy_deg)

    contype = 1 if mushroom_collisions else 0
    for inst in scene.instances:
        model = inst.model
        scale = inst.scale_vector
        name = f"mushroom_{inst.id}"
        body = world.add_body(name=name, pos=inst.position, quat=_quat(inst.rotation))
        free = free_ids is None or inst.id in free_ids
        if free:
            body.add_freejoint(name=f"{name}_joint")
        for part, vertices, faces, volume, total in _parts(inst.species, inst.model_id):
            spec.add_mesh(name=f"{name}_{part}", uservert=vertices, userface=faces, scale=scale)
            body.add_geom(name=f"{name}_{part}", type=mujoco.mjtGeom.mjGEOM_MESH, meshname=f"{name}_{part}",
                          material=f"{inst.species}_{part}", mass=inst.mass * volume / total,
                          contype=contype, conaffinity=contype, condim=4, friction=[0.8, 0.01, 0.001])
        body.add_site(name=f"{name}_cap_top", pos=[0, 0, model.cap_top_z * scale[2]], size=[0.002, 0, 0], group=4)
        if not free:
            continue
        root = spec.add_equality(name=f"{name}_root", type=mujoco.mjtEq.mjEQ_WELD, objtype=mujoco.mjtObj.mjOBJ_BODY,
                                 name1=name, name2="world", active=True)
        # The anchor is given in body2's frame (the world): put it at the stem base, so the root
        # resists bending about the stem base rather than swinging about the world origin. A zero
        # relative pose means "as placed".
        root.data[:10] = 0.0
        root.data[:3] = inst.position
        # Stiff and hard: with MuJoCo's default soft weld a light, top-heavy mushroom sags and
        # tips over within a second; this holds it within a millimetre.
        root.solref = ROOT_SOLREF
        root.solimp = ROOT_SOLIMP
    return spec


def scene_to_model(scene: Scene, **kwargs: bool) -> mujoco.MjModel:
    """Compile ``scene_to_spec(scene)``."""
    return scene_to_spec(scene, **kwargs).compile()


def write_mjcf(scene: Scene, folder: str | Path, **kwargs: bool) -> Path:
    """Write ``scene.xml`` with its assets into ``folder`` (MuJoCo's viewer loads it); returns the path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    spec = scene_to_spec(scene, **kwargs)
    for name, data in spec.assets.items():
        (folder / name).write_bytes(data)
    xml_path = folder / "scene.xml"
    write_atomic(xml_path, spec.to_xml())
    return xml_path
