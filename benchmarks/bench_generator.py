"""Scene generation speed: geometry + MJCF per scene and MuJoCo compile time (one core).

Run: ``python benchmarks/bench_generator.py [--scenes 5]``. Prints one Markdown table.
Targets: a 100-mushroom scene in under 1 s; compile under 100 ms.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("OMP_NUM_THREADS", "1")

from generator import SceneConfig, generate_scene_with_stats, model_library  # noqa: E402
from generator.mjcf import scene_to_spec  # noqa: E402
from generator.overlap import model_solid  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scenes", type=int, default=5, help="scenes per row (different seeds)")
    args = parser.parse_args()
    for species in ("white", "brown"):  # models and their overlap proxies: built once per process
        for model_id in range(len(model_library(species))):
            model_solid(species, model_id)
    print("| mushrooms requested | placed (median) | geometry s/scene | MJCF spec s | compile ms | scenes/s (all) |")
    print("| --- | --- | --- | --- | --- | --- |")
    for count in (10, 50, 100):
        placed, geometry, spec_s, compile_s = [], [], [], []
        for seed in range(args.scenes):
            t0 = time.perf_counter()
            scene, stats = generate_scene_with_stats(SceneConfig().replace(placement__num_mushrooms=count), seed)
            t1 = time.perf_counter()
            spec = scene_to_spec(scene)
            t2 = time.perf_counter()
            spec.compile()
            t3 = time.perf_counter()
            placed.append(stats.placed)
            geometry.append(t1 - t0)
            spec_s.append(t2 - t1)
            compile_s.append(t3 - t2)
        total = statistics.median(g + s + c for g, s, c in zip(geometry, spec_s, compile_s))
        print(f"| {count} | {statistics.median(placed):.0f} | {statistics.median(geometry):.3f} | "
              f"{statistics.median(spec_s):.3f} | {1000 * statistics.median(compile_s):.0f} | {1 / total:.2f} |")


if __name__ == "__main__":
    main()
