"""Training throughput of the inverse model (samples/s), on the CPU and on CUDA where available.

    python bench/bench_train.py [--db URL] [--batch-size 256] [--steps 40] [--threads N]

Without --db it trains on synthetic samples (random 4 cm chains, their P-data from Top, random
next states and curves): the cost per sample does not depend on what the samples mean. Each
measured step is a full training step (augmentation, preprocessing, forward, backward, Adam).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from twisted.model.config import NetConfig, TrainConfig
from twisted.model.data import TransitionData, load_transitions, transitions_from_samples
from twisted.model.train import Trainer
from twisted.sim import sample_curve
from twisted.topology import PData, top


def synthetic(n: int, seed: int = 0) -> TransitionData:
    rng = np.random.default_rng(seed)
    points, p_from, p_to, curves = [], [], [], []
    for _ in range(n):
        angles = np.cumsum(rng.normal(0, 0.5, 21)) + rng.uniform(0, 2 * np.pi)
        xy = np.concatenate(
            [[[0.0, 0.0]], np.cumsum(0.04 * np.stack([np.cos(angles), np.sin(angles)], 1), 0)]
        )
        pts = np.concatenate([xy, 0.01 + rng.uniform(0, 0.02, (22, 1))], axis=1)
        p = top(pts)
        if p.cross > 4:
            continue
        k = p.cross + 1
        points.append(pts)
        p_from.append(p)
        p_to.append(PData.from_crossings([(2 * i + 1, 2 * i + 2, 1) for i in range(k)]))
        curves.append(sample_curve(rng).to_array())
    return transitions_from_samples(np.stack(points), np.stack(curves), p_from, p_to)


def measure(data: TransitionData, device: str, batch_size: int, steps: int, net: NetConfig) -> float:
    trainer = Trainer(data, TrainConfig(batch_size=batch_size, net=net), device)
    order = trainer.epoch_order(0)

    def run(k: int) -> None:
        for b in range(k):
            i = b % trainer.batches_per_epoch
            index = order[i * batch_size : (i + 1) * batch_size]
            trainer.step(index, trainer.batch_variants(0, i, len(index)))
        if device.startswith("cuda"):
            torch.cuda.synchronize()

    run(3)  # warm-up
    t0 = time.perf_counter()
    run(steps)
    return steps * batch_size / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--db", help="train on this store's transitions instead of synthetic ones")
    ap.add_argument("--batch-size", type=int, nargs="+", default=[256])
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's choice)")
    ap.add_argument("--samples", type=int, default=4096)
    args = ap.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    if args.db:
        from twisted.store import open_store

        data = load_transitions(open_store(args.db))
        source = f"{len(data)} transitions from {args.db}"
    else:
        data = synthetic(args.samples)
        source = f"{len(data)} synthetic samples"
    net = NetConfig()
    params = sum(p.numel() for p in Trainer(data, TrainConfig(net=net)).net.parameters())
    print(f"data: {source}; network {net} ({params} parameters); torch {torch.__version__}")
    devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    if not torch.cuda.is_available():
        print("cuda: not available here (no GPU visible to torch)")
    for device in devices:
        name = torch.cuda.get_device_name() if device == "cuda" else f"cpu, {torch.get_num_threads()} threads"
        for bs in args.batch_size:
            rate = measure(data, device, bs, args.steps, net)
            print(f"{device:5s} ({name}) batch {bs:5d}: {rate:10.0f} samples/s")


if __name__ == "__main__":
    main()
