"""Run directories written by hand, in the runner's format (``solar_jax.training.runner``), with
known numbers: a seed's curves are straight lines, so their means are known."""

import dataclasses
import functools
import json
from pathlib import Path

from solar_jax.cli import parse_config
from solar_jax.config import config_to_dict
from solar_jax.morphology import get_suite, load

SYNERGY_METHODS = ("solar", "solar_no_pref")


@functools.cache
def num_agents(name: str) -> int:
    return load(name).num_agents


def labels_of(n: int) -> list[int]:
    """Torso alone, then pairs of agents along the pre-order: [0, 1, 1, 2, 2, ...]."""
    return [0] + [1 + (i - 1) // 2 for i in range(1, n)]


def eval_steps(seed: int, count: int = 6, every: int = 1000) -> list[int]:
    """0, then about every ``every`` steps, a little later for each seed (rounds overshoot)."""
    return [0] + [k * every + 7 * (seed + 1) * k for k in range(1, count)]


def train_return(seed: int, steps: float) -> float:
    return 10.0 * seed + steps / 100.0


def write_run(
    path: Path,
    suite: str = "walker++",
    method: str = "solar",
    seed: int = 0,
    schedule: str = "paper",
    **td3,
) -> Path:
    """A run of ``suite`` with evaluations (``eval_steps``) and rounds every ~250 steps."""
    base = parse_config([f"schedule={schedule}"])
    config = dataclasses.replace(
        base,
        morph=suite,
        method=method,
        seed=seed,
        out=str(path),
        td3=dataclasses.replace(base.td3, **td3),
    )
    members = get_suite(suite)
    names = list(members.members)
    path.mkdir(parents=True)
    resolved = {"morphologies": names, "num_train": len(members.train), "replay_capacity": 1000}
    (path / "config.json").write_text(
        json.dumps({"config": config_to_dict(config), "resolved": resolved})
    )
    records = []
    steps = eval_steps(seed)
    for round_, env_steps in enumerate(steps):
        record = {"kind": "eval", "round": round_, "env_steps": env_steps}
        record["eval/train_return"] = train_return(seed, env_steps)
        if members.held_out:
            record["eval/heldout_return"] = train_return(seed, env_steps) / 2
        for i, name in enumerate(names):  # robot i: the training return plus 10 i
            record[f"eval/{name}/return"] = train_return(seed, env_steps) + 10.0 * i
        records.append(record)
    for round_, env_steps in enumerate(range(250 + seed, steps[-1], 250), start=1):
        record = {"kind": "round", "round": round_, "env_steps": env_steps}
        record["episode/train_return"] = train_return(seed, env_steps) - 1.0
        if members.held_out:
            record["episode/heldout_return"] = train_return(seed, env_steps) / 3
        if method in SYNERGY_METHODS:
            for name in names:
                labels = labels_of(num_agents(name))
                record[f"synergy/{name}/labels"] = labels
                record[f"synergy/{name}/num_clusters"] = max(labels) + 1
                record[f"synergy/{name}/exemplars"] = sorted({labels.index(k) for k in labels})
        records.append(record)
    records.sort(key=lambda r: (r["env_steps"], r["kind"]))
    (path / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    return path


def write_sweep(path: Path, lanes: list[dict], suite: str = "walker++") -> Path:
    """A sweep directory: ``sweep.json`` and one run per lane (``{"seed": s, "lr": x}``)."""
    entries = []
    for lane in lanes:
        run_dir = f"lane{len(entries)}"
        write_run(path / run_dir, suite, seed=lane["seed"], lr=lane["lr"])
        entries.append(
            {"run_dir": run_dir, "seed": lane["seed"], "overrides": {"td3.lr": lane["lr"]}}
        )
    (path / "sweep.json").write_text(json.dumps({"lanes": entries}))
    return path
