import numpy as np
import pytest
import torch

LAB_MODULE = "lab9_toy"
TASKS = {1: "double", 2: "norms"}


@pytest.mark.task(1)
@pytest.mark.points(1)
def test_double(impl, device):
    x = torch.arange(5.0, device=device)
    got = impl.double(x)
    assert type(got) is torch.Tensor and got.device == x.device and got.dtype == x.dtype
    torch.testing.assert_close(got, 2 * x)


@pytest.mark.task(2)
@pytest.mark.points(2)
def test_norms(impl, device):
    x = torch.randn(6, 3, generator=torch.Generator().manual_seed(1)).to(device)
    got = impl.norms(x)
    assert type(got) is torch.Tensor, f"expected a plain tensor, got {type(got).__name__}"
    assert got.shape == (6,) and got.dtype == x.dtype and got.device == x.device
    expected = x.double().norm(dim=-1).float()
    torch.testing.assert_close(got, expected)
    np.testing.assert_allclose(got.cpu().numpy(), expected.cpu().numpy(), rtol=1e-6)
