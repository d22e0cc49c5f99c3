"""Whether a run's lanes fit their device's memory once their replays are as full as
``total_steps`` can make them.

The replay is allocated as it fills (``trainer.replay_slots``), so a run starts small
and its peak comes late: at the last growth the old buffers and the new ones are both
alive (``replay.grow`` pads a copy). A lane's peak is therefore its state at the last
allocation, plus the allocation before it, plus a round's staging buffer. The fullest
morphology can hold at most ``total_steps`` transitions, which bounds the last
allocation (the ring's full size for the paper's budgets: 10.5 GiB per humanoid++
lane). A sweep that cannot fit is refused before anything is compiled; ``dry_run``
prints the sum instead.
"""

import os

import jax

from solar_jax.config import ConfigError
from solar_jax.training.trainer import Trainer, replay_slots, tree_bytes

GiB = 2**30


def allocations(trainer: Trainer, total_steps: int) -> list[int]:
    """The replay's slots per morphology, allocation by allocation, for a run whose
    fullest morphology reaches ``total_steps`` transitions at most."""
    config, morphs = trainer.config, trainer.num_morphs
    # Before the last round the fullest morphology holds fewer than total_steps.
    last = replay_slots(config, morphs, max(total_steps - 1, 0))
    ladder = [replay_slots(config, morphs, 0)]
    while ladder[-1] < last:
        ladder.append(min(2 * ladder[-1], last))
    return ladder


def lane_peak_bytes(trainer: Trainer, total_steps: int) -> int:
    """One lane's device bytes at its replay's last growth (module docstring)."""
    ladder = allocations(trainer, total_steps)
    seed = trainer.config.seed
    state = jax.eval_shape(lambda: trainer.init(seed, slots=ladder[-1]))
    peak = tree_bytes(state) + tree_bytes(trainer.staging())
    if len(ladder) > 1:
        before = jax.eval_shape(lambda: trainer.init(seed, slots=ladder[-2]))
        peak += tree_bytes(before.replay)
    return peak


def device_bytes(device) -> int | None:
    """What ``device`` lets this process allocate: the allocator's limit on an
    accelerator, the host's physical memory on a CPU; None when unknown."""
    stats = device.memory_stats() or {}
    if "bytes_limit" in stats:
        return int(stats["bytes_limit"])
    if device.platform == "cpu":
        try:
            return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
        except (ValueError, OSError):
            return None
    return None


def _need(trainer: Trainer, num_lanes: int, devices: list, total_steps: int) -> tuple:
    """(lanes on the busiest device, bytes per lane, bytes it allows or None)."""
    lanes_per_device = -(-num_lanes // len(devices))
    return lanes_per_device, lane_peak_bytes(trainer, total_steps), device_bytes(devices[0])


def memory_plan(trainer: Trainer, num_lanes: int, devices: list, total_steps: int) -> str:
    """One line: the lanes' peak on their busiest device against what it allows."""
    lanes, per_lane, limit = _need(trainer, num_lanes, devices, total_steps)
    allowed = "an unknown amount" if limit is None else f"{limit / GiB:.1f} GiB"
    return (
        f"memory: {lanes} lane(s) on {devices[0]} need {lanes * per_lane / GiB:.2f} GiB at "
        f"the replay's last growth ({per_lane / GiB:.2f} GiB per lane); it allows {allowed}"
    )


def check_fits(trainer: Trainer, num_lanes: int, devices: list, total_steps: int) -> None:
    """Raise a one-line ``ConfigError`` when the lanes cannot fit (module docstring)."""
    lanes, per_lane, limit = _need(trainer, num_lanes, devices, total_steps)
    if limit is None or lanes * per_lane <= limit:
        return
    fit = limit // per_lane
    advice = f"run {fit} lane(s) per device, or lower" if fit else "lower"
    raise ConfigError(
        f"{lanes} lane(s) of {trainer.config.morph} need {lanes * per_lane / GiB:.2f} GiB on "
        f"{devices[0]} when their replays grow to {allocations(trainer, total_steps)[-1]:,} "
        f"slots ({per_lane / GiB:.2f} GiB per lane), more than its {limit / GiB:.2f} GiB: "
        f"{advice} replay_capacity= or total_steps="
    )
