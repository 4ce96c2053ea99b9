"""DrQ's random-shift augmentation of pixel observations (Kostrikov et al. 2020).

One place for it: the RL update (`augment_shift`, agent.py) and the pixel student's regression
(offline/training/distill.py) both shift frames with `random_shift`.
"""

from __future__ import annotations

import numpy as np
import torch

__all__ = ['random_shift']


def random_shift(stacks: torch.Tensor, pad: int, rng: np.random.Generator) -> torch.Tensor:
    """One random shift of up to `pad` pixels per window (E, N, C, H, W): the camera moves.

    The same as replicate-padding every window by `pad` and cropping H x W at a random offset
    (DrQ), done by clamped indexing so uint8 frames stay uint8 (a quarter of the float
    memory, no conversion): a shift of the whole window, not of each frame, keeps the
    window's frames aligned as the camera saw them. `pad <= 0` returns the input itself.
    """
    if pad <= 0:
        return stacks
    e, n, c, h, w = stacks.shape
    dx, dy = rng.integers(0, 2 * pad + 1, size=(2, e))
    device = stacks.device
    rows = (torch.arange(h, device=device)[None] + torch.as_tensor(dy, device=device)[:, None]
            - pad).clamp_(0, h - 1)
    cols = (torch.arange(w, device=device)[None] + torch.as_tensor(dx, device=device)[:, None]
            - pad).clamp_(0, w - 1)
    flat = stacks.reshape(e, n * c, h, w)
    index = torch.arange(e, device=device)[:, None, None]
    # Advanced indices around a slice put their dims first: (E, H, W, N*C).
    out = flat[index, :, rows[:, :, None], cols[:, None, :]]
    return out.permute(0, 3, 1, 2).reshape(e, n, c, h, w)
