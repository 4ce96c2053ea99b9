"""The GPU path of issue 36: the paper-sized pixel config trains on CUDA (skipped without one).

The paper's pixel runs (params/train/pixels_paper.yaml: 4 convs x 32 filters, 1024-wide heads,
batch 128) do not fit a CPU (0.045 ZeUS updates/s, docs/training.md). Where CI has a GPU this
runs a short smoke run there: a few real updates of ZeusAgent on CUDA from the synthetic
system's pixel batches, the checkpoint written and read back on the CPU (a GPU-trained
checkpoint must deploy on the robot's CPU). `python benchmarks/bench_updates.py --device cuda`
gives the throughput that sizes a paper-scale run (docs/training.md).
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from zeus_ros.learning import load_config, make_agent
from zeus_ros.learning.synthetic import SyntheticSystem

REPO = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(),
                                reason='no CUDA device: the GPU smoke run needs one')


def test_the_paper_pixel_config_trains_on_cuda_and_deploys_on_cpu(tmp_path: Path) -> None:
    from zeus_ros.learning.checkpoint import load_checkpoint, save_checkpoint
    from zeus_ros.learning.inference import InferenceAgent

    config = load_config(REPO / 'params' / 'train' / 'pixels_paper.yaml').replace(device='cuda')
    system = SyntheticSystem(obs_dim=17, action_dim=6, k=config.k, pixels=True)
    agent = make_agent(config, system.spec('Cheetah-Run-v0'))
    assert agent.device.type == 'cuda'
    before = {n: p.detach().clone() for n, p in agent.modules['critic'].named_parameters()}
    for step in range(4):
        metrics = agent.update(system.sample(config.batch_size),
                               system.sample(config.batch_size), step)
    torch.cuda.synchronize()
    assert all(torch.isfinite(torch.as_tensor(v)).all() for v in metrics.values()
               if isinstance(v, (int, float, torch.Tensor)))
    moved = [n for n, p in agent.modules['critic'].named_parameters()
             if not torch.equal(p.detach(), before[n])]
    assert moved, 'four updates on CUDA changed no critic weight'
    path = tmp_path / 'gpu.pt'
    save_checkpoint(path, agent, step=4)
    assert load_checkpoint(path, map_location='cpu').config.obs_kind == 'pixels'
    acting = InferenceAgent.from_checkpoint(path)
    assert acting.obs_kind == 'pixels'
