import pytest
import torch


@pytest.fixture(autouse=True)
def _one_torch_thread():
    """Small networks: one thread is faster than two on a shared 2-core machine (spinning OpenMP threads)."""
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)
