"""Deployment logic, in one place: the rolling k-step history and the inference wrapper.

Used by the ROS nodes (context_estimator, policy) and by the in-process collector/evaluator, so
that what runs on the robot is exactly what runs in evaluation. The nodes and `zeus collect
--checkpoint` build their agent with `reuse_features=True`: every frame goes through phi once
(one row at a time), however many histories and actions use it, so a live recording and a
collection still agree to the bit. Evaluation keeps the batched path, which agrees up to float
rounding (the batch size changes the kernels' summation order). Never reuse features of an
agent that is being trained: its phi changes with every update.
"""

from __future__ import annotations

from collections import OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from zeus_ros.learning.agent import ZeusAgent
from zeus_ros.learning.checkpoint import DEPLOY_MODULES, load_checkpoint
from zeus_ros.learning.context import HistoryFeatures

__all__ = ['MAX_CONTEXT_LAG', 'ContextHistory', 'HistoryArrays', 'InferenceAgent']

MAX_CONTEXT_LAG = 16
"""The most steps a policy may act behind its context (the policy node's `context_lag`
parameter, `zeus collect --context-lag`): beyond it the context is too old to be worth waiting
for, and the node keeps no older ones."""


@dataclass(slots=True)
class HistoryArrays:
    """One history as arrays, oldest first, missing slots zero-filled at the front."""

    hist_obs: np.ndarray
    """(k, *obs_shape)."""
    hist_action: np.ndarray
    """(k, A) float32."""
    hist_reward: np.ndarray
    """(k, 1) float32."""
    hist_next_obs: np.ndarray
    """(k, *obs_shape)."""
    hist_mask: np.ndarray
    """(k,) bool, True for real transitions."""


