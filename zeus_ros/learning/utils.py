"""Small helpers shared by the learning modules: MLPs, soft updates, seeding, devices."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
import contextlib
import random

import numpy as np
import torch
from torch import nn

__all__ = [
    'eval_mode',
    'mlp',
    'resolve_device',
    'safe_norm',
    'set_seed_everywhere',
    'soft_update_params',
    'weight_init',
]


def mlp(in_dim: int, hidden_dims: Sequence[int], out_dim: int) -> nn.Sequential:
    """ReLU MLP `in -> hidden... -> out` with a linear output (the paper uses ReLU everywhere)."""
    layers: list[nn.Module] = []
    last = in_dim
    for width in hidden_dims:
        layers += [nn.Linear(last, width), nn.ReLU(inplace=True)]
        last = width
    layers.append(nn.Linear(last, out_dim))
    return nn.Sequential(*layers)


def weight_init(module: nn.Module) -> None:
    """Orthogonal init for linear and conv layers (as SAC-AE / drqv2), zero biases."""
    if isinstance(module, nn.Linear):
        nn.init.orthogonal_(module.weight.data)
        if module.bias is not None:
            module.bias.data.fill_(0.0)
    elif isinstance(module, nn.Conv2d | nn.ConvTranspose2d):
        gain = nn.init.calculate_gain('relu')
        nn.init.orthogonal_(module.weight.data, gain)
        if module.bias is not None:
            module.bias.data.fill_(0.0)


def soft_update_params(net: nn.Module, target: nn.Module, tau: float) -> None:
    """Polyak-average `net` into `target`: target <- tau * net + (1 - tau) * target."""
    with torch.no_grad():
        for param, target_param in zip(net.parameters(), target.parameters(), strict=True):
            target_param.data.lerp_(param.data, tau)


def safe_norm(x: torch.Tensor, dim: int = -1) -> torch.Tensor:
    """Euclidean norm along `dim` whose gradient is 0 (not NaN) where the vector is zero."""
    squared = x.pow(2).sum(dim)
    positive = squared > 0
    safe = torch.where(positive, squared, torch.ones_like(squared))
    return torch.where(positive, safe.sqrt(), torch.zeros_like(squared))


def resolve_device(device: str) -> torch.device:
    """Map 'auto' to CUDA when available, else CPU; pass explicit names through."""
    if device == 'auto':
        return torch.device('cuda' if torch.cuda.is_available() else 'cpu')
    return torch.device(device)


def set_seed_everywhere(seed: int) -> None:
    """Seed Python, NumPy and torch (CPU and CUDA) for reproducible runs."""
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)
    if torch.cuda.is_available():
        torch.cuda.manual_seed_all(seed)


@contextlib.contextmanager
def eval_mode(*modules: nn.Module) -> Iterator[None]:
    """Temporarily switch modules to eval mode, restoring their previous mode afterwards."""
    previous = [module.training for module in modules]
    for module in modules:
        module.train(False)
    try:
        yield
    finally:
        for module, mode in zip(modules, previous, strict=True):
            module.train(mode)
