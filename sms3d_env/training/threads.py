"""``torch_threads``: torch's intra-op thread count for one block of work, restored after it."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def torch_threads(n: int) -> Iterator[None]:
    """Run the block with ``torch.set_num_threads(n)`` and give the caller's count back after it,
    also when the block raises (training is sized to the machine's cores; a caller evaluating
    beside it keeps its own setting)."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)
