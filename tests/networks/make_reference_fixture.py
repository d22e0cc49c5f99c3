"""Writes ``reference_forward.npz``: the authors' PyTorch networks on fixed inputs.

    python tests/networks/make_reference_fixture.py PATH/TO/Synergy-RL

Needs torch, scikit-learn and xmltodict, and a checkout of the authors' code
(github.com/drdh/Synergy-RL, MIT), which it imports unmodified; nothing of it is copied
here. For walker_7_main at the tiny sizes (with the reference's fixed gate width 256 and
embedding width 64) it builds the reference's SOLAR TD3 and Amorpheus TD3, clusters with
a fixed preference, and stores every parameter, the clustering, random inputs and the
outputs: the actor's actions [B, N], both critics' per-token Q and the ΔQ of each agent
(algorithm.md §3, first critic, each agent's action zeroed in turn).
It also runs 8 iterations of the reference's ``train_single`` on fixed batches and stores
the parameters after them. ``test_reference_forward.py`` loads them into ours and compares.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository, as a script
from benchmarks.reference import (  # noqa: E402
    import_reference,
    reference_args,
    reference_parameters,
)
from solar_jax.config import NetworkConfig  # noqa: E402

OUT = Path(__file__).with_name("reference_forward.npz")
PARENTS = (-1, 0, 1, 2, 0, 4, 5)  # walker_7_main
PREFERENCE = (0.3, 0.1, 0.1, 0.1, 0.1, 0.25, 0.25)  # gives 3 clusters + the torso's
BATCH = 6
ITERATIONS = 8  # TD3 iterations of train_single: 8 critic, 4 actor, 2 synergy steps
TRAIN_BATCH = 8


class FixedBatches:
    """A replay buffer whose ``sample`` returns the given batches in turn (the first is
    train_single's ΔQ batch, whatever size it asks for)."""

    def __init__(self, batches):
        self.batches, self.calls = batches, 0

    def sample(self, batch_size):
        batch = self.batches[self.calls % len(self.batches)]
        self.calls += 1
        return batch


def build(arguments, utils, TD3, synergy: bool):
    """The reference's TD3 for walker_7_main at the tiny sizes, clustered at PREFERENCE."""
    args = reference_args(arguments, NetworkConfig.tiny(), "solar" if synergy else "amorpheus")
    name = "walker_7_main"
    args.graphs = {name: [[p] for p in PARENTS]}
    args.envs_train_names, args.envs_test_names = [name], []
    args.agent_obs_size, args.max_action = 19, 1.0
    args.max_num_agents = len(PARENTS)
    args.max_children = utils.findMaxChildren([name], args.graphs)
    policy = TD3.TD3(args)
    policy.change_morphology(args.graphs[name])
    policy.synergy.update_synergy_weights(name, np.array(PREFERENCE))
    return policy, name


def train_iterations(arguments, utils, TD3, rng) -> dict:
    """SOLAR's parameters (the forward check's, reseeded) after ``ITERATIONS`` of the
    reference's train_single on fixed batches, without target-policy noise (its one
    random draw); the clustering it made from its ΔQ batch."""
    import torch

    n = len(PARENTS)
    batches = []
    for _ in range(ITERATIONS + 1):
        obs = rng.normal(size=(TRAIN_BATCH, n * 19)) * 2
        next_obs = obs + rng.normal(size=obs.shape) * 0.3
        action = rng.uniform(-1, 1, size=(TRAIN_BATCH, n))
        reward = rng.normal(size=(TRAIN_BATCH, 1)) + 1
        done = (rng.uniform(size=(TRAIN_BATCH, 1)) < 0.2).astype(np.float64)
        batches.append(tuple(x.astype(np.float32) for x in (obs, next_obs, action, reward, done)))
    torch.manual_seed(0)  # the forward check's SOLAR parameters, which start the training
    policy, name = build(arguments, utils, TD3, synergy=True)
    out = {}
    policy.models2train()
    policy.train_single(
        name,
        FixedBatches(batches),
        ITERATIONS,
        batch_size=TRAIN_BATCH,
        discount=0.99,
        tau=0.046,
        policy_noise=0.0,
        noise_clip=0.5,
        policy_freq=2,
        update_ac=True,
        update_sy=True,
    )
    out |= reference_parameters(policy, name, "solar", "train", targets=True)
    for i, field in enumerate(("obs", "next_obs", "action", "reward", "done")):
        out[f"train/{field}"] = np.stack([b[i] for b in batches])
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("reference", type=Path, help="a checkout of drdh/Synergy-RL")
    root = parser.parse_args().reference
    import torch

    arguments, utils, TD3 = import_reference(root)
    torch.manual_seed(0)
    n = len(PARENTS)
    rng = np.random.default_rng(0)
    # Observation-like scales: positions ~1, velocities up to 10.
    obs = (rng.normal(size=(BATCH, n, 19)) * rng.choice([0.5, 3.0], size=19)).astype(np.float32)
    action = rng.uniform(-1, 1, size=(BATCH, n)).astype(np.float32)
    out = {"obs": obs, "action": action, "parents": np.array(PARENTS)}
    for method, synergy in (("solar", True), ("amorpheus", False)):
        policy, name = build(arguments, utils, TD3, synergy)
        state = torch.from_numpy(obs.reshape(BATCH, -1))
        act = torch.from_numpy(action)
        with torch.no_grad():
            actions = policy.actor(state, policy.synergy, env_name=name)
            q1, q2 = policy.critic(state, act, policy.synergy, name)
            full = policy.critic(state, act, policy.synergy, name)[0].mean(dim=-1)
            dq = torch.stack(
                [
                    full
                    - policy.critic(state, act * (1 - torch.eye(n)[i]), policy.synergy, name)[
                        0
                    ].mean(dim=-1)
                    for i in range(n)
                ],
                dim=1,
            )
        out[f"{method}/actions"] = actions.numpy()
        out[f"{method}/q1"], out[f"{method}/q2"] = q1.numpy(), q2.numpy()
        out[f"{method}/delta_q"] = dq.numpy()
        out |= reference_parameters(policy, name, method, method)
    out |= train_iterations(arguments, utils, TD3, rng)
    np.savez_compressed(OUT, **out)
    print(f"wrote {OUT} ({OUT.stat().st_size / 1024:.0f} KiB)")


if __name__ == "__main__":
    main()
