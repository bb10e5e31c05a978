"""Generate a dataset: many seeded scenes in parallel, resumable, then COCO files and a manifest.

Scene ``i`` depends only on (config, options, run seed, i): the same files come out whatever the
number of workers or backend. Finished scenes (folders with ``DONE``) are skipped on a re-run, once
their ``scene.json`` shows they were made with the requested settings; ``*.tmp`` folders left by a
killed run are removed and redone. Pool workers die with the process that started them.
"""

from __future__ import annotations

import atexit
import errno
import itertools
import json
import multiprocessing
import os
import platform
import shutil
import sys
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from importlib import metadata
from pathlib import Path
from typing import Any

from generator.config import SceneConfig, require_int
from generator.dataset.coco import merge_split
from generator.dataset.errors import CorruptFileError, DatasetWriteError, ManifestMismatchError
from generator.dataset.options import DatasetOptions
from generator.dataset.seeds import SPLITS, realism_rng, scene_seed, split_of
from generator.dataset.writer import (
    MAX_SCENES,
    SCENE_DIR,
    _write_bytes,
    dumps,
    is_complete,
    scene_dirname,
    write_scene,
)
from generator.processes import die_with_parent, init_ray

MANIFEST = "manifest.json"
FORMAT_VERSION = 1
_PACKAGES = ("mujoco", "numpy", "opencv-python-headless", "pycocotools", "trimesh", "manifold3d")

_renderers: dict[tuple[int, int], Any] = {}  # one SceneRenderer per image size, per process


def _renderer(height: int, width: int) -> Any:
    from generator.dataset.render import SceneRenderer

    key = (height, width)
    if key not in _renderers:
        _renderers[key] = SceneRenderer(height, width)
        if len(_renderers) == 1:
            atexit.register(close_renderers)
    return _renderers[key]


def close_renderers() -> None:
    """Close this process's cached renderers."""
    while _renderers:
        _renderers.popitem()[1].close()


def produce_scene(out_dir: str, index: int, config: dict[str, Any], options: dict[str, Any], run_seed: int) -> str:
    """Generate, render and write scene ``index`` (runs in a worker); returns its split."""
    from generator.generate import generate_scene

    cfg = SceneConfig.from_dict(config)
    opts = DatasetOptions.from_dict(options)
    scene = generate_scene(cfg, scene_seed(run_seed, index))
    rng = realism_rng(run_seed, index)
    frame = _renderer(cfg.camera.height, cfg.camera.width).render(scene, opts, rng)
    split = split_of(run_seed, index, opts.split_ratios)
    write_scene(Path(out_dir), index, scene, frame, split, run_seed, options)
    return split


def _package_versions() -> dict[str, str]:
    versions = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def _run_key(config: SceneConfig, options: DatasetOptions, seed: int) -> dict[str, Any]:
    return {"format_version": FORMAT_VERSION, "seed": seed, "config": config.to_dict(), "options": options.to_dict()}


def _prepare_out_dir(out: Path) -> None:
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".write_probe"
        _write_bytes(probe, b"ok")
        probe.unlink()
    except OSError as exc:
        raise DatasetWriteError(out, f"output folder is not writable ({exc.strerror or exc})") from exc


def _differences(old: Any, new: Any, prefix: str = "") -> list[str]:
    """The settings in which two JSON values differ, each as ``name (old there, new requested)``,
    recursing into objects so that a name is as precise as ``config.placement.num_mushrooms``."""
    if isinstance(old, dict) and isinstance(new, dict):
        return [d for k in sorted(set(old) | set(new))
                for d in _differences(old.get(k), new.get(k), f"{prefix}.{k}" if prefix else k)]
    old, new = json.loads(dumps(old)), json.loads(dumps(new))  # tuples and lists compare equal
    if old == new:
        return []
    short = [text if len(text) <= 40 else text[:37] + "..." for text in (dumps(old), dumps(new))]
    return [f"{prefix} ({short[0]} there, {short[1]} requested)"]


