"""How fast retargeting runs, and how long the whole walking set would take.

Goal: the whole data set (every source of params `data.sources` with no
max_takes: 720 Bandai Namco walking clips, ~73 min at 30 fps, and the long takes of the
other sources; originals, whose mirrors are exact joint-space copies) retargets in under
10 minutes on 2 cores. Times a spread of Bandai Namco takes.
Run with `nice -n 10 python benchmarks/retarget_speed.py [--takes N]`; it prints output
frames (at retarget.rate_hz) per second, per core (wall and CPU time) and with the pool,
and the projected whole-set time (from the pool's wall time, and from CPU time, which is
what two free cores would do when the machine is shared).
`--smoke`: 2 takes (unless `--takes` is given), to check that the benchmark still runs.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import re
import sys
import time
from multiprocessing import Pool

from pimann.core.params import DataParams, load_params
from pimann.mocap.clips import Take, select_takes
from pimann.retarget import retarget_clip

GOAL_S = 600.0  # s


def bvh_seconds(take: Take) -> float:
    """Take duration from the BVH header (or the source's rate), without parsing the motion."""
    with open(take.path) as file:
        head = file.read(20000)
    frames = int(re.search(r"Frames:\s*(\d+)", head).group(1))
    frame_time = float(re.search(r"Frame Time:\s*([0-9.eE+-]+)", head).group(1))
    return (frames - 1) * (1.0 / take.rate_hz if take.rate_hz else frame_time)


def with_max_takes(data: DataParams, sample: int | None) -> DataParams:
    """Every source with no max_takes (sample None), or `sample` Bandai Namco takes only."""
    sources = {
        key: dataclasses.replace(source, max_takes=sample)
        for key, source in data.sources.items()
        if sample is None or source.labels == "bandai_namco"
    }
    return dataclasses.replace(data, sources=sources)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--takes", type=int, default=None, help="Bandai takes to time (12)")
    parser.add_argument("--smoke", action="store_true", help="tiny sizes: check that it runs")
    args = parser.parse_args(argv)
    if args.takes is None:
        args.takes = 2 if args.smoke else 12
    params = load_params()
    everything = select_takes(with_max_takes(params.data, None))
    sample = select_takes(with_max_takes(params.data, args.takes))
    rate = params.retarget.rate_hz
    total_frames = sum(int(bvh_seconds(t) * rate) + 1 for t in everything)
    work = functools.partial(retarget_clip, params=params)
    work(sample[0])  # warm-up: model loading, imports

    start, cpu_start = time.perf_counter(), time.process_time()
    results = [clip for take in sample for clip in work(take)]
    serial, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    frames = sum(len(r[1]) for r in results)
    ik_seconds = sum(r[3] for r in results)

    workers = params.retarget.workers
    start = time.perf_counter()
    with Pool(workers) as pool:
        pool.map(work, sample)
    pooled = time.perf_counter() - start

    per_core = frames / serial
    with_pool = frames / pooled
    projected = total_frames / with_pool
    print(f"timed takes: {len(sample)}, frames at {rate:g} Hz: {frames}")
    print(f"retargeting alone (retarget_motion): {1000 * ik_seconds / frames:.2f} ms/frame")
    print(f"per core (retarget + quality):  {per_core:8.1f} frames/s ({1000 / per_core:.2f} ms)")
    cpu_ms = 1000 * cpu / frames
    print(f"per core, CPU time:             {frames / cpu:8.1f} frames/s ({cpu_ms:.2f} ms)")
    print(f"pool of {workers} workers:          {with_pool:8.1f} frames/s")
    minutes = total_frames / rate / 60
    print(f"whole set: {len(everything)} takes, {total_frames} frames ({minutes:.1f} min)")
    print(f"projected whole-set time: {projected:.0f} s ({projected / GOAL_S:.2f} x the goal)")
    # the machine may be shared: CPU time tells what free cores would do
    free = total_frames * cpu / frames / workers
    print(f"projected on {workers} free cores (CPU time): {free:.0f} s ({free / GOAL_S:.2f} x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
