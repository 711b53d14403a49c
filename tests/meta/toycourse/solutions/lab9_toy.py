"""Toy lab: two tasks, used to prove the grader cannot be broken or fooled."""

import torch


def double(x):
    """Task 1. x: (N,) float -> 2 * x."""
    return 2 * x


def norms(x):
    """Task 2. x: (N, 3) float -> (N,) Euclidean norms."""
    return torch.linalg.vector_norm(x, dim=-1)
