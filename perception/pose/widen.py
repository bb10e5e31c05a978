"""Function-preserving widening of a trained axis CNN (Net2WiderNet).

Why: the axis CNN's training loss had settled level with its validation error (0.105 rad
against 6.16°): more data of the same kind no longer helped it, a wider network might.
Training a wider one from the upright prior costs hours on a CPU; Net2WiderNet (Chen, Goodfellow
& Shlens, "Net2Net: Accelerating learning via knowledge transfer", ICLR 2016, arXiv:1511.05641)
starts it from the narrow network's function instead.

Each conv block's output channels grow from ``c`` to ``c'``: the first ``c`` are the old ones,
each new one copies a randomly drawn old channel (its conv filter and its BatchNorm's weight,
bias and running statistics), and the next layer splits the weight it gave an old channel among
that channel's copies, so its input sums are unchanged. The split is uneven (random shares that
sum to one): copies with the same filter and the same outgoing weights would get the same
gradients and stay copies forever, while unequal outgoing weights give their filters different
gradients from the first step. New hidden units of the head start at PyTorch's default
initialisation with zero outgoing weights. The widened network computes what the narrow one did
(in eval mode, up to float rounding).
"""

from __future__ import annotations

import torch
from torch import nn

from perception.errors import PerceptionConfigError
from perception.pose.axis_cnn import AxisCNN, AxisCNNConfig


def _conv_blocks(model: AxisCNN) -> list[tuple[nn.Conv2d, nn.BatchNorm2d]]:
    return [(block[0], block[1]) for block in model.features if isinstance(block, nn.Sequential)]


def check_growth(old: AxisCNNConfig, width: int, hidden: int) -> None:
    """Raise :class:`PerceptionConfigError` naming ``width`` or ``hidden`` where it is not an int
    at least the ``old`` network's (a network can only be widened)."""
    for name, value in (("width", width), ("hidden", hidden)):
        if not isinstance(value, int) or isinstance(value, bool) or value < getattr(old, name):
            raise PerceptionConfigError(name, f"can only grow: the network has {getattr(old, name)}, asked for {value!r}")


def widen_axis_cnn(model: AxisCNN, width: int, hidden: int | None = None, seed: int = 0) -> AxisCNN:
    """A copy of ``model`` with ``width`` channels after its first block (and ``hidden`` head
    units; default: the model's) that computes the same function (see the module doc).

    Raises:
        PerceptionConfigError: ``width`` or ``hidden`` smaller than the model's.
    """
    old = model.config
    hidden = old.hidden if hidden is None else hidden
    check_growth(old, width, hidden)
    wide = AxisCNN(AxisCNNConfig(width=width, hidden=hidden, crop_size=old.crop_size, channels=old.channels))
    draw = torch.Generator().manual_seed(seed)
    # source[j]: the old channel that new input channel j copies; share[j]: its part of that
    # channel's outgoing weights (the shares of one old channel's copies sum to one)
    source = torch.arange(old.channels)
    share = torch.ones(old.channels)
    with torch.no_grad():
        for (conv, norm), (wide_conv, wide_norm) in zip(_conv_blocks(model), _conv_blocks(wide)):
            grown = wide_conv.out_channels - conv.out_channels
            out_source = torch.cat([torch.arange(conv.out_channels),
                                    torch.randint(conv.out_channels, (grown,), generator=draw)])
            wide_conv.weight.copy_((conv.weight[:, source] * share[None, :, None, None])[out_source])
            for name in ("weight", "bias", "running_mean", "running_var"):
                getattr(wide_norm, name).copy_(getattr(norm, name)[out_source])
            wide_norm.num_batches_tracked.copy_(norm.num_batches_tracked)
            weights = 0.5 + torch.rand(len(out_source), generator=draw)
            totals = torch.zeros(conv.out_channels).index_add_(0, out_source, weights)
            source, share = out_source, weights / totals[out_source]
        first, last = model.head[0], model.head[2]
        wide_first, wide_last = wide.head[0], wide.head[2]
        wide_first.weight[:old.hidden] = first.weight[:, source] * share[None, :]
        wide_first.bias[:old.hidden] = first.bias
        wide_last.weight.zero_()
        wide_last.weight[:, :old.hidden] = last.weight
        wide_last.bias.copy_(last.bias)
    return wide.train(model.training)


__all__ = ["check_growth", "widen_axis_cnn"]
