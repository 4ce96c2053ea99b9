"""Deployment helpers: the rolling history, the inference wrapper and frame stacking."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from zeus_ros.learning import ContextHistory, FrameStack, InferenceAgent, ZeusConfig, make_agent
from zeus_ros.learning.synthetic import SyntheticSystem

torch.set_num_threads(1)


def _inference(method: str = 'zeus', seed: int = 0) -> InferenceAgent:
    config = ZeusConfig(method=method, seed=seed, k=3, alpha_psi=1.0, hidden_dim=16,
                        model_hidden_dim=16, context_hidden_dim=16, encoder_hidden_dim=16,
                        transition_dim=8, context_dim=3, device='cpu')
    return InferenceAgent(make_agent(config, SyntheticSystem(k=3).spec()))


def test_history_is_front_padded() -> None:
    """A partial history puts its transitions at the end and masks the front."""
    history = ContextHistory(k=3, obs_shape=(2,), action_dim=1)
    history.push([1.0, 1.0], [0.5], 2.0, [3.0, 3.0])
    arrays = history.arrays()
    assert arrays.hist_mask.tolist() == [False, False, True]
    assert arrays.hist_obs[2].tolist() == [1.0, 1.0] and arrays.hist_reward[2, 0] == 2.0
    assert not arrays.hist_obs[:2].any()
    assert len(history) == 1


def test_history_rolls_and_clears() -> None:
    """Only the newest k transitions stay; clear() starts a new episode."""
    history = ContextHistory(k=2, obs_shape=(1,), action_dim=1)
    for step in range(4):
        history.push([step], [0.0], float(step), [step + 1])
    assert history.arrays().hist_reward[:, 0].tolist() == [2.0, 3.0]
    history.clear()
    assert len(history) == 0 and not history.arrays().hist_mask.any()


def test_history_rejects_bad_shapes() -> None:
    """A wrongly shaped observation is refused with the expected shape."""
    history = ContextHistory(k=2, obs_shape=(3,), action_dim=1)
    with pytest.raises(ValueError, match=r'expected \(3,\)'):
        history.push([0.0, 0.0], [0.0], 0.0, [0.0, 0.0, 0.0])


def test_empty_history_gives_finite_context() -> None:
    """The first step of an episode has a finite context of the right size."""
    inference = _inference()
    context = inference.context(inference.new_history())
    assert context.shape == (3,) and np.isfinite(context).all()


def test_context_matches_agent_encoding() -> None:
    """context() equals encode_context on the same front-padded arrays."""
    inference = _inference()
    history = inference.new_history()
    rng = np.random.default_rng(0)
    for _ in range(2):
        history.push(rng.normal(size=6), rng.uniform(-1, 1, 2), 0.3, rng.normal(size=6))
    a = history.arrays()
    expected = inference.agent.encode_context(a.hist_obs, a.hist_action, a.hist_reward,
                                              a.hist_next_obs, a.hist_mask)
    np.testing.assert_allclose(inference.context(history), expected.numpy())


def test_act_with_noise_stays_in_bounds() -> None:
    """Noisy actions are clipped to the action bounds."""
    inference = _inference()
    context = inference.context(inference.new_history())
    actions = [inference.act(np.zeros(6), context, noise=5.0, rng=np.random.default_rng(i))
               for i in range(20)]
    stacked = np.stack(actions)
    assert np.all(stacked <= 1.0) and np.all(stacked >= -1.0)
    assert np.any(np.abs(stacked) == 1.0)


def test_oracle_needs_true_context() -> None:
    """The oracle refuses to act without the true context and passes it through."""
    inference = _inference('oracle')
    with pytest.raises(ValueError, match='true context'):
        inference.context(inference.new_history())
    assert inference.context(inference.new_history(), [1.25]).tolist() == [1.25]


def test_no_context_policy_has_empty_context() -> None:
    """no_context agents use a zero-length context."""
    inference = _inference('no_context')
    context = inference.context(inference.new_history())
    assert context.shape == (0,)
    assert inference.act(np.zeros(6), context).shape == (2,)


def test_frame_stack_repeats_first_frame() -> None:
    """At an episode start the first frame fills every slot of the stack."""
    stack = FrameStack(num_frames=3)
    frame = np.full((84, 84, 3), 7, dtype=np.uint8)
    out = stack.reset(frame)
    assert out.shape == (9, 84, 84) and out.dtype == np.uint8 and np.all(out == 7)


def test_frame_stack_keeps_newest_last() -> None:
    """Pushing frames shifts older ones out, newest in the last 3 channels."""
    stack = FrameStack(num_frames=3)
    for value in range(5):
        out = stack.push(np.full((84, 84, 3), value, dtype=np.uint8))
    assert [int(out[3 * i, 0, 0]) for i in range(3)] == [2, 3, 4]


def test_frame_stack_resizes_other_sizes() -> None:
    """Frames of another size are resized to 84x84."""
    out = FrameStack().push(np.full((100, 120, 3), 200, dtype=np.uint8))
    assert out.shape == (9, 84, 84) and np.all(out == 200)


def test_frame_stack_rejects_non_rgb() -> None:
    """A frame without 3 colour channels is refused."""
    with pytest.raises(ValueError, match='HxWx3'):
        FrameStack().push(np.zeros((84, 84), dtype=np.uint8))


def _pixel_inference() -> InferenceAgent:
    from zeus_ros.learning import AgentSpec

    config = ZeusConfig(method='zeus', obs_kind='pixels', k=3, alpha_psi=1.0, hidden_dim=16,
                        model_hidden_dim=16, context_hidden_dim=16, transition_dim=8,
                        context_dim=3, num_filters=8, num_conv_layers=2, device='cpu')
    spec = AgentSpec(task='Synthetic', context_names=('mass',), obs_kind='pixels',
                     obs_shape=(9, 84, 84), action_dim=2, action_low=np.full(2, -1.0),
                     action_high=np.full(2, 1.0))
    return InferenceAgent(make_agent(config, spec))


def _episodes(inference: InferenceAgent, steps: int, seed: int = 0) -> list[tuple]:
    """(obs, action, reward, first) per step: two episodes, as a node receives them."""
    rng = np.random.default_rng(seed)

    def frame() -> np.ndarray:
        if inference.obs_kind == 'pixels':
            return rng.integers(0, 256, inference.obs_shape, dtype=np.uint8)
        return rng.normal(size=inference.obs_shape).astype(np.float32)

    return [(frame(), rng.uniform(-1, 1, inference.action_dim).astype(np.float32),
             float(rng.normal()), step in (0, steps // 2)) for step in range(steps)]


def _run(inference: InferenceAgent, steps: list[tuple]) -> tuple[np.ndarray, np.ndarray]:
    """Contexts and deterministic actions of the estimator/policy loop over `steps`."""
    history, contexts, actions, prev = inference.new_history(), [], [], None
    for obs, action, reward, first in steps:
        if first:
            history.clear()
        else:
            history.push(prev[0], prev[1], reward, obs.copy())  # a new array, as decoded
        contexts.append(inference.context(history))
        actions.append(inference.act(obs.copy(), contexts[-1]))
        prev = (obs, action)
    return np.stack(contexts), np.stack(actions)


@pytest.mark.parametrize('kind', ['state', 'pixels'])
def test_reused_features_give_the_contexts_and_actions_of_the_batched_path(kind: str) -> None:
    """reuse_features changes how often phi runs, not what comes out (float rounding aside)."""
    plain = _pixel_inference() if kind == 'pixels' else _inference()
    reusing = InferenceAgent(plain.agent, reuse_features=True)
    steps = _episodes(plain, 12)
    (plain_ctx, plain_act), (ctx, act) = _run(plain, steps), _run(reusing, steps)
    np.testing.assert_allclose(ctx, plain_ctx, atol=1e-5)
    np.testing.assert_allclose(act, plain_act, atol=1e-5)
    # On the same context the action is the same to the bit: one frame through phi either way.
    for (obs, *_), context in zip(steps, plain_ctx, strict=True):
        assert np.array_equal(reusing.act(obs, context), plain.act(obs, context))


def test_each_frame_goes_through_phi_once() -> None:
    """With reuse_features the estimator's history and the policy encode each new frame once."""
    plain = _inference()
    reusing = InferenceAgent(plain.agent, reuse_features=True)
    encoded: list[int] = []
    plain.agent.modules['encoder'].register_forward_hook(
        lambda _module, inputs, _out: encoded.append(inputs[0].shape[0]))
    steps = _episodes(plain, 12)
    _run(reusing, steps)
    assert sum(encoded) == len(steps)  # o_t once: by the history or by act, whichever is first
    encoded.clear()
    _run(plain, steps)
    assert sum(encoded) > 3 * len(steps)


