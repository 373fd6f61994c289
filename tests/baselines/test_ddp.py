"""Two-process training (gloo, CPU) against one process on the same global batches."""

from __future__ import annotations

import json
import os
import socket

import pytest
import torch
import torch.multiprocessing as mp

from zendar_baselines.cnn.checkpoints import MANIFEST_NAME, load_checkpoint
from zendar_baselines.bench.configs import Schedule
from zendar_baselines.cnn.mask_frames import MaskFrames

from tests.baselines.tiny_mask_model import TinyMaskNet, moving_target_task

N_SAMPLES = 16
SCHEDULE = Schedule(lr=1e-2, batch_size=8, epochs=1)  # global batch: 4 samples per process
SEED = 7


def _data() -> MaskFrames:
    inputs, masks = moving_target_task(N_SAMPLES, seed=3)
    return MaskFrames(inputs, masks)


def _fresh_model() -> TinyMaskNet:
    from zendar_baselines.cnn.training import seed_everything

    seed_everything(0)
    return TinyMaskNet(in_channels=2)


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _worker(rank: int, world_size: int, port: int, out_dir: str, log_dir: str) -> None:
    os.environ.update(
        MASTER_ADDR="127.0.0.1", MASTER_PORT=str(port), WORLD_SIZE=str(world_size), RANK=str(rank), LOCAL_RANK=str(rank)
    )
    os.environ.setdefault("GLOO_SOCKET_IFNAME", "lo")
    torch.set_num_threads(1)
    import zendar_baselines.cnn.training as training

    # Record which process writes checkpoints (rank 0 alone should).
    save = training.save_checkpoint

    def recording_save(path, *args, **kwargs):
        with open(os.path.join(log_dir, f"saved-by-rank-{rank}"), "a") as log:
            log.write(f"{os.path.basename(path)}\n")
        return save(path, *args, **kwargs)

    training.save_checkpoint = recording_save
    result = training.train(_fresh_model(), _data(), SCHEDULE, seed=SEED, out_dir=out_dir, progress=False)
    with open(os.path.join(log_dir, f"result-{rank}.json"), "w") as handle:
        json.dump({"losses": list(result.epoch_losses), "path": str(result.checkpoint_path),
                   "exists": result.checkpoint_path.exists()}, handle)


@pytest.mark.slow  # two spawned interpreters importing torch: ~25 s on 2 cores
def test_two_processes_match_one_process_on_the_global_batch(tmp_path):
    torch.set_num_threads(1)
    from zendar_baselines.cnn.training import train

    single_model = _fresh_model()
    single = train(single_model, _data(), SCHEDULE, seed=SEED, out_dir=tmp_path / "single", progress=False)

    out_dir, log_dir = tmp_path / "ddp", tmp_path / "log"
    log_dir.mkdir()
    mp.spawn(_worker, args=(2, _free_port(), str(out_dir), str(log_dir)), nprocs=2, join=True)

    assert sorted(os.listdir(log_dir)) == ["result-0.json", "result-1.json", "saved-by-rank-0"]
    assert (log_dir / "saved-by-rank-0").read_text() == "epoch-0001.pt\n"
    assert sorted(os.listdir(out_dir)) == sorted(["epoch-0001.pt", MANIFEST_NAME])
    results = [json.loads((log_dir / f"result-{rank}.json").read_text()) for rank in (0, 1)]
    for result in results:
        assert result["exists"] and result["path"] == str(out_dir / "epoch-0001.pt")
        # The epoch loss is the mean over both processes' cells: the single-process figure.
        assert abs(result["losses"][0] - single.epoch_losses[0]) < 1e-6 * abs(single.epoch_losses[0])

    ddp_state = load_checkpoint(out_dir / "epoch-0001.pt")["model_state"]
    initial = _fresh_model().state_dict()
    for name, tensor in single_model.state_dict().items():
        # Two Adam steps of lr 1e-2 moved every weight by ~2e-2; summation order changes ~3e-8, while
        # normalising each process's loss by its own cells instead of the global count changes ~1e-4.
        assert (tensor - initial[name]).abs().min() > 1e-3
        torch.testing.assert_close(ddp_state[name], tensor, rtol=0, atol=2e-6)
