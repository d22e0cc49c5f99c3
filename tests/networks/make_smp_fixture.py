"""Writes ``smp_reference.npz``: the reference's SMP (both passes) on fixed inputs.

    python tests/networks/make_smp_fixture.py amorpheus=PATH/TO/amorpheus \
        reference=PATH/TO/Synergy-RL

SMP as the SOLAR paper ran it: "the implementation of SMP in the Amorpheus codebase"
(github.com/yobibyte/amorpheus, MIT): its ``ModularActor``, ``ModularCritic`` and
``TD3``, imported unmodified, with ``torchfold`` (the batching they import; Synergy-RL's
copy, kept on the CPU) on, as its scripts run it: the critic then gives one Q per limb,
``[B, N]``, and TD3 one target per limb. Synergy-RL carries the same two modules, but
its graphs (a list per body) do not run them. Two changes of size only: the reference's
``MLPBase`` (400-300, fixed in its code) at ``HIDDEN``, and ``msg_dim`` at ``MESSAGE``.

For walker_7_main and humanoid_2d_9_full (one network, ``max_children`` 4, the humanoid's)
it stores every parameter, random inputs and the outputs: actions ``[B, n]``, per-limb
Q of both heads and of ``Q1``. Then 8 iterations of the reference's ``train_single`` on
walker_7_main with fixed batches and no target-policy noise, and every parameter after
them. ``test_smp.py`` loads them into ours and compares.
"""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository, as a script
from benchmarks.options import parse_options  # noqa: E402
from benchmarks.reference import import_smp  # noqa: E402
from solar_jax.morphology import load  # noqa: E402
from tests.networks.make_reference_fixture import FixedBatches  # noqa: E402

OUT = Path(__file__).with_name("smp_reference.npz")
ROBOTS = ("walker_7_main", "humanoid_2d_9_full")
HIDDEN = (32, 24)  # MLPBase's two hidden layers (the reference: 400, 300)
MESSAGE = 8  # msg_dim (the reference: 32)
WIDTH = 64  # the bottom-up module's width, fixed in the reference
BATCH = 5
ITERATIONS = 8  # train_single: 8 critic steps, 4 actor steps and target updates
TRAIN_BATCH = 6
LR = 1e-3  # large enough that 8 steps move every parameter well past float noise


def build(utils, arguments, TD3, graphs: dict):
    """The reference's SMP TD3 (its ``scripts/smp_baseline``: --td --bu, lr 1e-4, no
    gradient clip) for these graphs; ``max_children`` over all of them."""
    sys.argv = ["main.py", "--td", "--bu", "--actor_type", "smp", "--critic_type", "smp"]
    sys.argv += ["--lr", str(LR)]
    args = arguments.get_args()
    args.msg_dim = MESSAGE  # the reference's flag has no type: set, not parsed
    args.graphs = graphs
    args.limb_obs_size, args.max_action = 19, 1.0
    args.max_children = utils.findMaxChildren(list(graphs), graphs)
    return TD3.TD3(args), args


def modules(policy, targets: bool = False) -> dict:
    out = {
        "actor/up": policy.actor.sNet[0],
        "actor/down": policy.actor.actor[0],
        "critic/up": policy.critic.sNet[0],
        "critic/down": policy.critic.critic[0],
    }
    if targets:
        out |= {
            "target_actor/up": policy.actor_target.sNet[0],
            "target_actor/down": policy.actor_target.actor[0],
            "target_critic/up": policy.critic_target.sNet[0],
            "target_critic/down": policy.critic_target.critic[0],
        }
    return out


def parameters(policy, tag: str, targets: bool = False) -> dict:
    return {
        f"{tag}/{prefix}/{key}": value.detach().numpy().copy()
        for prefix, module in modules(policy, targets).items()
        for key, value in module.state_dict().items()
    }


def main(argv: list[str]) -> int:
    opts = parse_options(argv, dict(amorpheus="", reference=""), __doc__)
    amorpheus, reference = Path(opts["amorpheus"]), Path(opts["reference"])
    utils, arguments, TD3 = import_smp(amorpheus, reference, HIDDEN)
    import torch

    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    graphs = {name: list(load(name).parents) for name in ROBOTS}
    policy, args = build(utils, arguments, TD3, graphs)
    out = parameters(policy, "init")
    out["max_children"] = np.int64(args.max_children)
    out["sizes"] = np.array([MESSAGE, WIDTH, *HIDDEN])
    for name, parents in graphs.items():
        n = len(parents)
        policy.change_morphology(parents)
        obs = (rng.normal(size=(BATCH, n * 19)) * 2).astype(np.float32)
        action = rng.uniform(-1, 1, size=(BATCH, n)).astype(np.float32)
        with torch.no_grad():
            policy.actor.batch_size = policy.critic.batch_size = BATCH
            acted = policy.actor(torch.from_numpy(obs))
            q1, q2 = policy.critic(torch.from_numpy(obs), torch.from_numpy(action))
            first = policy.critic.Q1(torch.from_numpy(obs), torch.from_numpy(action))
        out |= {
            f"{name}/parents": np.asarray(parents),
            f"{name}/obs": obs,
            f"{name}/action_in": action,
            f"{name}/action": acted.numpy(),
            f"{name}/q": np.stack([q1.numpy(), q2.numpy()]),
            f"{name}/q1": first.numpy(),
        }

    # 8 TD3 iterations on the walker, from the same parameters, reseeded draws.
    walker = graphs[ROBOTS[0]]
    n = len(walker)
    policy.change_morphology(walker)
    batches = []
    for _ in range(ITERATIONS):
        obs = (rng.normal(size=(TRAIN_BATCH, n * 19)) * 2).astype(np.float32)
        next_obs = (obs + rng.normal(size=obs.shape) * 0.3).astype(np.float32)
        action = rng.uniform(-1, 1, size=(TRAIN_BATCH, n)).astype(np.float32)
        reward = (rng.normal(size=(TRAIN_BATCH, 1)) + 1).astype(np.float32)
        done = (rng.uniform(size=(TRAIN_BATCH, 1)) < 0.2).astype(np.float32)
        batches.append((obs, next_obs, action, reward, done))
    for i, batch in enumerate(batches):
        for key, value in zip(("obs", "next_obs", "action", "reward", "done"), batch, strict=True):
            out[f"train/{i}/{key}"] = value
    for module in (policy.actor, policy.actor_target, policy.critic, policy.critic_target):
        module.batch_size = TRAIN_BATCH
    policy.train_single(
        FixedBatches(batches),
        ITERATIONS,
        batch_size=TRAIN_BATCH,
        discount=args.discount,
        tau=args.tau,
        policy_noise=0.0,
        noise_clip=args.noise_clip,
        policy_freq=args.policy_freq,
    )
    out |= parameters(policy, "trained", targets=True)
    out["train/settings"] = np.array([LR, args.discount, args.tau, args.policy_freq])
    np.savez_compressed(OUT, **out)
    print(f"-> {OUT} ({OUT.stat().st_size / 1e3:.0f} kB)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
