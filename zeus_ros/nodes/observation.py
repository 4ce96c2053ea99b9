"""Turn observation messages into the arrays a checkpoint expects (state vector or frame stack)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from zeus_ros.learning.frames import FrameStack
from zeus_ros.nodes.common import array_from_image

if TYPE_CHECKING:
    from sensor_msgs.msg import Image
    from zeus_msgs.msg import StateVector

__all__ = ['ObservationDecoder']


class ObservationDecoder:
    """Decodes o_k per step; keeps the frame stack of the running episode for pixel agents."""

    def __init__(self, obs_kind: str, obs_shape: tuple[int, ...], image_size: int = 84) -> None:
        self.obs_kind = obs_kind
        self.obs_shape = tuple(obs_shape)
        self.image_size = image_size
        self.frames = FrameStack(num_frames=obs_shape[0] // 3, size=image_size) \
            if obs_kind == 'pixels' else None

    def validate(self, msg: StateVector | Image) -> np.ndarray:
        """Check one message and return its raw array; ValueError says what is wrong."""
        if self.obs_kind == 'pixels':
            return array_from_image(msg, (self.image_size, self.image_size))
        data = np.asarray(msg.data, dtype=np.float32)
        if data.shape != self.obs_shape:
            raise ValueError(f'state vector has {data.size} values, the checkpoint expects '
                             f'{self.obs_shape[0]}')
        if not np.all(np.isfinite(data)):
            raise ValueError('state vector holds NaN or Inf')
        return data

    def observation(self, raw: np.ndarray, first: bool) -> np.ndarray:
        """The agent's observation for this step (a new frame stack at an episode start)."""
        if self.frames is None:
            return raw
        return self.frames.reset(raw) if first else self.frames.push(raw)
