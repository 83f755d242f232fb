"""Under torchrun each rank keeps its own memories (DDP must not copy rank 0's buffers over
the others'), trains with a parameter its run leaves unused, draws its own noise, and resumes
from its own saved state: two CPU processes on gloo."""

import json
import os
import socket

import pytest
import torch
import torch.multiprocessing as mp
from torch import nn

from rmbench.policies.checkpoint import save_checkpoint, saved_step
from rmbench.training.loop import TrainConfig, rank_seed, train

STEPS, SAVE_EVERY, KILLED_AT = 4, 2, 3


class Killed(Exception):
    """The run stopping between two saves, on every rank at the same step."""


class Walker(nn.Module):
    """A regression that carries a memory across batches (a non-persistent buffer, as Mem-0's
    episode memories are) and noise from its own generator, with a layer it never uses."""

    def __init__(self):
        super().__init__()
        torch.manual_seed(0)
        self.lin = nn.Linear(3, 1)
        self.unused = nn.Linear(2, 2)  # (an M(1) task's end classifier, an ablation's fusion)
        self.register_buffer("seen", torch.zeros(1), persistent=False)
        self.generator = torch.Generator().manual_seed(rank_seed(0))

    def forward(self, batch):
        self.seen += batch["rank"] + 1  # rank 0 adds 1 per step, rank 1 adds 2
        noise = torch.randn(8, 1, generator=self.generator)
        return ((self.lin(batch["x"]) + 0.01 * noise - batch["y"]) ** 2).mean(), {}

    def param_groups(self):
        return [{"name": "all", "params": list(self.parameters()), "lr": 1e-2, "min_lr": 1e-3}]

    def extra_state(self):
        return {"seen": self.seen.clone(), "generator": self.generator.get_state()}

    def load_extra_state(self, state):
        self.seen.copy_(state["seen"])
        self.generator.set_state(state["generator"])


def _rank(rank, world, port, out, report, kill):
    os.environ.update(MASTER_ADDR="127.0.0.1", MASTER_PORT=str(port), RANK=str(rank),
                      WORLD_SIZE=str(world), LOCAL_RANK=str(rank))
    torch.set_num_threads(1)

    def batches(start, rank, world):
        step = start
        while True:
            if kill and step == KILLED_AT:
                raise Killed
            x = torch.randn(8, 3, generator=torch.Generator().manual_seed(1000 * rank + step))
            yield {"x": x, "y": x.sum(1, keepdim=True), "rank": torch.tensor(float(rank))}
            step += 1

    model = Walker()
    try:
        train(model, batches, TrainConfig(steps=STEPS, save_every=SAVE_EVERY, log_every=1),
              out, {"policy": "walker"}, progress=False, write_checkpoint=save_checkpoint,
              checkpoint_step=saved_step)
    except Killed:
        pass
    finally:
        torch.distributed.destroy_process_group()
    with open(f"{report}.{rank}", "w") as f:
        json.dump({"seen": model.seen.item(),
                   "generator": model.generator.get_state().tolist(),
                   "weight": model.lin.weight.flatten().tolist()}, f)


def _run(out, report, kill=False, world=2):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    mp.spawn(_rank, args=(world, port, str(out), str(report), kill), nprocs=world)
    return [json.load(open(f"{report}.{r}")) for r in range(world)]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("ranks")
    whole = _run(root / "whole", root / "whole")
    _run(root / "resumed", root / "killed", kill=True)
    resumed = _run(root / "resumed", root / "resumed")
    return whole, resumed


def test_each_rank_keeps_its_own_memory_and_noise(runs):
    whole, _ = runs
    assert [r["seen"] for r in whole] == [STEPS * 1.0, STEPS * 2.0]
    assert whole[0]["generator"] != whole[1]["generator"]
    assert whole[0]["weight"] == whole[1]["weight"]  # one model, its gradients averaged


def test_each_rank_resumes_from_its_own_state(runs):
    whole, resumed = runs
    assert resumed == whole
