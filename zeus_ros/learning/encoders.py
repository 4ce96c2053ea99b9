"""phi, the observation encoders, and the SAC-AE pixel decoder."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

__all__ = ['PixelDecoder', 'PixelEncoder', 'StateEncoder', 'conv_output_size']


def conv_output_size(image_size: int, num_layers: int) -> int:
    """Side length after the encoder's convs: one 3x3 stride 2, then 3x3 stride 1 layers."""
    size = (image_size - 3) // 2 + 1
    return size - 2 * (num_layers - 1)


class PixelEncoder(nn.Module):
    """SAC-AE conv encoder: stacked uint8 frames -> 50-d LayerNorm + tanh features."""

    def __init__(self, obs_shape: Sequence[int], feature_dim: int = 50, num_layers: int = 4,
                 num_filters: int = 32) -> None:
        super().__init__()
        channels, height, width = obs_shape
        if height != width:
            raise ValueError(f'pixel encoder expects square frames, got {height}x{width}')
        layers: list[nn.Module] = [nn.Conv2d(channels, num_filters, 3, stride=2)]
        for _ in range(num_layers - 1):
            layers += [nn.ReLU(inplace=True), nn.Conv2d(num_filters, num_filters, 3, stride=1)]
        layers.append(nn.ReLU(inplace=True))
        self.convs = nn.Sequential(*layers)
        side = conv_output_size(height, num_layers)
        self.fc = nn.Linear(num_filters * side * side, feature_dim)
        self.norm = nn.LayerNorm(feature_dim)
        self.feature_dim = feature_dim

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """Encode (N, C, H, W) frames with values in [0, 255] (uint8 or float)."""
        h = self.convs(obs.float() / 255.0)
        return torch.tanh(self.norm(self.fc(h.flatten(1))))


class StateEncoder(nn.Module):
    """MLP encoder for state vectors, normalised with the dataset mean / std it stores."""

    obs_mean: torch.Tensor
    """(obs_dim,) buffer: the dataset mean of the state vectors."""
    obs_std: torch.Tensor
    """(obs_dim,) buffer: their standard deviation."""

    def __init__(self, obs_dim: int, feature_dim: int = 50, hidden_dim: int = 256,
                 obs_mean: Sequence[float] | None = None,
                 obs_std: Sequence[float] | None = None) -> None:
        super().__init__()
        mean = torch.zeros(obs_dim) if obs_mean is None else torch.as_tensor(obs_mean)
        std = torch.ones(obs_dim) if obs_std is None else torch.as_tensor(obs_std)
        self.register_buffer('obs_mean', mean.float().reshape(obs_dim))
        self.register_buffer('obs_std', std.float().reshape(obs_dim))
        self.trunk = nn.Sequential(
            nn.Linear(obs_dim, hidden_dim), nn.ReLU(inplace=True),
            nn.Linear(hidden_dim, feature_dim))
        self.norm = nn.LayerNorm(feature_dim)
        self.feature_dim = feature_dim

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """Encode (N, D) raw state vectors."""
        x = (obs.float() - self.obs_mean) / self.obs_std
        return torch.tanh(self.norm(self.trunk(x)))


class PixelDecoder(nn.Module):
    """SAC-AE decoder: features -> reconstructed frames, centred in [-0.5, 0.5]."""

    def __init__(self, obs_shape: Sequence[int], feature_dim: int = 50, num_layers: int = 4,
                 num_filters: int = 32) -> None:
        super().__init__()
        channels, height, _ = obs_shape
        self.num_filters = num_filters
        self.side = conv_output_size(height, num_layers)
        self.fc = nn.Linear(feature_dim, num_filters * self.side * self.side)
        layers: list[nn.Module] = []
        for _ in range(num_layers - 1):
            layers += [nn.ConvTranspose2d(num_filters, num_filters, 3, stride=1),
                       nn.ReLU(inplace=True)]
        output_padding = (height - 3) % 2
        layers.append(nn.ConvTranspose2d(num_filters, channels, 3, stride=2,
                                         output_padding=output_padding))
        self.deconvs = nn.Sequential(*layers)

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """Reconstruct (N, C, H, W) frames from (N, feature_dim) features."""
        h = torch.relu(self.fc(features)).view(-1, self.num_filters, self.side, self.side)
        return self.deconvs(h)
