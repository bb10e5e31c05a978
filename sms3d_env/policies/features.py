"""``NormalizedFlatten``: the features extractor of the shipped pick policies."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor


class NormalizedFlatten(BaseFeaturesExtractor):
    """Concatenate a Dict observation's entries (in the space's key order) and standardise them
    with fixed statistics (those of the demonstrations), kept as buffers in the model: a saved
    policy needs no ``VecNormalize`` file beside it.

    Args:
        observation_space: the env's ``Dict`` of ``Box`` spaces.
        mean, std: one entry per flattened observation dimension (std > 0).
    """

    def __init__(self, observation_space: Any, mean: list[float], std: list[float]) -> None:
        dim = sum(int(np.prod(s.shape)) for s in observation_space.spaces.values())
        super().__init__(observation_space, features_dim=dim)
        if len(mean) != dim or len(std) != dim:
            raise ValueError(f"normaliser statistics have {len(mean)}/{len(std)} entries, the "
                             f"observation {dim}")
        if not all(s > 0 for s in std):
            raise ValueError("normaliser std entries must all be > 0")
        self.keys = list(observation_space.spaces)
        self.register_buffer("mean", th.as_tensor(mean, dtype=th.float32))
        self.register_buffer("std", th.as_tensor(std, dtype=th.float32))

    def forward(self, observations: dict[str, th.Tensor]) -> th.Tensor:
        x = th.cat([observations[k].flatten(1) for k in self.keys], dim=1)
        return (x - self.mean) / self.std
