import numpy as np
import pytest
import trimesh
from scipy import stats

from generator import SceneConfig, generate_scene, model_library
from generator.config import PlacementConfig
from generator.placement import sample_tilt


def test_roll_pitch_std_and_yaw_uniform():
    config = PlacementConfig()
    rng = np.random.default_rng(123)
    tilts = np.rad2deg(sample_tilt(config, rng, size=10_000)).reshape(-1, 2)
    assert abs(tilts[:, 0].std() - 20.0) < 1.0
    assert abs(tilts[:, 1].std() - 20.0) < 1.0
    assert abs(tilts.mean()) < 1.0  # signed, as the paper says
    half = np.rad2deg(sample_tilt(PlacementConfig(tilt_distribution="half_normal"), rng, size=5000))
    assert half.min() >= 0


@pytest.fixture(scope="module")
def dense_scene():
    return generate_scene(SceneConfig().replace(placement__num_mushrooms=60), seed=5)


def test_yaw_of_placed_mushrooms_is_uniform(dense_scene):
    scenes = [dense_scene] + [generate_scene(SceneConfig().replace(placement__num_mushrooms=60), seed=s) for s in (6, 7)]
    yaw = []
    for scene in scenes:
        for m in scene.instances:
            # yaw of R = Rz Ry Rx is atan2(R[1,0], R[0,0])
            yaw.append(np.arctan2(m.rotation[1, 0], m.rotation[0, 0]) % (2 * np.pi))
    assert stats.kstest(np.asarray(yaw), "uniform", args=(0, 2 * np.pi)).pvalue > 0.01


def test_every_pair_overlaps_at_most_tau(dense_scene):
    tau = dense_scene.config.placement.overlap_iou
    meshes = []
    for m in dense_scene.instances:
        mesh = m.model.mesh.copy()
        mesh.apply_transform(m.transform)
        meshes.append(mesh)
    worst = 0.0
    for i in range(len(meshes)):
        for j in range(i):
            if np.linalg.norm(meshes[i].bounding_sphere.center - meshes[j].bounding_sphere.center) > (
                meshes[i].bounding_sphere.primitive.radius + meshes[j].bounding_sphere.primitive.radius):
                continue
            inter = trimesh.boolean.intersection([meshes[i], meshes[j]], engine="manifold")
            v = inter.volume if len(inter.faces) else 0.0
            iou = v / (meshes[i].volume + meshes[j].volume - v)
            worst = max(worst, iou)
    assert worst <= tau + 1e-6
    assert len(dense_scene.instances) == 60


def test_stem_bases_on_terrain(dense_scene):
    for m in dense_scene.instances:
        ground = dense_scene.terrain.height_at(m.stem_base[0], m.stem_base[1])
        assert abs(m.stem_base[2] - ground) < 1e-3
        # the mesh's lowest point is sunk no deeper than the insertion depth plus the stem's
        # tilted footprint; it never floats above the soil
        mesh = m.model.mesh.copy()
        mesh.apply_transform(m.transform)
        low = mesh.vertices[np.argmin(mesh.vertices[:, 2])]
        assert low[2] <= dense_scene.terrain.height_at(low[0], low[1]) + 1e-3


def test_annotations_consistent_with_mesh(dense_scene):
    for m in dense_scene.instances:
        assert np.allclose(m.rotation.T @ m.rotation, np.eye(3), atol=1e-9)
        assert np.isclose(np.linalg.det(m.rotation), 1.0)
        assert np.isclose(np.linalg.norm(m.stem_axis), 1.0)
        cap = m.model.cap_mesh.copy()
        cap.apply_transform(m.transform)
        # every cap vertex lies inside its oriented box
        local = (cap.vertices - m.cap_obb.center) @ m.cap_obb.rotation
        assert np.all(np.abs(local) <= m.cap_obb.size / 2 + 1e-9)
        assert np.allclose(m.cap_obb.corners.mean(axis=0), m.cap_obb.center)
        # the cap top is the cap's highest point along the stem axis
        assert np.isclose((cap.vertices @ m.stem_axis).max(), m.cap_top @ m.stem_axis, atol=1e-9)
        assert 0.015 < m.cap_diameter < 0.09


