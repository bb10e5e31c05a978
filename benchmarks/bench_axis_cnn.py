"""Axis-CNN inference speed: ms per mushroom and per bed, on the masks of a rendered bed.

Renders one clean 640 x 480 bed (``--mushrooms``, seed ``--seed``), takes MuJoCo's masks, and
times the shipped ``AxisCNNEstimator.estimate_axes`` (crops + 8-view network; ``--weights`` for
another checkpoint, to compare two on one machine) on one mask and on all of them; medians over
``--repeats`` runs after a warm-up. Prints one Markdown table; run
``python benchmarks/bench_axis_cnn.py [--weights runs/axis_cnn12/best.pt]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # runs from a checkout

import torch  # noqa: E402

from generator import SceneConfig, generate_scene  # noqa: E402
from generator.dataset.render import SceneRenderer  # noqa: E402
from perception.detection.detector import detections_from_labels  # noqa: E402
from perception.pose.axis_cnn import AxisCNNEstimator  # noqa: E402


def median_ms(run, repeats: int) -> float:
    run()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="torch intra-op threads to time")
    p.add_argument("--mushrooms", type=int, default=40)
    p.add_argument("--seed", type=int, default=424242)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--weights", help="an axis-CNN checkpoint (default: the shipped one)")
    args = p.parse_args()
    scene = generate_scene(SceneConfig().replace(placement__num_mushrooms=args.mushrooms), seed=args.seed)
    with SceneRenderer(480, 640) as renderer:
        frame = renderer.render(scene, amodal=False)
    masks = [d.mask for d in detections_from_labels(frame.labels_mushroom) if d.area >= 20]
    estimator = AxisCNNEstimator.from_checkpoint(args.weights) if args.weights else AxisCNNEstimator.from_pretrained()
    config = estimator.model.config
    print(f"torch={torch.__version__}, {args.weights or 'shipped weights'} (width {config.width}, hidden "
          f"{config.hidden}), {len(masks)} masks of a {args.mushrooms}-mushroom bed, 8 views each\n")
    print("| threads | ms / mushroom (one mask) | ms / bed (all masks) | ms / mushroom in the bed |")
    print("|---:|---:|---:|---:|")
    for threads in args.threads:
        torch.set_num_threads(threads)
        one = median_ms(lambda: estimator.estimate_axes(frame.rgb, frame.depth, masks[:1], frame.intrinsics), args.repeats)
        bed = median_ms(lambda: estimator.estimate_axes(frame.rgb, frame.depth, masks, frame.intrinsics), args.repeats)
        print(f"| {threads} | {one:.1f} | {bed:.0f} | {bed / len(masks):.1f} |")


if __name__ == "__main__":
    main()
