"""Our TD3 update in lockstep with the authors' for 200 iterations at lr 1e-3 on hopper_3
(``benchmarks/lockstep.py``, which says how both are fed the same parameters, batches,
noise and re-clustering batch): SOLAR beside Synergy-RL's ``train_single``, Amorpheus
beside the original Amorpheus's. Each fixture holds the reference's side of one run
(its JSON rows, its initial parameters, its float64 parameters after the last
iteration), written by

    python benchmarks/lockstep.py method=M reference=PATH amorpheus=PATH lr=1e-3 seed=0 \\
        iterations=200 fixture=tests/networks/lockstep_M.npz

so this test needs no torch. Ours replays the run and must end inside the envelope of
the reference's own float32 runs (``lockstep.ENVELOPE`` times their largest distance to
float64, per parameter group) with the reference's clustering at every block.
"""

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks import lockstep
from benchmarks.reference import random_transitions
from solar_jax.morphology import load

pytestmark = pytest.mark.slow


def _fixture(method: str) -> tuple[dict, dict]:
    arrays = dict(np.load(Path(__file__).with_name(f"lockstep_{method}.npz")))
    return json.loads(str(arrays.pop("result"))), arrays


@pytest.mark.parametrize("method", ["solar", "amorpheus"])
def test_our_update_ends_inside_the_references_float32_envelope(method):
    run, arrays = _fixture(method)
    morph = load(run["robot"])
    data = random_transitions(morph, run["transitions"], seed=0)
    assert lockstep.data_digest(data) == run["data_sha256"], (
        "MuJoCo C gives other transitions than the fixture's: write the fixture again"
    )
    initial = {k.removeprefix("initial/"): v for k, v in arrays.items() if "initial/" in k}
    ours = lockstep.our_learner(method, run["lr"], initial, morph)
    schedule = lockstep.Schedule(data, run["iterations"], run["seed"], ours.hyper)
    probe_obs = data["obs"][schedule.probe]
    probe_act = data["action"][schedule.probe]
    every = run["every"]
    for row in run["rows"][1:]:
        ours.recluster(probe_obs, probe_act)
        lockstep.ours_block(ours, schedule, row["iteration"] - every, row["iteration"])
        labels = ours.stats(probe_obs, probe_act)["labels"]
        assert labels in (row["ref32"]["labels"], row["ref64"]["labels"]), row["iteration"]

    last = run["rows"][-1]
    assert last["iteration"] == run["iterations"]
    groups = ours.groups()
    checked = 0
    for name, float64 in arrays.items():
        if not name.startswith(f"ref64/{run['iterations']}/"):
            continue
        group = name.rsplit("/", 1)[1]
        distance = np.linalg.norm(groups[group] - float64) / np.linalg.norm(float64)
        envelope = last["envelope"][group]
        assert 0 < envelope < 1e-3, (group, envelope)  # the reference moved, by rounding only
        assert distance <= lockstep.ENVELOPE * envelope, (group, distance, envelope)
        checked += 1
    assert checked == (4 if method == "solar" else 2)
