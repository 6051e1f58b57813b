"""Grain with worker processes over a packed dataset (JAX-side input pipeline).

Run: ``python examples/grain_workers.py DATASET_DIR [--split train] [--workers 2]``. Prints one
line per example (its scene's seed and the shape of its video) and then the count.

Grain starts its workers with the *spawn* method: each worker imports this file again as
``__mp_main__``. Everything that builds and iterates the pipeline must therefore sit under
``if __name__ == "__main__":`` (the spawn guard); without it every worker would start the
pipeline again and Python stops with "An attempt has been made to start a new process before the
current process has finished its bootstrapping phase". The source pickles (each worker opens its
own shard readers), so it is built once, here.
"""

from __future__ import annotations

import argparse

import grain.python as grain

from kubric.datasets import load, to_grain


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset_dir")
    parser.add_argument("--split", default="train")
    parser.add_argument("--workers", type=int, default=2, help="Grain worker processes")
    args = parser.parse_args(argv)
    source = load(args.dataset_dir, args.split)
    pipeline = (to_grain(source, shuffle_seed=0)            # a grain.MapDataset
                .to_iter_dataset(grain.ReadOptions(num_threads=1))
                .mp_prefetch(grain.MultiprocessingOptions(num_workers=args.workers)))
    count = 0
    for example in pipeline:
        print(f"seed {int(example['metadata']['seed'])} video {example['video'].shape}")
        count += 1
    print(f"{count} examples through {args.workers} Grain worker processes")
    return 0


if __name__ == "__main__":  # the spawn guard: Grain's workers import this file again
    raise SystemExit(main())
