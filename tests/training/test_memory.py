"""A run's memory at its replay's last growth, and the refusal of lanes that cannot fit
(``solar_jax.training.memory``), on the tiny run (``tests/tiny.py``: the replay starts
at 1,024 slots and grows to 2,048 past 624 stored)."""

import dataclasses

import jax
import pytest

from solar_jax.config import ConfigError
from solar_jax.train import main
from solar_jax.training import memory
from solar_jax.training.memory import allocations, check_fits, lane_peak_bytes, memory_plan
from solar_jax.training.trainer import replay_slots, tree_bytes
from tests.tiny import ARGS


@dataclasses.dataclass
class Device:
    """A stand-in accelerator whose allocator allows ``limit`` bytes."""

    limit: int
    platform: str = "gpu"

    def memory_stats(self) -> dict:
        return {"bytes_limit": self.limit}

    def __str__(self) -> str:
        return "cuda:0"


@pytest.mark.parametrize("total", [300, 900, 5000, 3_000_000])
def test_allocations_are_the_ones_a_run_of_that_length_makes(tiny_trainer, total):
    config, morphs = tiny_trainer.config, tiny_trainer.num_morphs
    # Every fill level a run of ``total`` steps can start a round at, and its allocation.
    reached = sorted({replay_slots(config, morphs, size) for size in range(0, total, 7)})
    reached = sorted(set(reached) | {replay_slots(config, morphs, total - 1)})
    assert allocations(tiny_trainer, total) == reached
    assert allocations(tiny_trainer, 900) == [1024, 2048]
    assert allocations(tiny_trainer, 3_000_000)[-1] == tiny_trainer.capacity == 1_000_000


def test_the_peak_holds_the_last_allocation_and_the_one_it_grew_from(tiny_trainer):
    def state(slots):
        return jax.eval_shape(lambda: tiny_trainer.init(0, slots=slots))

    staging = tree_bytes(tiny_trainer.staging())
    assert lane_peak_bytes(tiny_trainer, 300) == tree_bytes(state(1024)) + staging
    grown = tree_bytes(state(2048)) + tree_bytes(state(1024).replay) + staging
    assert lane_peak_bytes(tiny_trainer, 900) == grown


def test_lanes_that_cannot_fit_are_refused_in_one_line(tiny_trainer):
    per_lane = lane_peak_bytes(tiny_trainer, 900)
    device = Device(limit=int(2.5 * per_lane))
    check_fits(tiny_trainer, 2, [device], 900)
    check_fits(tiny_trainer, 4, [device, Device(device.limit)], 900)  # 2 per device
    with pytest.raises(ConfigError) as refused:
        check_fits(tiny_trainer, 4, [device], 900)
    message = str(refused.value)
    assert "4 lane(s)" in message and "cuda:0" in message and "2,048 slots" in message
    assert "run 2 lane(s) per device" in message and "\n" not in message
    assert "4 lane(s) on cuda:0 need" in memory_plan(tiny_trainer, 4, [device], 900)


def test_a_run_too_large_for_the_host_is_one_error_line(monkeypatch, capsys):
    monkeypatch.setattr(memory, "device_bytes", lambda device: 1 << 20)
    assert main([*ARGS, "total_steps=900"]) == 2
    err = capsys.readouterr().err
    assert "1 lane(s) of" in err and "more than its 0.00 GiB" in err and err.count("\n") == 1
    assert "lower replay_capacity= or total_steps=" in err


def test_a_cpu_allows_its_physical_memory():
    cpu = jax.devices("cpu")[0]
    assert memory.device_bytes(cpu) > 1 << 30
