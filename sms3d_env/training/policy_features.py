"""The name under which SB3 pickled the shipped policy's features extractor, and models trained
before 0.2.0: SB3's own ``PPO.load`` imports ``NormalizedFlatten`` from here. The class lives in
:mod:`sms3d_env.policies.features`."""

from sms3d_env.policies.features import NormalizedFlatten

__all__ = ["NormalizedFlatten"]
