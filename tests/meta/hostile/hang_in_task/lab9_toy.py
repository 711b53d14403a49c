import torch


def double(x):
    return 2 * x


def norms(x):
    while True:
        pass
