"""Widening a trained axis CNN: the same function, copies that can part, refusals to narrow."""

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from perception.errors import PerceptionConfigError
from perception.pose.axis_cnn import SHIPPED_AXIS_CNN, AxisCNNConfig, load_axis_cnn
from perception.pose.depth_crops import CROP_CHANNELS, CROP_SIZE
from perception.pose.widen import widen_axis_cnn


def _crops(n: int = 32) -> torch.Tensor:
    """Crops with the channels' ranges: a mask, relative depth in [-1, 1], validity, grey, masked depth."""
    draw = torch.Generator().manual_seed(0)
    mask = (torch.rand(n, 1, CROP_SIZE, CROP_SIZE, generator=draw) > 0.5).float()
    depth = torch.rand(n, 1, CROP_SIZE, CROP_SIZE, generator=draw) * 2 - 1
    valid = (torch.rand(n, 1, CROP_SIZE, CROP_SIZE, generator=draw) > 0.1).float()
    grey = torch.rand(n, 1, CROP_SIZE, CROP_SIZE, generator=draw) - 0.5
    crops = torch.cat([mask, depth * valid, valid, grey, depth * valid * mask], 1)
    assert crops.shape[1] == CROP_CHANNELS
    return crops


@pytest.fixture(scope="module")
def shipped():
    return load_axis_cnn(SHIPPED_AXIS_CNN)[0]


@pytest.mark.parametrize(("more_width", "more_hidden"), [(0, 0), (1, 0), (16, 64), (32, 0)])
def test_the_widened_network_computes_what_the_shipped_one_does(shipped, more_width: int, more_hidden: int) -> None:
    width, hidden = shipped.config.width + more_width, shipped.config.hidden + more_hidden
    wide = widen_axis_cnn(shipped, width, hidden).eval()
    assert wide.config == AxisCNNConfig(width=width, hidden=hidden)
    assert sum(p.numel() for p in wide.parameters()) >= sum(p.numel() for p in shipped.parameters())
    x = _crops()
    with torch.no_grad():
        assert torch.allclose(wide(x), shipped(x), atol=2e-5)


def test_the_same_seed_widens_alike_and_another_differently(shipped) -> None:
    a, b, c = (widen_axis_cnn(shipped, shipped.config.width + 8, seed=s).state_dict() for s in (1, 1, 2))
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert not all(torch.equal(a[k], c[k]) for k in a)


def test_a_training_step_parts_each_copy_from_its_original(shipped) -> None:
    # Copied filters start equal to their originals; after one step none may still equal one,
    # or the extra channels would never learn anything the old ones did not.
    narrow = shipped.config.width
    wide = widen_axis_cnn(shipped, narrow + 8, seed=3).train()
    first = wide.features[0][0].weight
    old, new = first[:narrow].detach().clone(), first[narrow:].detach().clone()
    assert all(any(torch.equal(n, o) for o in old) for n in new)
    target = torch.nn.functional.normalize(torch.randn(32, 3, generator=torch.Generator().manual_seed(1)), dim=-1)
    (1 - (wide(_crops()) * target).sum(-1)).mean().backward()
    with torch.no_grad():
        for p in wide.parameters():
            p -= 1e-2 * p.grad
    old, new = first[:narrow].detach(), first[narrow:].detach()
    assert not any(torch.equal(n, o) for n in new for o in old)


@settings(max_examples=25, deadline=None)
@given(st.integers(-60, 8), st.integers(-200, 40))
def test_only_growth_is_accepted_and_a_refusal_names_its_field(more_width: int, more_hidden: int) -> None:
    model = load_axis_cnn(SHIPPED_AXIS_CNN)[0]
    width, hidden = model.config.width + more_width, model.config.hidden + more_hidden
    if more_width < 0 or more_hidden < 0:
        with pytest.raises(PerceptionConfigError, match="width" if more_width < 0 else "hidden"):
            widen_axis_cnn(model, width, hidden)
    else:
        assert widen_axis_cnn(model, width, hidden).config.width == width


def test_a_non_integer_width_is_refused(shipped) -> None:
    with pytest.raises(PerceptionConfigError, match="width"):
        widen_axis_cnn(shipped, float(shipped.config.width + 8))  # type: ignore[arg-type]
