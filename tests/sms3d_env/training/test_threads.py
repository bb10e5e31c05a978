"""``torch_threads`` sets torch's thread count for a block and gives the caller's back."""

from __future__ import annotations

import pytest
import torch

from sms3d_env.training.threads import torch_threads


def test_the_callers_thread_count_comes_back_after_the_block_and_after_an_error():
    before = torch.get_num_threads()
    other = 1 if before != 1 else 2
    with torch_threads(other):
        assert torch.get_num_threads() == other
    assert torch.get_num_threads() == before
    with pytest.raises(RuntimeError, match="inside"):
        with torch_threads(other):
            raise RuntimeError("inside")
    assert torch.get_num_threads() == before
