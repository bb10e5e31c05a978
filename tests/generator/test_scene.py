import dataclasses
import json

import mujoco
import numpy as np
import pytest
import trimesh

from generator import Scene, SceneConfig, SceneFormatError, generate_scene, load_mushroom_mesh
from generator.errors import MeshError
from generator.mjcf import scene_to_model, scene_to_spec, write_mjcf
from generator.terrain import Terrain


@pytest.fixture(scope="module")
def scene():
    return generate_scene(SceneConfig().replace(placement__num_mushrooms=15), seed=11)


def test_json_round_trip_is_exact(scene, tmp_path):
    again = type(scene).from_json(scene.to_json())
    assert again.to_json() == scene.to_json()
    assert np.array_equal(again.terrain.heights, scene.terrain.heights)
    for a, b in zip(again.instances, scene.instances):
        assert np.array_equal(a.rotation, b.rotation) and a.mass == b.mass
    path = tmp_path / "scene.json"
    scene.save(path)
    assert type(scene).load(path).to_json() == scene.to_json()


def test_schema_1_scene_with_listed_heights_still_loads(scene):
    old = scene.to_dict()
    old["schema_version"] = 1
    old["terrain"]["heights"] = scene.terrain.heights.tolist()
    again = type(scene).from_json(json.dumps(old))
    assert again.to_json() == scene.to_json()
    assert np.array_equal(again.terrain.heights, scene.terrain.heights)


def test_bad_encoded_heights_are_named(scene):
    data = scene.to_dict()
    data["terrain"]["heights"]["base64"] = data["terrain"]["heights"]["base64"][:-8]
    with pytest.raises(SceneFormatError, match="terrain.heights"):
        type(scene).from_json(json.dumps(data))


def test_corrupt_scene_file_is_named(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text('{"schema_version": 1, "seed": ')
    with pytest.raises(SceneFormatError, match="bad.json"):
        Scene.load(path)
    path.write_text('{"schema_version": 99}')
    with pytest.raises(SceneFormatError, match="schema_version"):
        Scene.load(path)


def test_same_seed_same_bytes_different_seed_different_scene(scene):
    config = scene.config
    again = generate_scene(config, seed=11)
    assert again.to_json() == scene.to_json()
    assert scene_to_spec(again).to_xml() == scene_to_spec(scene).to_xml()
    other = generate_scene(config, seed=12)
    assert not np.array_equal(other.terrain.heights, scene.terrain.heights)


def test_terrain_statistics(scene):
    h = scene.terrain.heights
    cfg = scene.config.terrain
    assert h.shape == (cfg.resolution, cfg.resolution)
    # fBm with persistence 0.5 stays within the sum of the octave amplitudes
    assert np.abs(h - cfg.base_elevation).max() <= cfg.amplitude * 2 * np.sqrt(2)
    assert h.std() > cfg.amplitude * 0.1


def test_heightfield_rows_match_terrain(scene):
    """The hfield row order trap: a point on the terrain must be where MuJoCo's hfield is."""
    model = scene_to_model(scene)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    geomgroup = np.zeros(6, np.uint8)
    geomgroup[0] = 1
    rng = np.random.default_rng(0)
    geom_id = np.zeros(1, np.int32)
    terrain_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "terrain")
    errors = []
    for x, y in rng.uniform(-0.3, 0.3, size=(20, 2)):
        dist = mujoco.mj_ray(model, data, np.array([x, y, 1.0]), np.array([0, 0, -1.0]), None, 1, -1, geom_id)
        if geom_id[0] != terrain_id:
            continue
        errors.append(abs((1.0 - dist) - scene.terrain.height_at(x, y)))
    assert len(errors) > 5
    assert max(errors) < 1e-3


def test_mjcf_compiles_and_rendered_depth_matches_cap_top(scene):
    model = scene_to_model(scene)
    assert model.nbody == 1 + len(scene.instances)
    assert model.neq == len(scene.instances)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    cam = model.camera("overhead")
    pos, rot = data.cam_xpos[cam.id], data.cam_xmat[cam.id].reshape(3, 3)
    from generator.camera import camera_intrinsics, project, world_from_camera_cv

    intr = camera_intrinsics(scene.config.camera)
    pose = world_from_camera_cv(pos, rot)
    with mujoco.Renderer(model, intr.height, intr.width) as renderer:
        renderer.enable_depth_rendering()
        renderer.update_scene(data, camera="overhead")
        depth = renderer.render()
    # The mushroom whose cap top is highest is never occluded at its top.
    top = max(scene.instances, key=lambda m: m.cap_top[2])
    u, v, z = project(top.cap_top[None], pose, intr)[0]
    window = depth[int(v) - 1:int(v) + 2, int(u) - 1:int(u) + 2]
    # The cap top is the highest point along the stem; seen from above the surface there is at
    # most a little closer than the top itself when tilted.
    mesh = top.model.cap_mesh.copy()
    mesh.apply_transform(top.transform)
    locations, _, _ = mesh.ray.intersects_location(pos[None], ((top.cap_top - pos) / np.linalg.norm(top.cap_top - pos))[None])
    expected = np.min(np.linalg.norm(locations - pos, axis=1) * np.abs(((top.cap_top - pos) / np.linalg.norm(top.cap_top - pos)) @ rot[:, 2]))
    assert abs(float(np.median(window)) - expected) < 2e-3
    assert abs(z - expected) < 0.02


