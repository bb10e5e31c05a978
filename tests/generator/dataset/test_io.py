"""Dataset files: COCO, determinism across workers/backends, kill-and-resume, errors, readers."""

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from pycocotools.coco import COCO

from generator import ConfigError, SceneConfig
from generator.dataset import (
    CorruptFileError,
    DatasetOptions,
    DatasetWriteError,
    ManifestMismatchError,
    generate_dataset,
)
from generator.dataset import runner as runner_module
from generator.dataset import writer as writer_module
from generator.dataset.cli import main as cli_main
from generator.dataset.readers import InstancePointCloudDataset, read_scene_files

ROOT = Path(__file__).resolve().parents[3]
CFG = SceneConfig().replace(camera__width=160, camera__height=120, placement__num_mushrooms=8)


def tree_bytes(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("ref")
    generate_dataset(out, CFG, 4, seed=11, progress=False)
    return out


def test_coco_loads_and_links_to_scene_json(reference):
    n_anns = 0
    for split in ("train", "val", "test"):
        coco = COCO(str(reference / f"coco_{split}.json"))
        assert {c["name"] for c in coco.loadCats(coco.getCatIds())} == {"mushroom", "mushroom_cap"}
        for img in coco.loadImgs(coco.getImgIds()):
            sample = read_scene_files(reference / img["file_name"].split("/")[0])
            assert sample.index == img["scene_id"] == img["id"]
            ids = {m["id"] for m in sample.record["instances"]}
            for ann in coco.loadAnns(coco.getAnnIds(imgIds=img["id"])):
                assert ann["scene_id"] == img["id"] and ann["instance_id"] in ids
                labels = sample.labels_mushroom if ann["category_id"] == 1 else sample.labels_cap
                assert np.array_equal(coco.annToMask(ann).astype(bool), labels == ann["instance_id"] + 1)
                n_anns += 1
    assert n_anns > 20


def test_rle_encoders_match_pycocotools():
    from pycocotools import mask as mask_utils

    from generator.dataset.coco import encode_labels, encode_mask

    def reference_rle(mask):
        rle = mask_utils.encode(np.asfortranarray(mask.astype(np.uint8)))
        return {"size": [int(s) for s in rle["size"]], "counts": rle["counts"].decode("ascii")}

    rng = np.random.default_rng(0)
    for trial in range(60):
        h, w = (int(n) for n in rng.integers(1, 25, 2))
        labels = rng.integers(0, 4, (h, w)).astype(np.uint16)
        labels[rng.random((h, w)) < 0.6 * (trial % 3)] = 0  # sparse, dense and empty-ish images
        if trial % 7 == 0:
            labels[:] = 3  # a label that fills the image: no zero runs at all
        encoded = encode_labels(labels)
        assert sorted(encoded) == [int(k) for k in np.unique(labels) if k]
        for k in range(4):
            assert encode_mask(labels == k) == reference_rle(labels == k)
            if k in encoded:
                assert encoded[k] == reference_rle(labels == k)


def test_manifest_lists_complete_scenes_and_versions(reference):
    import json

    m = json.loads((reference / "manifest.json").read_text())
    assert m["status"] == "complete" and [e["index"] for e in m["scenes"]] == [0, 1, 2, 3]
    assert "mujoco" in m["packages"] and m["seed"] == 11
    assert all((reference / e["dir"] / "DONE").is_file() for e in m["scenes"])


def test_two_workers_give_identical_files(reference, tmp_path):
    generate_dataset(tmp_path, CFG, 4, seed=11, workers=2, progress=False)
    assert tree_bytes(tmp_path) == tree_bytes(reference)


@pytest.mark.slow
def test_ray_backend_gives_identical_files(reference, tmp_path):
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        generate_dataset(tmp_path, CFG, 4, seed=11, backend="ray", progress=False)
    finally:
        ray.shutdown()
    assert tree_bytes(tmp_path) == tree_bytes(reference)


def test_killed_and_resumed_run_equals_uninterrupted(reference, tmp_path):
    cmd = [sys.executable, "-m", "generator.dataset.cli", "generate", "--out", str(tmp_path), "--num-scenes", "4",
           "--seed", "11", "--num-mushrooms", "8", "--width", "160", "--height", "120", "--no-progress"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not (tmp_path / "scene_000000" / "DONE").exists():
        assert proc.poll() is None and time.monotonic() < deadline, "generator ended before the first scene"
        time.sleep(0.005)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (tmp_path / "scene_000003").exists(), "the run finished before it was killed"
    assert not (tmp_path / "coco_train.json").exists()
    assert subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True).returncode == 0
    assert tree_bytes(tmp_path) == tree_bytes(reference)


def test_killed_parent_leaves_no_worker_and_resume_is_identical(reference, tmp_path, processes):
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "generator.dataset.cli", "generate", "--out", str(out), "--num-scenes", "4",
           "--seed", "11", "--num-mushrooms", "8", "--width", "160", "--height", "120", "--no-progress",
           "--workers", "2"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while True:  # until both workers exist and have written a scene
        children = processes.children(proc.pid)
        workers = processes.pool_workers(proc.pid)
        if len(workers) == 2 and any(out.glob("scene_*/DONE")):
            break
        assert proc.poll() is None and time.monotonic() < deadline, "generator ended before its workers wrote"
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    survivors = processes.survivors(children)
    assert survivors == [], f"processes of the killed run still alive: {survivors} (workers {workers})"
    assert not (out / "coco_train.json").exists(), "the run finished before it was killed"
    generate_dataset(out, CFG, 4, seed=11, progress=False)  # resume (CFG is the command's config)
    assert tree_bytes(out) == tree_bytes(reference)


def test_orphaned_worker_watch_exits_when_the_parent_dies(processes):
    # The portable fallback of die_with_parent, for systems without prctl(PR_SET_PDEATHSIG).
    child = ("import os, threading, time; from generator.processes import exit_when_orphaned; "
             "threading.Thread(target=exit_when_orphaned, args=(os.getppid(), 0.05), daemon=True).start(); "
             "print(os.getpid(), flush=True); time.sleep(60)")
    parent = f"import subprocess, sys; subprocess.Popen([sys.executable, '-c', {child!r}]).wait()"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-c", parent], env=env, stdout=subprocess.PIPE, text=True)
    pid = int(proc.stdout.readline())
    proc.kill()
    proc.wait()
    assert processes.survivors([pid]) == []


def test_pool_keeps_a_few_scenes_in_flight(monkeypatch):
    # One future per scene up front would hold a million of them before a million-scene run starts.
    lock, outstanding, peak = threading.Lock(), [0], [0]

    def finished(_):
        with lock:
            outstanding[0] -= 1

    class CountingPool(ThreadPoolExecutor):
        def __init__(self, max_workers, **_process_pool_arguments):
            super().__init__(max_workers)

        def submit(self, fn, *args):
            with lock:
                outstanding[0] += 1
                peak[0] = max(peak[0], outstanding[0])
            future = super().submit(fn, *args)
            future.add_done_callback(finished)
            return future

    monkeypatch.setattr(runner_module, "ProcessPoolExecutor", CountingPool)
    monkeypatch.setattr(runner_module, "_run_one", lambda index, args: "train")
    updates = []
    runner_module._run_pool(list(range(2000)), (), 2, updates.append)
    assert len(updates) == 2000 and peak[0] <= 4


def test_start_up_looks_at_the_folders_present_not_every_requested_index(reference, monkeypatch):
    checked = []
    real = runner_module.is_complete
    monkeypatch.setattr(runner_module, "is_complete", lambda folder: checked.append(folder) or real(folder))
    assert runner_module._complete_scenes(reference, 1_000_000) == [0, 1, 2, 3]
    assert len(checked) == 4


def test_num_scenes_is_capped_by_the_folder_numbering(tmp_path):
    with pytest.raises(ConfigError, match="num_scenes") as info:
        generate_dataset(tmp_path / "o", CFG, 1_000_001, progress=False)
    assert info.value.field == "num_scenes" and not (tmp_path / "o").exists()


def _without_manifest(reference: Path, out: Path) -> dict[str, bytes]:
    shutil.copytree(reference, out)
    for name in ("manifest.json", "coco_train.json", "coco_val.json", "coco_test.json"):
        (out / name).unlink()
    shutil.rmtree(out / "scene_000003")
    return tree_bytes(out)


@pytest.mark.parametrize(("changes", "setting"), [
    ({"seed": 12}, "seed (11 there, 12 requested)"),
    ({"config": CFG.replace(placement__num_mushrooms=9)}, "config.placement.num_mushrooms (8 there, 9 requested)"),
    ({"options": DatasetOptions(shadows=True)}, "options.shadows (false there, true requested)"),
])
def test_resume_without_manifest_checks_every_scene(reference, tmp_path, changes, setting):
    out = tmp_path / "d"
    before = _without_manifest(reference, out)
    run = {"config": CFG, "seed": 11, "options": None, **changes}
    with pytest.raises(ManifestMismatchError) as info:
        generate_dataset(out, run["config"], 4, run["seed"], options=run["options"], progress=False)
    assert str(out / "scene_000000") in str(info.value) and setting in str(info.value)
    assert tree_bytes(out) == before  # refused before anything was written


def test_resume_without_manifest_with_the_same_settings_completes(reference, tmp_path):
    out = tmp_path / "d"
    _without_manifest(reference, out)
    generate_dataset(out, CFG, 4, seed=11, progress=False)
    assert tree_bytes(out) == tree_bytes(reference)


def test_scenes_the_manifest_does_not_list_are_checked(reference, tmp_path):
    generate_dataset(tmp_path / "other", CFG, 1, seed=5, progress=False)
    out = tmp_path / "d"
    shutil.copytree(reference, out)
    shutil.rmtree(out / "scene_000003")  # as if the manifest was written before scene 3 was done
    shutil.copytree(tmp_path / "other" / "scene_000000", out / "scene_000003")
    manifest = json.loads((out / "manifest.json").read_text())
    manifest["scenes"] = [e for e in manifest["scenes"] if e["index"] != 3]
    (out / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(ManifestMismatchError, match="scene_000003: this scene was made with different seed"):
        generate_dataset(out, CFG, 4, seed=11, progress=False)


def test_disk_full_leaves_nothing_marked_complete_and_resume_recovers(reference, tmp_path, monkeypatch):
    real_write = writer_module._write_bytes

    def failing(path, data):
        if "scene_000001.tmp" in str(path) and path.name == "depth.png":
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
        real_write(path, data)

    monkeypatch.setattr(writer_module, "_write_bytes", failing)
    with pytest.raises(DatasetWriteError, match="disk full") as info:
        generate_dataset(tmp_path, CFG, 4, seed=11, progress=False)
    assert "scene_000001" in str(info.value)
    assert (tmp_path / "scene_000000" / "DONE").is_file()
    assert not (tmp_path / "scene_000001").exists() and not list(tmp_path.glob("*.tmp"))
    import json

    m = json.loads((tmp_path / "manifest.json").read_text())
    assert m["status"] == "incomplete" and [e["index"] for e in m["scenes"]] == [0]
    monkeypatch.setattr(writer_module, "_write_bytes", real_write)
    generate_dataset(tmp_path, CFG, 4, seed=11, progress=False)
    assert tree_bytes(tmp_path) == tree_bytes(reference)


def test_unwritable_output_folder_is_a_clear_error(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    with pytest.raises(DatasetWriteError, match="not writable") as info:
        generate_dataset(blocker / "out", CFG, 1, progress=False)
    assert info.value.path == blocker / "out"
    assert cli_main(["generate", "--out", str(blocker / "out"), "--num-scenes", "1", "--no-progress"]) == 2


def test_invalid_config_is_rejected_before_writing(tmp_path, capsys):
    assert cli_main(["generate", "--out", str(tmp_path / "o"), "--num-scenes", "1", "--num-mushrooms", "0"]) == 2
    assert "placement.num_mushrooms" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
    bad = tmp_path / "bad.yaml"
    bad.write_text("camera: {width: 5}\n")
    with pytest.raises(ConfigError, match="camera.width"):
        SceneConfig.from_file(str(bad))


def test_resume_with_other_settings_is_refused(reference, tmp_path):
    generate_dataset(tmp_path, CFG, 1, seed=1, progress=False)
    with pytest.raises(ManifestMismatchError, match="seed"):
        generate_dataset(tmp_path, CFG, 1, seed=2, progress=False)


def test_corrupt_files_are_named(reference, tmp_path):
    import shutil

    shutil.copytree(reference / "scene_000002", tmp_path / "scene_000002")
    rgb = tmp_path / "scene_000002" / "rgb.png"
    rgb.write_bytes(rgb.read_bytes()[:200])
    with pytest.raises(CorruptFileError) as info:
        read_scene_files(tmp_path / "scene_000002")
    assert info.value.path == rgb
    with pytest.raises(CorruptFileError, match="not a readable PNG"):
        read_scene_files(tmp_path / "scene_000002", verify=False)
    scene_json = tmp_path / "scene_000002" / "scene.json"
    scene_json.write_text("{not json")
    with pytest.raises(CorruptFileError, match="scene.json"):
        read_scene_files(tmp_path / "scene_000002", verify=False)


def test_point_cloud_dataset_in_camera_frame(reference):
    ds = InstancePointCloudDataset(reference, num_points=128, cap_only=True)
    assert len(ds) > 10
    item = ds[0]
    assert item["points"].shape == (128, 3)
    r = item["rotation"].double().numpy()
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-6)
    np.testing.assert_allclose(r[:, 2], item["stem_axis"].double().numpy(), atol=1e-6)
    # the visible cap points lie within a cap diameter of the cap centre
    d = np.linalg.norm(item["points"].double().numpy() - item["cap_center"].double().numpy(), axis=1)
    assert d.max() < item["meta"]["cap_diameter"]
    assert np.array_equal(ds[0]["points"].numpy(), item["points"].numpy())  # repeatable sampling


def test_show_writes_an_overlay(reference, tmp_path):
    import cv2

    out = tmp_path / "show.png"
    assert cli_main(["show", str(reference), "--scene", "1", "--out", str(out)]) == 0
    img = cv2.imread(str(out))
    rgb = cv2.imread(str(reference / "scene_000001" / "rgb.png"))
    bar = img.shape[0] - rgb.shape[0]  # the title bar, which says what the colours and lines are
    assert 10 < bar < 60 and img.shape[1:] == rgb.shape[1:]
    assert (img[:bar] < 128).any(), "the title bar holds dark text"
    assert (np.abs(img[bar:].astype(int) - rgb).sum(axis=2) > 30).mean() > 0.02
