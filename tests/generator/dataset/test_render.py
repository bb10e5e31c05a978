"""Rendered data agrees with the 3D ground truth: depth lies on the meshes, masks on the caps."""

import numpy as np
import pytest
import trimesh

from generator import SceneConfig, generate_scene
from generator.camera import project
from generator.dataset import DatasetOptions, RealismOptions, generate_dataset
from generator.dataset.backproject import backproject
from generator.dataset.readers import SceneDataset, read_scene_files
from generator.dataset.render import SceneRenderer
from generator.dataset.seeds import realism_rng

CFG = SceneConfig().replace(camera__width=160, camera__height=120, placement__num_mushrooms=12)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("ds")
    generate_dataset(out, CFG, 2, seed=5, progress=False)
    return out


def _world_points(sample, mask):
    intr = sample.record["camera"]["intrinsics"]
    pts, _ = backproject(sample.depth, intr["fx"], intr["fy"], intr["cx"], intr["cy"], mask)
    pose = sample.world_from_camera
    return pts @ pose[:3, :3].T + pose[:3, 3]


def test_backprojected_depth_lies_on_each_mushroom_mesh(dataset):
    sample = read_scene_files(dataset / "scene_000000")
    scene = sample.scene
    checked = 0
    for inst in scene.instances:
        mask = sample.labels_mushroom == inst.id + 1
        if mask.sum() < 10:
            continue
        pts = _world_points(sample, mask)
        mesh = trimesh.util.concatenate([inst.model.cap_mesh, inst.model.stem_mesh])
        mesh.apply_transform(inst.transform)
        _, dist, _ = trimesh.proximity.closest_point(mesh, pts)
        assert np.median(dist) < 1e-3, f"instance {inst.id}: median {np.median(dist) * 1e3:.2f} mm"
        checked += 1
    assert checked >= 5


def test_wrong_principal_point_would_be_detected(dataset):
    """The half-pixel principal point matters: W/2 instead of W/2 - 0.5 moves points off the mesh."""
    sample = read_scene_files(dataset / "scene_000000")
    intr = sample.record["camera"]["intrinsics"]
    assert intr["cx"] == CFG.camera.width / 2 - 0.5 and intr["cy"] == CFG.camera.height / 2 - 0.5


def test_visible_unoccluded_cap_centre_projects_inside_its_masks(dataset):
    checked = 0
    for d in ("scene_000000", "scene_000001"):
        sample = read_scene_files(dataset / d)
        pose = sample.world_from_camera
        intr = sample.record["camera"]["intrinsics"]
        from generator.camera import Intrinsics
        K = Intrinsics(**{k: intr[k] for k in ("width", "height", "fx", "fy", "cx", "cy")})
        for ann in sample.annotations:
            if ann["category_id"] != 2:
                continue
            iid = ann["instance_id"]
            amodal = sample.amodal_caps[iid]
            visible = sample.labels_cap == iid + 1
            assert not (visible & ~amodal).any(), "visible cap pixels outside the amodal cap"
            if ann["visible_fraction"] < 0.999:
                continue
            inst = next(m for m in sample.record["instances"] if m["id"] == iid)
            u, v, _ = project(np.array([inst["cap_top"]]), pose, K)[0]
            ui, vi = int(round(u)), int(round(v))
            assert visible[vi, ui] and amodal[vi, ui] and sample.labels_mushroom[vi, ui] == iid + 1
            checked += 1
    assert checked >= 5


def test_labels_only_use_known_instance_ids(dataset):
    sample = read_scene_files(dataset / "scene_000001")
    ids = {m["id"] + 1 for m in sample.record["instances"]} | {0}
    assert set(np.unique(sample.labels_mushroom)) <= ids
    assert set(np.unique(sample.labels_cap)) <= set(np.unique(sample.labels_mushroom))
    assert (sample.depth > 0).mean() > 0.99  # soil everywhere under the camera
    item = SceneDataset(dataset)[0]
    assert item["rgb"].shape == (3, 120, 160) and item["depth"].dtype.is_floating_point
    assert 0.3 < float(item["depth"][item["depth"] > 0].median()) < 0.45


def test_depth_noise_follows_the_stereo_model():
    scene = generate_scene(CFG.replace(camera__width=320, camera__height=240), 3)
    with SceneRenderer(240, 320) as r:
        clean = r.render(scene, amodal=False).depth
        noisy = r.render(scene, DatasetOptions(realism=RealismOptions(depth_noise=True)), realism_rng(0, 0),
                         amodal=False).depth
    focal = 382.0 * 240 / 480  # d405 preset at 320 x 240
    sigma = clean.astype(np.float64) ** 2 * 0.08 / (focal * 0.018)
    z = (noisy - clean) / sigma
    assert abs(z.std() - 1.0) < 0.05 and abs(z.mean()) < 0.05


def test_realism_changes_images_and_records_draws():
    scene = generate_scene(CFG, 1)
    all_on = DatasetOptions(realism=RealismOptions(depth_noise=True, edge_holes=True, lighting=True, soil=True,
                                                   camera_jitter=True))
    with SceneRenderer(120, 160) as r:
        base = r.render(scene)
        a = r.render(scene, all_on, realism_rng(0, 1))
        b = r.render(scene, all_on, realism_rng(0, 1))
    assert set(a.realism) == {"lighting", "soil", "camera"}
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.depth, b.depth)  # seeded
    assert not np.array_equal(a.rgb, base.rgb)
    assert (a.depth == 0).sum() > (base.depth == 0).sum()  # edge holes
    assert not np.allclose(a.world_from_camera, base.world_from_camera)