def test_models_are_watertight_and_shaped():
    for species in ("white", "brown"):
        models = model_library(species)
        assert len(models) >= 7
        assert len({round(m.cap_diameter, 6) for m in models}) == len(models)
        for model in models:
            for mesh in (model.mesh, model.cap_mesh, model.stem_mesh):
                assert mesh.is_watertight and mesh.volume > 0
            assert np.allclose(model.mesh.bounds[0][2], 0.0, atol=1e-9)  # stem base at z = 0
            assert model.cap_bottom_z < model.cap_top_z
            stem_r = np.linalg.norm(model.stem_mesh.vertices[:, :2], axis=1).max()
            assert 0.25 < 2 * stem_r / model.cap_diameter < 0.5  # stem a third of the cap across


def test_procedural_models_are_seeded_new_shapes():
    from generator.mushroom_models import MODELS_PER_SPECIES, procedural_models

    library = {round(m.cap_diameter, 9) for m in model_library("white")}
    first, again, other = (procedural_models("white", 12, seed) for seed in (3, 3, 4))
    assert [m.model_id for m in first] == list(range(MODELS_PER_SPECIES, MODELS_PER_SPECIES + 12))
    assert [m.cap_diameter for m in first] == [m.cap_diameter for m in again]  # determined by the seed
    assert {m.cap_diameter for m in first}.isdisjoint(m.cap_diameter for m in other)
    assert library.isdisjoint(round(m.cap_diameter, 9) for m in first)  # none is a library model
    for m in first:
        assert m.mesh.is_watertight and 0.025 <= m.cap_diameter <= 0.040  # the library's ranges
    with pytest.raises(ValueError, match="species"):
        procedural_models("oyster", 2, 0)
    with pytest.raises(ValueError, match="n:"):
        procedural_models("brown", 0, 0)


def test_proxies_bracket_every_model():
    from generator.overlap import model_solid

    for species in ("white", "brown"):
        for model_id in range(len(model_library(species))):
            solid = model_solid(species, model_id)
            assert solid.inner is not None and solid.outer is not None
            assert (solid.inner - solid.exact).volume() == 0.0
            assert (solid.exact - solid.outer).volume() == 0.0
            assert 0.6 < solid.inner.volume() / solid.volume < 1 < solid.outer.volume() / solid.volume < 1.6


def _random_pair(rng, spread):
    """Two posed models (random species, model, tilt, yaw, scale) whose stem bases lie within
    ``spread`` (m) of the origin in x and y."""
    from generator.geometry import rotation_xyz
    from generator.overlap import Posed, model_solid

    posed = []
    for _ in range(2):
        species = ("white", "brown")[int(rng.integers(2))]
        t = np.eye(4)
        scale = rng.uniform(0.8, 2.0) * rng.uniform(0.9, 1.1, 3)
        t[:3, :3] = rotation_xyz(*rng.normal(0, 0.35, 2), rng.uniform(0, 2 * np.pi)) * scale
        t[:2, 3] = rng.uniform(-spread, spread, 2)
        posed.append(Posed.place(model_solid(species, int(rng.integers(7))), t, scale))
    return posed


def test_bounded_overlap_test_decides_as_the_exact_booleans():
    """Random pairs across the depths where each bound is used, many near tau."""
    from generator.overlap import OverlapCounts, exceeds_iou, intersection_iou

    rng = np.random.default_rng(3)
    counts = OverlapCounts()
    outcomes = set()
    for _ in range(160):
        a, b = _random_pair(rng, spread=0.035)
        tau = float(rng.choice([0.0, 0.01, 0.05, 0.2]))
        exact = intersection_iou(a.manifold("exact"), b.manifold("exact"), a.volume, b.volume) > tau
        assert exceeds_iou(a, [b], tau, counts) == exact
        outcomes.add(exact)
    assert outcomes == {True, False}
    assert counts.bounds > 0 and counts.exact < 160  # the bounds did decide some pairs


def test_the_hull_overlap_test_decides_as_the_boolean_of_the_whole_hulls():
    """The hull test's shortcuts (boxes apart, a separating plane, a vertex inside the other
    piece) give the answer of the exact boolean of the two mushrooms' hulls, touching or not."""
    from generator.overlap import OverlapCounts, exceeds_iou, intersection_iou

    rng = np.random.default_rng(5)
    counts = OverlapCounts()
    outcomes = set()
    for _ in range(120):
        a, b = _random_pair(rng, spread=0.06)
        for tau in (0.0, 0.02):
            whole = intersection_iou(a.manifold("hulls"), b.manifold("hulls"), a.manifold("hulls").volume(),
                                     b.manifold("hulls").volume()) > tau
            assert exceeds_iou(a, [b], tau, counts, solids="hulls") == whole
            outcomes.add(whole)
    assert outcomes == {True, False}
