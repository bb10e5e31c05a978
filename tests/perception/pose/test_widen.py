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


@pytest.mark.parametrize(("width", "hidden"), [(32, 128), (33, 128), (48, 192), (64, 128)])
def test_the_widened_network_computes_what_the_shipped_one_does(shipped, width: int, hidden: int) -> None:
    wide = widen_axis_cnn(shipped, width, hidden).eval()
    assert wide.config == AxisCNNConfig(width=width, hidden=hidden)
    assert sum(p.numel() for p in wide.parameters()) >= sum(p.numel() for p in shipped.parameters())
    x = _crops()
    with torch.no_grad():
        assert torch.allclose(wide(x), shipped(x), atol=2e-5)


def test_the_same_seed_widens_alike_and_another_differently(shipped) -> None:
    a, b, c = (widen_axis_cnn(shipped, 40, seed=s).state_dict() for s in (1, 1, 2))
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert not all(torch.equal(a[k], c[k]) for k in a)


def test_a_training_step_parts_each_copy_from_its_original(shipped) -> None:
    # Copied filters start equal to their originals; after one step none may still equal one,
    # or the extra channels would never learn anything the old ones did not.
    wide = widen_axis_cnn(shipped, 40, seed=3).train()
    first = wide.features[0][0].weight
    old, new = first[:32].detach().clone(), first[32:].detach().clone()
    assert all(any(torch.equal(n, o) for o in old) for n in new)
    target = torch.nn.functional.normalize(torch.randn(32, 3, generator=torch.Generator().manual_seed(1)), dim=-1)
    (1 - (wide(_crops()) * target).sum(-1)).mean().backward()
    with torch.no_grad():
        for p in wide.parameters():
            p -= 1e-2 * p.grad
    old, new = first[:32].detach(), first[32:].detach()
    assert not any(torch.equal(n, o) for n in new for o in old)


@settings(max_examples=25, deadline=None)
@given(st.integers(-4, 40), st.integers(-4, 200))
def test_only_growth_is_accepted_and_a_refusal_names_its_field(width: int, hidden: int) -> None:
    model = load_axis_cnn(SHIPPED_AXIS_CNN)[0]
    if width < 32 or hidden < 128:
        with pytest.raises(PerceptionConfigError, match="width" if width < 32 else "hidden"):
            widen_axis_cnn(model, width, hidden)
    else:
        assert widen_axis_cnn(model, width, hidden).config.width == width


def test_a_non_integer_width_is_refused(shipped) -> None:
    with pytest.raises(PerceptionConfigError, match="width"):
        widen_axis_cnn(shipped, 48.0)  # type: ignore[arg-type]