def test_features_of_another_agent_are_not_reused() -> None:
    """A history encoded by one checkpoint gives a swapped-in one its own psi."""
    first = InferenceAgent(_inference().agent, reuse_features=True)
    second = _inference(seed=1)
    history = first.new_history()
    rng = np.random.default_rng(0)
    for _ in range(3):
        history.push(rng.normal(size=6), rng.uniform(-1, 1, 2), 0.3, rng.normal(size=6))
    first.context(history)
    expected = second.context(history)
    assert not np.allclose(first.context(history), expected)
    np.testing.assert_allclose(InferenceAgent(second.agent, reuse_features=True).context(history),
                               expected, atol=1e-5)


@pytest.mark.parametrize('kind', ['state', 'pixels'])
def test_encoding_ahead_leaves_act_only_the_head_and_the_same_action(kind: str) -> None:
    """The policy encodes o while it waits for psi: acting on o then encodes nothing more."""
    plain = _pixel_inference() if kind == 'pixels' else _inference()
    reusing = InferenceAgent(plain.agent, reuse_features=True)
    encoded: list[int] = []
    plain.agent.modules['encoder'].register_forward_hook(
        lambda _module, inputs, _out: encoded.append(inputs[0].shape[0]))
    obs, *_ = _episodes(plain, 1)[0]
    context = np.linspace(-1, 1, plain.context_dim, dtype=np.float32)
    reusing.encode_ahead(obs.copy())  # a decoded copy, as the node holds it
    assert encoded == [1]
    assert np.array_equal(reusing.act(obs.copy(), context), plain.act(obs, context))
    assert encoded == [1, 1]  # the plain agent's own encode; the reusing one took its memo
    reusing.encode_ahead(np.zeros(3, np.float32))  # another shape: nothing, no error
    InferenceAgent(plain.agent).encode_ahead(obs)  # without reuse_features: nothing
    assert encoded == [1, 1]