def test_write_mjcf_loads_from_disk(scene, tmp_path):
    xml = write_mjcf(scene, tmp_path / "scene")
    model = mujoco.MjModel.from_xml_path(str(xml))
    assert model.ngeom == 1 + 2 * len(scene.instances)
    assert model.nhfield == 1


def test_root_weld_anchored_at_stem_base(scene):
    model = scene_to_model(scene)
    for inst in scene.instances:
        eq = model.equality(f"mushroom_{inst.id}_root")
        assert np.allclose(eq.data[:3], inst.position)


def test_welded_mushrooms_stay_put(scene):
    model = scene_to_model(scene)
    data = mujoco.MjData(model)
    start = data.qpos.copy()
    for _ in range(250):
        mujoco.mj_step(model, data)
    assert np.abs(data.qpos - start).max() < 2e-3


def test_user_mesh_loader(tmp_path):
    cap = trimesh.creation.icosphere(subdivisions=3, radius=20.0)
    cap.apply_scale([1.0, 1.0, 0.55])
    cap.apply_translation([0, 0, 30.0])
    stem = trimesh.creation.cylinder(radius=6.0, height=32.0)
    stem.apply_translation([0, 0, 16.0])
    whole = trimesh.boolean.union([cap, stem], engine="manifold")
    # A y-up scan in millimetres
    whole.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]))
    path = tmp_path / "scan.stl"
    whole.export(path)
    model = load_mushroom_mesh(path, "white", unit="mm", up_axis="y")
    assert abs(model.cap_diameter - 0.040) < 0.002
    assert model.mesh.bounds[0][2] == pytest.approx(0.0, abs=1e-6)
    assert 0.018 < model.cap_bottom_z < 0.032
    assert model.cap_mesh.is_watertight and model.stem_mesh.is_watertight

    ball = trimesh.creation.icosphere(radius=10.0)
    ball.export(tmp_path / "ball.stl")
    with pytest.raises(MeshError, match="no clear cap"):
        load_mushroom_mesh(tmp_path / "ball.stl", "white")
    open_mesh = trimesh.Trimesh(whole.vertices, whole.faces[: len(whole.faces) // 2])
    open_mesh.export(tmp_path / "open.stl")
    with pytest.raises(MeshError, match="watertight"):
        load_mushroom_mesh(tmp_path / "open.stl", "white", up_axis="y")
    (tmp_path / "junk.obj").write_text("this is not a mesh")
    with pytest.raises(MeshError):
        load_mushroom_mesh(tmp_path / "junk.obj", "white")


def test_terrain_height_at_is_bilinear():
    heights = np.array([[0.0, 1.0], [2.0, 3.0]])
    terrain = Terrain(heights, 2.0, 2.0)
    assert terrain.height_at(-1.0, -1.0) == 0.0  # row 0 at -y, column 0 at -x
    assert terrain.height_at(1.0, -1.0) == 1.0
    assert terrain.height_at(-1.0, 1.0) == 2.0
    assert terrain.height_at(0.0, 0.0) == pytest.approx(1.5)
    json.dumps(dataclasses.asdict(SceneConfig()))


def test_free_ids_makes_other_mushrooms_static(scene):
    n = len(scene.instances)
    full = scene_to_spec(scene).compile()
    assert full.nv == 6 * n and full.neq == n  # default unchanged: every mushroom free and rooted
    free = {0, 2}
    m = scene_to_spec(scene, free_ids=free).compile()
    assert m.nv == 6 * len(free) and m.neq == len(free)
    for inst in scene.instances:
        b = m.body(f"mushroom_{inst.id}")
        assert (b.jntnum[0] == 1) == (inst.id in free)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    for inst in scene.instances:  # static or free, each mushroom stands where it was placed
        np.testing.assert_allclose(d.xpos[m.body(f"mushroom_{inst.id}").id], inst.position, atol=1e-9)
