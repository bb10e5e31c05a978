"""Dataset generation speed: scenes per second at 640 x 480 with all outputs (RGB, depth, modal
and amodal masks, scene.json, COCO, manifest), for 10/50/100 requested mushrooms and 1/2 workers.

Anchor (docs/anchors.md): the public SMS3D generator takes 2.51 / 8.43 / 12.24 s per
scene at 10 / 50 / 100 requested mushrooms (1 process, 1024 x 1024); the goal is >= 10x faster.

    python benchmarks/bench_dataset.py [--scenes 6] [--counts 10 50 100] [--workers 1 2] [--size 640x480]
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("MUJOCO_GL", "egl")

from generator import SceneConfig, model_library  # noqa: E402
from generator.dataset import generate_dataset  # noqa: E402
from generator.overlap import model_solid  # noqa: E402

ANCHOR_S_PER_SCENE = {10: 2.51, 50: 8.43, 100: 12.24}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", type=int, default=6)
    ap.add_argument("--counts", type=int, nargs="+", default=[10, 50, 100])
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--size", default="640x480")
    args = ap.parse_args()
    w, h = (int(x) for x in args.size.split("x"))
    for species in ("white", "brown"):  # models and their overlap proxies: built once per process
        for model_id in range(len(model_library(species))):
            model_solid(species, model_id)
    print("| requested | workers | scenes | s/scene | scenes/s | speed-up vs anchor | MB/scene | peak RSS MiB (self / children) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for n in args.counts:
        cfg = SceneConfig().replace(camera__width=w, camera__height=h, placement__num_mushrooms=n)
        for k in args.workers:
            out = Path(tempfile.mkdtemp(prefix="bench_ds_"))
            # warm-up scene (imports, first renderer) is not timed: a long run pays it once
            generate_dataset(out, cfg, k, seed=1000 + n, workers=k, progress=False) if k == 1 else None
            shutil.rmtree(out)
            t = time.perf_counter()
            generate_dataset(out, cfg, args.scenes, seed=n, workers=k, progress=False)
            dt = time.perf_counter() - t
            size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file()) / args.scenes / 1e6
            shutil.rmtree(out)
            me = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
            sps = args.scenes / dt
            anchor = ANCHOR_S_PER_SCENE.get(n)
            speedup = f"{anchor * sps:.1f}x" if anchor else "-"
            print(f"| {n} | {k} | {args.scenes} | {dt / args.scenes:.3f} | {sps:.2f} | {speedup} | {size:.2f} | "
                  f"{me:.0f} / {kids:.0f} |", flush=True)


if __name__ == "__main__":
    main()
