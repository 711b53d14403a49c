import pytest
import torch

LAB_MODULE = "lab8_guard"
TASKS = {3: "as_view"}


def probe_hidden_view(lab):
    secret_shape_of_the_hidden_test = (3, 7)
    x = torch.arange(21.0).reshape(secret_shape_of_the_hidden_test)[:2]
    y = lab.as_view(x.contiguous())
    return bool(y.shape == (14,))


@pytest.mark.task(3)
@pytest.mark.points(1)
def test_as_view_hidden(impl):
    assert impl.probe(probe_hidden_view), "as_view: wrong shape on the hidden input"
