"""Frame stacking for pixel observations: HxWx3 uint8 frames -> (3*N, 84, 84) uint8 stacks."""

from __future__ import annotations

from collections import deque

import numpy as np
import torch
import torch.nn.functional as F  # noqa: N812

__all__ = ['FrameStack', 'to_chw']


def to_chw(frame: np.ndarray, size: int = 84) -> np.ndarray:
    """One HxWx3 uint8 frame -> (3, size, size) uint8, area-resized when it is not size x size."""
    frame = np.asarray(frame)
    if frame.ndim != 3 or frame.shape[2] != 3:
        raise ValueError(f'expected an HxWx3 RGB frame, got shape {frame.shape}')
    if frame.dtype != np.uint8:
        raise ValueError(f'expected a uint8 frame, got {frame.dtype}')
    chw = np.ascontiguousarray(frame.transpose(2, 0, 1))
    if chw.shape[1:] != (size, size):
        resized = F.interpolate(torch.from_numpy(chw).float().unsqueeze(0), size=(size, size),
                                mode='area')
        chw = resized.squeeze(0).round().clamp(0, 255).to(torch.uint8).numpy()
    return chw


class FrameStack:
    """The last `num_frames` frames of an episode, channels first, oldest first.

    At an episode start (after `clear()` or on the first push) the first frame is repeated, as
    SAC-AE / mtenv do, so every stack has the full channel count.
    """

    def __init__(self, num_frames: int = 3, size: int = 84) -> None:
        if num_frames < 1:
            raise ValueError(f'num_frames must be >= 1, got {num_frames}')
        self.num_frames = num_frames
        self.size = size
        self._frames: deque[np.ndarray] = deque(maxlen=num_frames)

    @property
    def shape(self) -> tuple[int, int, int]:
        """Shape of a stack: (3 * num_frames, size, size)."""
        return (3 * self.num_frames, self.size, self.size)

    def clear(self) -> None:
        """Forget the episode; the next push starts a new stack."""
        self._frames.clear()

    def reset(self, frame: np.ndarray) -> np.ndarray:
        """Start an episode with `frame` repeated num_frames times; return the stack."""
        self.clear()
        return self.push(frame)

    def push(self, frame: np.ndarray) -> np.ndarray:
        """Append a frame (repeating it if the stack is empty) and return the new stack."""
        chw = to_chw(frame, self.size)
        if not self._frames:
            self._frames.extend([chw] * self.num_frames)
        else:
            self._frames.append(chw)
        return self.stack()

    def stack(self) -> np.ndarray:
        """Current (3 * num_frames, size, size) uint8 stack (a copy)."""
        if not self._frames:
            raise RuntimeError('FrameStack is empty: push or reset a frame first')
        return np.concatenate(list(self._frames), axis=0)

    def __len__(self) -> int:
        """Frames held (num_frames once started, 0 after clear)."""
        return len(self._frames)