def _check_manifest(out: Path, key: dict[str, Any]) -> set[int]:
    """Refuse a manifest written with other settings; returns the scenes it lists (made with
    this run's settings, so they need no further check)."""
    path = out / MANIFEST
    if not path.exists():
        return set()
    try:
        old = json.loads(path.read_text(encoding="utf-8"))
        listed = {int(e["index"]) for e in old.get("scenes", [])}
    except (OSError, ValueError, TypeError, KeyError, AttributeError) as exc:
        raise ManifestMismatchError(f"{path}: unreadable manifest ({exc}); remove it (every scene is then "
                                    "checked against its scene.json) or use another --out") from exc
    differing = _differences({k: old.get(k) for k in key}, key)
    if differing:
        raise ManifestMismatchError(f"{path}: existing dataset was made with different {', '.join(differing)}; "
                                    "use another --out or the same settings to resume")
    return listed


def _check_scenes(out: Path, key: dict[str, Any], indices: Iterable[int]) -> None:
    """Refuse to resume beside complete scenes whose ``scene.json`` records other settings."""
    expected = {k: key[k] for k in ("seed", "config", "options")}
    for i in indices:
        path = out / scene_dirname(i) / "scene.json"
        try:
            record = json.loads(path.read_bytes())
            dataset = record["dataset"]
            recorded = {"seed": dataset.get("run_seed"), "config": record.get("config"),
                        "options": dataset.get("options")}
        except (OSError, ValueError, TypeError, KeyError, AttributeError) as exc:
            raise CorruptFileError(path, f"cannot read the settings this scene was made with ({exc})") from exc
        differing = _differences(recorded, expected)
        if differing:
            raise ManifestMismatchError(f"{path.parent}: this scene was made with different {', '.join(differing)}; "
                                        "use another --out or the same settings to resume")


def _write_json_atomic(path: Path, obj: Any) -> None:
    tmp = path.with_name(path.name + ".tmp")
    _write_bytes(tmp, dumps(obj).encode())
    os.replace(tmp, path)


def _complete_scenes(out: Path, num_scenes: int) -> list[int]:
    """Indices below ``num_scenes`` with a complete folder, from one listing of ``out``: one
    check per folder present, not per scene requested, so a huge ``num_scenes`` starts at once."""
    indices = (int(m[1]) for m in map(SCENE_DIR.fullmatch, os.listdir(out)) if m)
    return sorted(i for i in indices if i < num_scenes and is_complete(out / scene_dirname(i)))


def _write_outputs(out: Path, key: dict[str, Any], num_scenes: int, status: str) -> dict[str, Any]:
    """COCO per split and the manifest, from the complete scene folders on disk only."""
    done = _complete_scenes(out, num_scenes)
    per_split: dict[str, list[Any]] = {s: [] for s in SPLITS}
    for i in done:
        data = json.loads((out / scene_dirname(i) / "annotations.json").read_text(encoding="utf-8"))
        per_split[data["image"]["split"]].append((i, data["image"], data["annotations"]))
    coco_files = {}
    if status == "complete":
        for split in SPLITS:
            _write_json_atomic(out / f"coco_{split}.json", merge_split(per_split[split], split))
            coco_files[split] = f"coco_{split}.json"
    manifest = {**key, "status": status, "num_scenes": num_scenes, "packages": _package_versions(),
                "scenes": [{"index": i, "dir": scene_dirname(i), "split": s}
                           for s in SPLITS for i, _, _ in per_split[s]],
                "splits": {s: [i for i, _, _ in per_split[s]] for s in SPLITS}, "coco": coco_files}
    manifest["scenes"].sort(key=lambda e: e["index"])
    _write_json_atomic(out / MANIFEST, manifest)
    return manifest


