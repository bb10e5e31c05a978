"""Stage-1 and pipeline speed: the shipped RGB-D segmenter and Mask R-CNN (both configurations)
per 640 x 480 image, and the two-stage pipeline's time per scene (detector + pose network).

Targets: the shipped stage-1 model at most 0.5 s per 640 x 480 image on this CPU;
Mask R-CNN's light configuration under 1 s. Times are medians
over ``--repeats`` runs after a warm-up, eval mode, no_grad, on a rendered dataset scene. Network
weights matter: torchvision runs the mask head on every box scoring over 0.05 (up to 100), which
random weights produce in numbers, so the random-weight rows are upper bounds and ``--checkpoint``
(a trained detector) gives the realistic row and the pipeline rows.

    python benchmarks/bench_detector.py --data runs/pose_scenes_heldout [--checkpoint best.pt]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import torch

from generator.dataset.readers import read_scene_files, scene_indices
from generator.dataset.writer import scene_dirname
from perception.baselines.maskrcnn.model import DetectorConfig, MaskRCNNDetector, build_maskrcnn
from perception.baselines.point_transformer.estimator import PoseEstimator
from perception.detection.load import load_detector
from perception.evaluation.eval_pipeline import run_scene
from perception.pipeline import PosePipeline


def median_ms(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(1e3 * (time.perf_counter() - start))
    return statistics.median(times)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", required=True, help="a dataset folder from `sms3d generate` (640 x 480)")
    p.add_argument("--split", default="test")
    p.add_argument("--checkpoint", help="a trained mobilenet_v3_fpn detector for the pipeline rows")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    sample = read_scene_files(f"{args.data}/{scene_dirname(scene_indices(args.data, args.split)[0])}")
    print(f"threads={torch.get_num_threads()} torch={torch.__version__} image={sample.rgb.shape[1]}x{sample.rgb.shape[0]}\n")

    print("| detector | network input | params (M) | ms / image |")
    print("|---|---|---:|---:|")
    shipped = load_detector("shipped")
    ms = median_ms(lambda: shipped.detect(sample.rgb, sample.depth), args.repeats)
    params = sum(t.numel() for t in shipped.model.parameters()) / 1e6
    h, w = sample.rgb.shape[:2]
    print(f"| shipped RGB-D segmenter | {w // 2} x {h // 2} (RGB-D) | {params:.2f} | {ms:.0f} |")
    for arch, size in (("mobilenet_v3_fpn", (360, 480)), ("mobilenet_v3_fpn", (480, 640)), ("resnet50_fpn_v2", (480, 640))):
        config = DetectorConfig(arch=arch, min_size=size[0], max_size=size[1])
        detector = MaskRCNNDetector(build_maskrcnn(config), config)
        params = sum(t.numel() for t in detector.model.parameters()) / 1e6
        ms = median_ms(lambda d=detector: d.detect(sample.rgb), args.repeats)
        print(f"| {arch} (random weights) | {size[1]} x {size[0]} | {params:.1f} | {ms:.0f} |")
    trained = MaskRCNNDetector.from_checkpoint(args.checkpoint) if args.checkpoint else None
    if trained is not None:
        c = trained.config
        ms = median_ms(lambda: trained.detect(sample.rgb), args.repeats)
        print(f"| {c.arch} (trained: {args.checkpoint}) | {c.max_size} x {c.min_size} | "
              f"{sum(t.numel() for t in trained.model.parameters()) / 1e6:.1f} | {ms:.0f} |")

    estimator = PoseEstimator.from_pretrained()
    rows = [("oracle masks", PosePipeline(estimator, None), True),
            ("shipped RGB-D segmenter", PosePipeline(estimator, shipped), False)]
    if trained is not None:
        rows.append((f"Mask R-CNN {args.checkpoint}", PosePipeline(estimator, trained), False))
    print("\n| pipeline | mushrooms estimated | ms / scene |")
    print("|---|---:|---:|")
    for name, pipeline, oracle in rows:
        n = len(run_scene(pipeline, sample, oracle))
        ms = median_ms(lambda pl=pipeline, o=oracle: run_scene(pl, sample, o), args.repeats)
        print(f"| {name} | {n} | {ms:.0f} |")


if __name__ == "__main__":
    main()
