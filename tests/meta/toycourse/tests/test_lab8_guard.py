import pytest
import torch

LAB_MODULE = "lab8_guard"
TASKS = {1: "scale", 2: "scale_into", 3: "as_view", 4: "total_positive"}


def data(n=6, seed=0):
    return torch.rand(n, generator=torch.Generator().manual_seed(seed)) + 0.5


@pytest.mark.task(1)
@pytest.mark.points(2)
@pytest.mark.parametrize("factor", [2.0, -1.0, 0.5, 3.0, 4.0, 5.0])
def test_scale(impl, factor):
    x = data(seed=int(factor * 10))
    got = impl.scale(x, factor)
    # The reference is taken after the call, from the test's own x: an argument that came
    # back changed would change it too.
    torch.testing.assert_close(got, x * factor)


@pytest.mark.task(2)
@pytest.mark.points(1)
def test_scale_into(impl):
    x, out = data(), torch.full((6,), float("nan"))
    got = impl.scale_into(x, 3.0, out)
    torch.testing.assert_close(out, x * 3.0)
    torch.testing.assert_close(got, out)


def probe_as_view(lab, n):
    x = torch.arange(2.0 * n).reshape(2, n)
    y = lab.as_view(x)
    return {
        "tensor": isinstance(y, torch.Tensor),
        "same": y.data_ptr() == x.data_ptr(),
        "shape": tuple(y.shape),
    }


@pytest.mark.task(3)
@pytest.mark.points(1)
def test_as_view_is_a_view(impl):
    report = impl.probe(probe_as_view, 5)
    assert report["tensor"] and report["shape"] == (10,), report
    assert report["same"], "as_view returned a copy"


@pytest.mark.task(4)
@pytest.mark.points(1)
def test_total_positive(impl):
    x = data()
    torch.testing.assert_close(impl.total_positive(x), x.sum())
    bad = data()
    bad[2] = -1.0
    with pytest.raises(ValueError, match="x"):
        impl.total_positive(bad)
