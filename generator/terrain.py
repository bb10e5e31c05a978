"""Perlin fBm soil heights on a regular grid (the paper's equation in section 3.1.1)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from generator.config import TerrainConfig


def perlin2d(x: np.ndarray, y: np.ndarray, perm: np.ndarray) -> np.ndarray:
    """Classic gradient noise n(x, y) in about [-1, 1] for arrays of coordinates.

    ``perm`` is a permutation of ``0..255``; it selects one of 8 unit gradients per lattice point.
    """
    xi = np.floor(x).astype(np.int64)
    yi = np.floor(y).astype(np.int64)
    xf, yf = x - xi, y - yi
    angles = np.arange(8) * (np.pi / 4)
    grads = np.stack([np.cos(angles), np.sin(angles)], axis=1)

    def gradient_dot(ix: np.ndarray, iy: np.ndarray, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
        g = grads[perm[(perm[ix & 255] + iy) & 255] & 7]
        return g[..., 0] * dx + g[..., 1] * dy

    def fade(t: np.ndarray) -> np.ndarray:
        return t * t * t * (t * (t * 6 - 15) + 10)

    n00 = gradient_dot(xi, yi, xf, yf)
    n10 = gradient_dot(xi + 1, yi, xf - 1, yf)
    n01 = gradient_dot(xi, yi + 1, xf, yf - 1)
    n11 = gradient_dot(xi + 1, yi + 1, xf - 1, yf - 1)
    u, v = fade(xf), fade(yf)
    nx0 = n00 + u * (n10 - n00)
    nx1 = n01 + u * (n11 - n01)
    return np.sqrt(2.0) * (nx0 + v * (nx1 - nx0))


@dataclass(frozen=True)
class Terrain:
    """Soil heights ``heights[row, col]`` in metres over a patch centred on the origin.

    Row 0 lies at ``y = -size_y / 2`` and column 0 at ``x = -size_x / 2`` (MuJoCo's in-memory
    heightfield order), so ``heights[i, j]`` is the height at ``(xs[j], ys[i])``.
    """

    heights: np.ndarray
    size_x: float
    size_y: float

    @property
    def xs(self) -> np.ndarray:
        return np.linspace(-self.size_x / 2, self.size_x / 2, self.heights.shape[1])

    @property
    def ys(self) -> np.ndarray:
        return np.linspace(-self.size_y / 2, self.size_y / 2, self.heights.shape[0])

    def height_at(self, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray | float:
        """Bilinearly interpolated height; points outside the patch are clamped to its edge."""
        nrow, ncol = self.heights.shape
        u = np.clip((np.asarray(x, dtype=float) / self.size_x + 0.5) * (ncol - 1), 0, ncol - 1)
        v = np.clip((np.asarray(y, dtype=float) / self.size_y + 0.5) * (nrow - 1), 0, nrow - 1)
        j0 = np.minimum(np.floor(u).astype(int), ncol - 2)
        i0 = np.minimum(np.floor(v).astype(int), nrow - 2)
        fu, fv = u - j0, v - i0
        h = self.heights
        top = h[i0, j0] * (1 - fu) + h[i0, j0 + 1] * fu
        bottom = h[i0 + 1, j0] * (1 - fu) + h[i0 + 1, j0 + 1] * fu
        result = top * (1 - fv) + bottom * fv
        return float(result) if np.ndim(result) == 0 else result


def generate_terrain(config: TerrainConfig, rng: np.random.Generator) -> Terrain:
    """Sample a new soil patch: ``z = A * sum_o p**o * n(L**o * s * x, L**o * s * y) + z0``.

    A random offset per octave and a random permutation make every seed a different patch.
    """
    perm = rng.permutation(256)
    xs = np.linspace(-config.size_x / 2, config.size_x / 2, config.resolution)
    ys = np.linspace(-config.size_y / 2, config.size_y / 2, config.resolution)
    gx, gy = np.meshgrid(xs, ys)  # rows follow y
    offsets = rng.uniform(0, 256, size=(config.octaves, 2))
    total = np.zeros_like(gx)
    for octave in range(config.octaves):
        frequency = config.scale * config.lacunarity**octave
        total += config.persistence**octave * perlin2d(
            gx * frequency + offsets[octave, 0], gy * frequency + offsets[octave, 1], perm
        )
    return Terrain(config.amplitude * total + config.base_elevation, config.size_x, config.size_y)
