import torch


def double(x):
    return 2 * x


def norms(x):
    hog = torch.ones(40 * 2**30 // 4)  # 40 GiB
    return hog[: len(x)]