class ContextHistory:
    """Rolling history of the last k transitions (o, a, r, o') of the current episode."""

    def __init__(self, k: int, obs_shape: tuple[int, ...], action_dim: int,
                 obs_dtype: np.dtype | type = np.float32) -> None:
        if k < 1:
            raise ValueError(f'k must be >= 1, got {k}')
        self.k = k
        self.obs_shape = tuple(obs_shape)
        self.action_dim = action_dim
        self.obs_dtype = np.dtype(obs_dtype)
        self._items: deque[tuple[np.ndarray, np.ndarray, float, np.ndarray]] = deque(maxlen=k)
        # phi(o) and phi(o') of each transition, filled by features() for one encoder owner.
        self._features: deque[list[torch.Tensor | None]] = deque(maxlen=k)
        self._features_of: object = None

    def clear(self) -> None:
        """Start a new episode (a transition never spans a reset)."""
        self._items.clear()
        self._features.clear()

    def push(self, obs: Any, action: Any, reward: float, next_obs: Any) -> None:
        """Append (o_t, a_t, r_{t+1}, o_{t+1}); the oldest falls out after k."""
        obs_a = np.asarray(obs, dtype=self.obs_dtype)
        next_a = np.asarray(next_obs, dtype=self.obs_dtype)
        act_a = np.asarray(action, dtype=np.float32).reshape(-1)
        for name, value in (('obs', obs_a), ('next_obs', next_a)):
            if value.shape != self.obs_shape:
                raise ValueError(f'{name} has shape {value.shape}, expected {self.obs_shape}')
        if act_a.shape != (self.action_dim,):
            raise ValueError(f'action has {act_a.size} values, expected {self.action_dim}')
        reward_f = float(reward)
        if not np.isfinite(reward_f):
            raise ValueError(f'reward must be finite, got {reward}')
        self._items.append((obs_a.copy(), act_a.copy(), reward_f, next_a.copy()))
        self._features.append([None, None])

    def features(self, encode: Callable[[np.ndarray], torch.Tensor], owner: object
                 ) -> list[tuple[torch.Tensor, torch.Tensor]]:
        """(phi(o), phi(o')) of each held transition, oldest first, by `encode` of one frame.

        A frame is encoded once while it stays in the history; `owner` (the encoder's holder)
        drops what another owner encoded, so a swapped checkpoint never sees old features.
        """
        if owner is not self._features_of:
            for slot in self._features:
                slot[0] = slot[1] = None
            self._features_of = owner
        out = []
        for (obs, _act, _rew, next_obs), slot in zip(self._items, self._features, strict=True):
            feat, next_feat = slot
            if feat is None:
                feat = slot[0] = encode(obs)
            if next_feat is None:
                next_feat = slot[1] = encode(next_obs)
            out.append((feat, next_feat))
        return out

    def transitions(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """hist_action (k, A), hist_reward (k, 1) and hist_mask (k,), front-padded, no frames."""
        k, n = self.k, len(self._items)
        action = np.zeros((k, self.action_dim), dtype=np.float32)
        reward = np.zeros((k, 1), dtype=np.float32)
        mask = np.zeros(k, dtype=bool)
        for slot, (_obs, act, rew, _next) in enumerate(self._items, start=k - n):
            action[slot], reward[slot, 0] = act, rew
        mask[k - n:] = True
        return action, reward, mask

    def arrays(self) -> HistoryArrays:
        """The five hist_* arrays, front-padded like HistoryBatch."""
        k, n = self.k, len(self._items)
        out = HistoryArrays(
            hist_obs=np.zeros((k, *self.obs_shape), dtype=self.obs_dtype),
            hist_action=np.zeros((k, self.action_dim), dtype=np.float32),
            hist_reward=np.zeros((k, 1), dtype=np.float32),
            hist_next_obs=np.zeros((k, *self.obs_shape), dtype=self.obs_dtype),
            hist_mask=np.zeros(k, dtype=bool))
        for slot, (obs, action, reward, next_obs) in enumerate(self._items, start=k - n):
            out.hist_obs[slot] = obs
            out.hist_action[slot] = action
            out.hist_reward[slot, 0] = reward
            out.hist_next_obs[slot] = next_obs
            out.hist_mask[slot] = True
        return out

    def __len__(self) -> int:
        """Number of real transitions held (0..k)."""
        return len(self._items)


class InferenceAgent:
    """A trained agent for deployment: context from a history, clipped actions, no training."""

    FEATURE_MEMO = 8
    """Frames whose phi is kept by content (the estimator's newest o' is the policy's o)."""

    def __init__(self, agent: ZeusAgent, *, reuse_features: bool = False,
                 extra: dict[str, Any] | None = None) -> None:
        """`reuse_features`: encode each frame once (for the live nodes, see the module doc).

        `extra`: what the checkpoint stores beside the networks (the context read-out and
        novelty monitor, learning/readout.py), kept so that nothing decodes the file again.
        """
        self.agent = agent
        self.reuse_features = reuse_features
        self.extra: dict[str, Any] = dict(extra or {})
        self._low = np.asarray(agent.spec.action_low, dtype=np.float32)
        self._high = np.asarray(agent.spec.action_high, dtype=np.float32)
        self._memo: OrderedDict[bytes, torch.Tensor] = OrderedDict()

    @classmethod
    def from_checkpoint(cls, path: str | Path, *, expect_task: str | None = None,
                        expect_obs_kind: str | None = None,
                        device: str | torch.device = 'cpu',
                        reuse_features: bool = False,
                        data: bytes | None = None, sha256: str | None = None,
                        expect_sha256: str | None = None) -> InferenceAgent:
        """Load and validate a checkpoint (CheckpointError on any mismatch).

        `data`: the file's bytes when the caller has read them already, `sha256` their digest
        when it has it too, `expect_sha256` a pin (load_checkpoint: a file whose recorded
        sha256 differs is refused).
        """
        loaded = load_checkpoint(path, map_location=device, expect_task=expect_task,
                                 expect_obs_kind=expect_obs_kind, load_optimizers=False,
                                 data=data, sha256=sha256, expect_sha256=expect_sha256)
        return cls(loaded.agent, reuse_features=reuse_features, extra=loaded.extra)

    def drop_training_modules(self) -> None:
        """Free what acting never uses: critics, target copies, decoder, models, optimizers.

        For a deployed node (measured: pixel node -25 MiB); the agent can no longer be trained
        or saved whole.
        """
        for name in [name for name in self.agent.modules if name not in DEPLOY_MODULES]:
            del self.agent.modules[name]
        self.agent.optimizers.clear()

    # ---------------------------------------------------------------- what nodes need to know
    @property
    def k(self) -> int:
        """History length."""
        return self.agent.config.k

    @property
    def method(self) -> str:
        """Training method (oracle needs the true context at deployment)."""
        return self.agent.method

    @property
    def needs_true_context(self) -> bool:
        """True for oracle: `context()` then requires the true context."""
        return self.agent.objective.context_source == 'true'

    @property
    def obs_kind(self) -> str:
        """'state' or 'pixels'."""
        return self.agent.spec.obs_kind

    @property
    def obs_shape(self) -> tuple[int, ...]:
        """Observation shape the agent expects."""
        return self.agent.spec.obs_shape

    @property
    def obs_dtype(self) -> np.dtype:
        """uint8 for stacked frames, float32 for state vectors."""
        return np.dtype(np.uint8 if self.obs_kind == 'pixels' else np.float32)

    @property
    def action_dim(self) -> int:
        """Number of action dimensions."""
        return self.agent.spec.action_dim

    @property
    def action_low(self) -> np.ndarray:
        """Lower action bounds."""
        return self._low.copy()

    @property
    def action_high(self) -> np.ndarray:
        """Upper action bounds."""
        return self._high.copy()

    @property
    def task(self) -> str:
        """Task name the agent was trained on."""
        return self.agent.spec.task

    @property
    def context_names(self) -> tuple[str, ...]:
        """Names of the true context parameters."""
        return self.agent.spec.context_names

    @property
    def context_dim(self) -> int:
        """Size of the context vector the policy consumes (0 for no_context)."""
        return self.agent.context_dim

    def new_history(self) -> ContextHistory:
        """An empty history with this agent's k, shapes and dtype."""
        return ContextHistory(self.k, self.obs_shape, self.action_dim, self.obs_dtype)

    # ---------------------------------------------------------------- inference
    def context(self, history: ContextHistory, true_context: Any = None) -> np.ndarray:
        """The context vector for the current step: psi(H), or the true context for oracle.

        An empty history (first step of an episode) is valid and gives a finite context.
        """
        if self.needs_true_context:
            if true_context is None:
                raise ValueError('the oracle policy needs the true context at deployment '
                                 f'({", ".join(self.context_names)})')
            values = np.asarray(true_context, dtype=np.float32).reshape(-1)
            if values.shape != (self.context_dim,):
                raise ValueError(f'true_context has {values.size} values, expected '
                                 f'{self.context_dim} ({", ".join(self.context_names)})')
            return values
        if self.context_dim == 0:
            return np.zeros(0, dtype=np.float32)
        if history.k != self.k:
            raise ValueError(f'history has k={history.k}, the agent uses k={self.k}')
        if self.reuse_features and 'psi' in self.agent.modules:
            return self._context_from_features(history)
        arrays = history.arrays()
        out = self.agent.encode_context(arrays.hist_obs, arrays.hist_action, arrays.hist_reward,
                                        arrays.hist_next_obs, arrays.hist_mask)
        return out.cpu().numpy().astype(np.float32)

    def encode_ahead(self, obs: Any) -> None:
        """Encode o now and keep phi(o), so that acting on o later runs only the actor's head.

        Why: a policy in its own process gets o_k together with the estimator and waits for
        psi_k; encoding o_k while it waits takes phi (the conv encoder, milliseconds on a CPU)
        off the step's critical path, the two processes working on different cores. Without
        reuse_features, or for an observation of another shape, it does nothing.
        """
        if self.reuse_features and np.shape(obs) == self.obs_shape:
            self._phi(np.asarray(obs))

    def act(self, obs: Any, context: Any, deterministic: bool = True, noise: float = 0.0,
            rng: np.random.Generator | None = None) -> np.ndarray:
        """Action in task bounds; optional Gaussian noise with std noise * half the range."""
        if self.reuse_features:
            action = self._act_on_features(obs, context, deterministic)
        else:
            action = self.agent.act(obs, context, deterministic=deterministic)
        if noise > 0.0:
            rng = np.random.default_rng() if rng is None else rng
            half_range = (self._high - self._low) / 2
            action = action + noise * half_range * rng.standard_normal(action.shape)
        return np.clip(action, self._low, self._high).astype(np.float32)

    # ---------------------------------------------------------------- each frame encoded once
    @torch.no_grad()
    def _phi(self, obs: np.ndarray) -> torch.Tensor:
        """The phi of one observation (F,), from the memo when these very values were encoded."""
        frame = np.ascontiguousarray(obs, dtype=self.obs_dtype)
        key = frame.tobytes()
        feature = self._memo.get(key)
        if feature is None:
            agent = self.agent
            feature = agent.modules['encoder'](agent._as_tensor(frame[None]))[0]
            self._memo[key] = feature
            if len(self._memo) > self.FEATURE_MEMO:
                self._memo.popitem(last=False)
        else:
            self._memo.move_to_end(key)
        return feature

    @torch.no_grad()
    def _context_from_features(self, history: ContextHistory) -> np.ndarray:
        """psi(H) as ZeusAgent.encode_context computes it, on phi of each frame encoded once."""
        agent, k = self.agent, self.k
        pairs = history.features(self._phi, self)
        action, reward, mask = history.transitions()
        # Missing slots stay zero: psi ignores them whatever they hold (context.aggregate).
        feat = torch.zeros(1, k, agent.config.feature_dim, device=agent.device)
        next_feat = torch.zeros_like(feat)
        if pairs:
            feat[0, k - len(pairs):] = torch.stack([p[0] for p in pairs])
            next_feat[0, k - len(pairs):] = torch.stack([p[1] for p in pairs])
        history_features = HistoryFeatures(
            feat=feat, action=agent.normalize_action(agent._as_tensor(action[None])),
            reward=agent._as_tensor(reward[None]), next_feat=next_feat,
            mask=agent._as_tensor(mask[None]))
        return agent.modules['psi'](history_features)[0].cpu().numpy().astype(np.float32)

    @torch.no_grad()
    def _act_on_features(self, obs: Any, context: Any, deterministic: bool) -> np.ndarray:
        """ZeusAgent.act for one observation on its memoised phi; batches go to agent.act."""
        agent = self.agent
        frame = np.asarray(obs)
        values = None if context is None else np.asarray(context, np.float32).reshape(-1)
        if frame.shape != self.obs_shape or values is None or values.size != self.context_dim:
            return agent.act(obs, context, deterministic=deterministic)  # its checks and errors
        action = agent.act_on_features(self._phi(frame)[None], agent._as_tensor(values[None]),
                                       deterministic)
        return action[0].cpu().numpy()
