"""Inference wrapper: one camera-frame point cloud → rotation, stem axis and centre.

``PoseEstimator.estimate`` raises :class:`~perception.errors.NoEstimate` when fewer than
``min_points`` finite points remain (empty masks, NaN depth), and its subclass
:class:`~perception.errors.DegenerateCloud` when the points are all at one place or on one line
(they fix no orientation, though the network would answer); ``estimate_or_none`` returns
``None`` for both. It never returns NaN. Clouds are in metres in the camera frame: one whose
median depth is no plausible distance in metres (millimetres, say) is refused with
:class:`~perception.errors.PipelineInputError`, by the check ``PosePipeline`` makes of its depth.

Clouds larger than the network's ``num_points`` are subsampled: with ``sampling="random"`` (the
default, fast) each call draws from the estimator's seeded generator, so repeated calls on the
same cloud can differ slightly; ``sampling="fps"`` is deterministic and order independent but
costs a farthest-point-sampling pass per cloud.

``views=K`` (default 8; 1 for a single pass) averages K passes per cloud: each draws its own
``num_points`` sample and turns the cloud by ``2πk/K`` about the camera's optical axis (a
symmetry of a pinhole view, undone on the output); the stem axes and x axes are averaged and
re-orthonormalised stem first. Clouds hold far more points than the network reads (≈ 700–4,000
for a rendered mushroom, 512 read), and single passes scatter around the truth, so the average
is markedly more accurate for K× the network time (``perception/weights/README.md`` has the
measured errors).

``upright_pass=True`` (off by default) runs the K views a second time on each cloud turned
so that the first estimate's stem points at the camera, and averages both sets: the network is
most accurate on near-upright mushrooms, and the turned cloud is a different input whose
errors partly cancel the first set's. Measured on the shipped weights (8 views): mean stem-axis
error 2.2° → 2.1° on synthetic views, 4.6–5.4° → 4.4–5.2° on every scene instance (an earlier,
less trained network gained more: 3.1° → 2.7°), for twice the network time.

``workers=W`` splits a batch into ``W`` parts run in ``W`` threads (torch releases the GIL in
its kernels). The Point Transformer's CPU kernels are small, so one intra-op thread per worker
(``torch.set_num_threads(1)``) with ``W`` = the number of cores gives the best throughput:
``benchmarks/bench_pose.py --workers`` measures it.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from perception.baselines.point_transformer.pose_net import PoseNet, load_checkpoint
from perception.errors import PerceptionConfigError
from perception.pointcloud import (
    MIN_POINTS,
    PreparedCloud,
    SamplingMethod,
    check_metres,
    check_sampling,
    prepare_cloud,
    to_tensor,
)
from perception.pose.rotations import rotation_6d_stem_to_matrix

WEIGHTS_DIR = Path(__file__).resolve().parents[2] / "weights"
DEFAULT_WEIGHTS = "posenet_default.pt"


def default_weights_path() -> Path:
    """Path of the shipped default weights (package data)."""
    return WEIGHTS_DIR / DEFAULT_WEIGHTS


@dataclass(frozen=True)
class Estimate:
    """A mushroom pose in the camera frame (OpenCV axes, metres)."""

    rotation: np.ndarray  # (3, 3) camera-from-mushroom
    stem_axis: np.ndarray  # (3,) unit, = rotation[:, 2], from stem base towards the cap
    centre: np.ndarray  # (3,) centroid of the valid observed points
    num_points: int  # valid points the estimate is based on


class PoseEstimator:
    """Wraps a trained :class:`PoseNet` for single or batched inference."""

    def __init__(
        self,
        model: PoseNet,
        device: str | torch.device = "cpu",
        sampling: SamplingMethod = "random",
        seed: int = 0,
        min_points: int = MIN_POINTS,
        views: int = 8,
        workers: int = 1,
        upright_pass: bool = False,
    ) -> None:
        for name, value in (("views", views), ("workers", workers)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise PerceptionConfigError(name, f"must be an int >= 1, got {value!r}")
        check_sampling(sampling, "sampling")
        self.model = model.to(device).eval()
        self.views = views
        self.workers = workers
        self.upright_pass = upright_pass
        angles = 2 * np.pi * np.arange(views) / views
        c, s = np.cos(angles), np.sin(angles)
        zero, one = np.zeros(views), np.ones(views)
        # (K, 3, 3) turns about the optical axis (camera z).
        self._turns = np.stack((c, -s, zero, s, c, zero, zero, zero, one), -1).reshape(views, 3, 3)
        self.config = model.config
        self.device = torch.device(device)
        self.sampling = sampling
        self.min_points = min_points
        self._rng = np.random.default_rng(seed)

    @classmethod
    def from_checkpoint(cls, path: str | Path, device: str = "cpu", **kwargs) -> PoseEstimator:
        model, _ = load_checkpoint(path, map_location=device)
        return cls(model, device, **kwargs)

    @classmethod
    def from_pretrained(cls, device: str = "cpu", **kwargs) -> PoseEstimator:
        """The shipped default network (``perception/weights/posenet_default.pt``)."""
        return cls.from_checkpoint(default_weights_path(), device, **kwargs)

    def estimate(self, points_cam: np.ndarray, colors: np.ndarray | None = None) -> Estimate:
        """Estimate one mushroom's pose from its ``(N, 3)`` camera-frame points.

        Raises:
            NoEstimate: fewer than ``min_points`` finite points; ``DegenerateCloud`` (a
                ``NoEstimate``): all at one place or on one line.
            PipelineInputError: depths that are not metres.
            ValueError: wrong shapes, or colours missing for an RGB network.
        """
        return self.estimate_batch([points_cam], None if colors is None else [colors])[0]

    def estimate_or_none(self, points_cam: np.ndarray, colors: np.ndarray | None = None) -> Estimate | None:
        """Like :meth:`estimate`, but ``None`` instead of raising :class:`NoEstimate`."""
        from perception.errors import NoEstimate

        try:
            return self.estimate(points_cam, colors)
        except NoEstimate:
            return None

    @torch.inference_mode()
    def infer(self, x: torch.Tensor) -> torch.Tensor:
        """The network on prepared clouds ``x (B, N, C)`` → ``(B, 3, 3)``, split over
        ``workers`` threads for large batches."""
        if self.workers == 1 or len(x) < 2 * self.workers:
            return self.model(x)
        # inference_mode is thread-local: each worker enters it through this same method.
        with ThreadPoolExecutor(self.workers) as pool:
            return torch.cat(list(pool.map(self.infer_single, x.tensor_split(self.workers))))

    @torch.inference_mode()
    def infer_single(self, x: torch.Tensor) -> torch.Tensor:
        """The network on ``x`` in the calling thread."""
        return self.model(x)

    def _passes(self, prepared: Sequence[PreparedCloud], rotations: np.ndarray) -> np.ndarray:
        """The network on each prepared cloud turned by its rotation ``(n, 3, 3)``, the turn
        undone on the output: a cloud turned by T has rotation T R."""
        x = torch.stack([to_tensor(c.points @ t.T, c.colors) for c, t in zip(prepared, rotations, strict=True)])
        return np.einsum("nji,njk->nik", rotations, self.infer(x.to(self.device)).double().cpu().numpy())

    @torch.inference_mode()
    def estimate_batch(
        self, clouds: Sequence[np.ndarray], colors: Sequence[np.ndarray | None] | None = None
    ) -> list[Estimate]:
        """Estimate several mushrooms in one forward pass (raises :class:`NoEstimate` if any
        cloud is too small or degenerate; filter with :meth:`estimate_or_none` per cloud if that
        can happen)."""
        if self.config.use_rgb and colors is None:
            raise ValueError("colors: this network uses RGB; pass colours for every cloud")
        prepared = [
            prepare_cloud(
                np.asarray(p, dtype=np.float32),
                self.config.num_points,
                self._rng,
                None if not self.config.use_rgb else np.asarray(colors[i], dtype=np.float32),
                self.sampling,
                self.min_points,
            )
            for i, p in enumerate(clouds)
            for _ in range(self.views)
        ]
        if not prepared:
            return []
        for i, p in enumerate(clouds):  # shapes checked by prepare_cloud
            check_metres(np.asarray(p)[:, 2], f"clouds[{i}] z")
        turns = np.tile(self._turns, (len(clouds), 1, 1))
        R = self._passes(prepared, turns).reshape(len(clouds), self.views, 3, 3)
        if self.upright_pass:
            upright = np.repeat(turn_to_camera(_average_rotations(R)[:, :, 2]), self.views, axis=0)
            second = self._passes(prepared, turns @ upright).reshape(R.shape)
            R = np.concatenate((R, second), axis=1)
        R = _average_rotations(R)
        first = prepared[:: self.views]
        return [
            Estimate(R[i], R[i][:, 2].copy(), np.asarray(c.centre, dtype=np.float64), c.num_valid)
            for i, c in enumerate(first)
        ]


def _average_rotations(R: np.ndarray) -> np.ndarray:
    """``(n, K, 3, 3)`` passes → ``(n, 3, 3)``: stem and x axes averaged, re-orthonormalised
    stem first (the stem axis is what the network estimates best)."""
    if R.shape[1] == 1:
        return R[:, 0]
    mean = R.mean(1)
    return rotation_6d_stem_to_matrix(torch.from_numpy(np.concatenate((mean[:, :, 2], mean[:, :, 0]), 1))).numpy()


def turn_to_camera(axes: np.ndarray) -> np.ndarray:
    """``(n, 3, 3)`` shortest rotations taking unit ``axes (n, 3)`` to the camera direction
    ``-z`` (OpenCV camera frame); an axis pointing straight away is turned half a turn about x."""
    a = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    v = np.stack((-a[:, 1], a[:, 0], np.zeros(len(a))), 1)  # a × (0, 0, -1)
    c = -a[:, 2]
    K = np.zeros((len(a), 3, 3))
    K[:, 0, 2], K[:, 2, 0] = v[:, 1], -v[:, 1]
    K[:, 1, 2], K[:, 2, 1] = -v[:, 0], v[:, 0]
    K[:, 0, 1], K[:, 1, 0] = -v[:, 2], v[:, 2]
    away = c < -1 + 1e-9
    out = np.eye(3) + K + K @ K / np.where(away, 1.0, 1.0 + c)[:, None, None]
    out[away] = np.diag([1.0, -1.0, -1.0])
    return out