def _describe(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
        return f"disk full ({exc})"
    return f"{type(exc).__name__}: {exc}"


def generate_dataset(out_dir: str | os.PathLike[str], config: SceneConfig, num_scenes: int, seed: int = 0,
                     *, options: DatasetOptions | None = None, workers: int = 1, backend: str = "process",
                     progress: bool = True) -> dict[str, Any]:
    """Write ``num_scenes`` scenes into ``out_dir`` (resuming a previous run); returns the manifest.

    ``workers <= 1`` with the process backend renders in this process. Raises
    ``DatasetWriteError`` (folder not writable, disk full, a scene failed) and
    ``ManifestMismatchError`` (folder holds a dataset made with other settings)."""
    options = options or DatasetOptions()
    require_int("num_scenes", num_scenes, 1, MAX_SCENES)
    require_int("seed", seed, 0)
    if backend not in ("process", "ray"):
        raise ValueError(f"backend must be 'process' or 'ray', got {backend!r}")
    out = Path(out_dir)
    _prepare_out_dir(out)
    key = _run_key(config, options, seed)
    listed = _check_manifest(out, key)
    for tmp in sorted(out.glob("scene_*.tmp")):  # partial scenes of an interrupted run
        shutil.rmtree(tmp)
    done = _complete_scenes(out, num_scenes)
    _check_scenes(out, key, (i for i in done if i not in listed))
    done_set = set(done)
    todo = [i for i in range(num_scenes) if i not in done_set]
    _write_outputs(out, key, num_scenes, "incomplete")

    args = (str(out), config.to_dict(), options.to_dict(), seed)
    bar = _progress(len(todo), num_scenes - len(todo), progress)
    try:
        if backend == "ray":
            _run_ray(todo, args, workers, bar.update)
        elif workers <= 1:
            for i in todo:
                _run_one(i, args)
                bar.update(1)
        else:
            _run_pool(todo, args, workers, bar.update)
    except BaseException:
        bar.close()
        _write_outputs(out, key, num_scenes, "incomplete")
        raise
    bar.close()
    return _write_outputs(out, key, num_scenes, "complete")


def _run_one(index: int, args: tuple[Any, ...]) -> str:
    out, config, options, seed = args
    try:
        return produce_scene(out, index, config, options, seed)
    except OSError as exc:
        raise DatasetWriteError(Path(out) / scene_dirname(index), _describe(exc)) from exc


def _progress(total: int, initial: int, enabled: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=total + initial, initial=initial, unit="scene", disable=not enabled, file=sys.stderr)


def _run_pool(todo: list[int], args: tuple[Any, ...], workers: int, update: Callable[[int], Any]) -> None:
    ctx = multiprocessing.get_context("spawn")
    queue = iter(todo)
    # A few scenes in flight per worker, not one future per scene: a million-scene run would
    # otherwise hold a million futures before the first scene starts.
    in_flight = 2 * workers
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init,
                             initargs=(os.getpid(),)) as pool:
        pending = {pool.submit(_run_one, i, args) for i in itertools.islice(queue, in_flight)}
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in finished:
                exc = fut.exception()
                if exc is not None:
                    for other in pending:
                        other.cancel()
                    raise exc
                update(1)
            pending |= {pool.submit(_run_one, i, args) for i in itertools.islice(queue, len(finished))}


def _worker_init(parent_pid: int) -> None:
    # No orphan may keep writing scenes beside a resumed run.
    die_with_parent(parent_pid)


def _run_ray(todo: list[int], args: tuple[Any, ...], workers: int, update: Callable[[int], Any]) -> None:
    try:
        import ray
    except ImportError as exc:
        raise RuntimeError("backend 'ray' needs Ray: pip install 'sms3d-pick[ray]'") from exc
    if not ray.is_initialized():
        init_ray(max(workers, 1), runtime_env={"env_vars": {"MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}})
    task = ray.remote(_run_one)
    refs = [task.remote(i, args) for i in todo]
    remaining = list(refs)
    while remaining:
        ready, remaining = ray.wait(remaining, num_returns=1)
        ray.get(ready)
        update(len(ready))


def iter_scene_dirs(out_dir: str | os.PathLike[str]) -> Iterable[Path]:
    """Complete scene folders in index order."""
    return sorted(p for p in Path(out_dir).glob("scene_*") if p.is_dir() and is_complete(p))
