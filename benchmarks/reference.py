"""The authors' PyTorch TD3, unmodified, learning one robot on MuJoCo C: the yardstick for
"does ours learn as the reference does".

    python benchmarks/reference.py reference=PATH/TO/Synergy-RL [robot=hopper_3]
        [method=solar|amorpheus] [net=tiny|small|default] [seed=0] [total_steps=30000]
        [eval_every=2500] [threads=1]

Needs torch, scikit-learn and xmltodict, and a checkout of github.com/drdh/Synergy-RL
(MIT), imported as it is (its unused gym imports stubbed); nothing of it is copied here.
The physics and observation are ``tests/env/oracle.py`` (MuJoCo C, written apart from
``solar_jax.env``, which equals it). The loop is the reference's ``main.py`` for one
environment: uniform actions for all N agents (the torso's too) for the first 2000
steps, Gaussian exploration 0.126, after every episode ``train`` with L - 1 iterations,
L - 1 steps counted; a time-limit step is stored with done 0 and the auto-reset
observation, as the reference's vector env does. Every ``eval_every`` counted steps, at
the end of an episode, one deterministic episode: its return, length and the share of
|a| > 0.99 among its actuator actions.

Sizes: the ``net`` preset's width, feed-forward, layers and d (``--d_model``); the
reference's gate (256) and embedding (64) widths are fixed in its code, so compare with
ours at ``network.gate_hidden=256 network.embedding_dim=64``. The reference's
Amorpheus (``enable_synergy_*`` 0) averages its per-agent Q into one TD target, unlike
ours (per-agent targets, SPEC section 4). Writes one JSON line per evaluation to
``benchmarks/results/reference/<robot>_<net>_<method>_seed<seed>.jsonl``; run seeds as
separate processes (one thread each by default).
"""

import json
import sys
import time
import types
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script: make the repository importable
    sys.path.insert(0, str(ROOT))

from benchmarks.options import parse_options  # noqa: E402
from solar_jax.config import NetworkConfig  # noqa: E402
from solar_jax.morphology import load  # noqa: E402
from tests.env.oracle import reference_observation, reference_step  # noqa: E402

DEFAULTS = dict(
    reference="",
    robot="hopper_3",
    method="solar",
    net="tiny",
    seed="0",
    total_steps="30000",
    eval_every="2500",
    threads="1",
)


def import_reference(root: Path):
    """The reference's ``arguments``, ``utils`` and ``algs.TD3`` modules."""
    src = Path(root) / "modular-rl" / "src"
    if not (src / "algs" / "TD3.py").is_file():
        raise SystemExit(f"error: reference={root} is not a Synergy-RL checkout (no {src}/algs)")
    gym = types.ModuleType("gym")
    gym.envs = types.ModuleType("gym.envs")
    registration = types.ModuleType("gym.envs.registration")
    registration.register = lambda *a, **k: None
    sys.modules.update(
        {
            "gym": gym,
            "gym.envs": gym.envs,
            "gym.envs.registration": registration,
            "wrappers": types.ModuleType("wrappers"),
        }
    )
    sys.path.insert(0, str(src))
    import arguments
    import utils
    from algs import TD3

    return arguments, utils, TD3


def reference_args(arguments, config: NetworkConfig, method: str, extra: list[str] = ()):
    """The README's SOLAR flags (SPEC section 5) at ``config``'s sizes; Amorpheus with
    the synergy switches off."""
    on = "1" if method == "solar" else "0"
    sys.argv = [
        "main.py",
        *("--actor_type", "transformer", "--critic_type", "transformer"),
        *("--grad_clipping_value", "0.1", "--lr", "0.0001", "--start_timesteps", "2000"),
        *("--attention_layers", str(config.num_layers), "--attention_heads", str(config.heads)),
        *("--attention_hidden_size", str(config.feedforward)),
        *("--attention_embedding_size", str(config.width)),
        *("--transformer_norm", "1", "--condition_decoder", "1"),
        *("--enable_synergy_obs", on, "--enable_synergy_act", on),
        *("--synergy_action_dim", "1", "--d_model", str(config.transform_dim)),
        *extra,
    ]
    return arguments.get_args()


class OracleEnv:
    """One robot in MuJoCo C: ``reset() -> obs [N * 19]``, ``step(actuator actions)``."""

    def __init__(self, morph, seed: int):
        self.morph, self.rng = morph, np.random.default_rng(seed)

    def reset(self) -> np.ndarray:
        task, model = self.morph.task, self.morph.model
        self.qpos = model.qpos0 + self.rng.uniform(-1, 1, model.nq) * task.reset_qpos_noise
        if task.reset_qvel_normal:
            self.qvel = self.rng.normal(0, task.reset_qvel_noise, model.nv)
        else:
            self.qvel = self.rng.uniform(-1, 1, model.nv) * task.reset_qvel_noise
        self.t = 0
        return self._obs()

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool]:
        self.qpos, self.qvel, reward, terminated = reference_step(
            self.morph, self.qpos, self.qvel, action
        )
        self.t += 1
        return self._obs(), reward, terminated, self.t >= self.morph.task.max_episode_steps

    def _obs(self) -> np.ndarray:
        return reference_observation(self.morph, self.qpos, self.qvel).astype(np.float32).ravel()


def run(o: dict) -> list[dict]:
    import torch

    torch.set_num_threads(int(o["threads"]))
    arguments, utils, TD3 = import_reference(Path(o["reference"]))
    morph, name, seed = load(o["robot"]), o["robot"], int(o["seed"])
    args = reference_args(
        arguments, NetworkConfig.preset(o["net"]), o["method"], ["--seed", o["seed"]]
    )
    n = len(morph.parents)
    args.graphs = {name: [[p] for p in morph.parents]}
    args.envs_train_names, args.envs_test_names = [name], []
    args.agent_obs_size, args.max_action = 19, 1.0
    args.max_num_agents = n
    args.max_children = utils.findMaxChildren([name], args.graphs)
    torch.manual_seed(seed)
    np.random.seed(seed)  # noqa: NPY002 (the reference's replay samples from the global state)
    rng = np.random.default_rng(seed)
    policy = TD3.TD3(args)
    policy.change_morphology(args.graphs[name])
    replay = {name: utils.ReplayBuffer()}
    env, eval_env = OracleEnv(morph, seed), OracleEnv(morph, 10_000 + seed)

    def evaluate() -> dict:
        obs, ret, actions = eval_env.reset(), 0.0, []
        while True:
            action = policy.select_action(obs, name)[1:]
            actions.append(action)
            obs, reward, terminated, truncated = eval_env.step(action)
            ret += reward
            if terminated or truncated:
                saturated = float(np.mean(np.abs(np.concatenate(actions)) > 0.99))
                return {"return": ret, "length": eval_env.t, "saturated": saturated}

    total_steps, eval_every = int(o["total_steps"]), int(o["eval_every"])
    rows, counted, next_eval, start = [], 0, 0, time.perf_counter()
    while True:
        if counted >= next_eval or counted >= total_steps:
            rows.append({"env_steps": counted, **evaluate(), "wall_s": time.perf_counter() - start})
            print(json.dumps(rows[-1]), flush=True)
            next_eval += eval_every
        if counted >= total_steps:
            return rows
        obs, length, finished = env.reset(), 0, False
        while not finished:  # one episode; the terminating step is not counted
            if counted < args.start_timesteps:
                action = rng.uniform(-1, 1, size=n)
            else:
                action = policy.select_action(obs, name)
                noise = rng.normal(0, args.expl_noise, size=n)
                action = (action + noise).clip(-1, 1)
            next_obs, reward, terminated, truncated = env.step(action[1:])
            finished = terminated or truncated
            if finished:
                next_obs = env.reset()  # the vector env's auto-reset observation
            done = 0.0 if length + 1 == args.max_episode_steps else float(terminated)
            replay[name].add((obs, next_obs, action.astype(np.float32), reward, done))
            obs = next_obs
            if not finished:
                length += 1
                counted += 1
        if counted:  # main.py trains once anything was counted, even after an empty episode
            policy.train(
                replay, [length], args.batch_size, args.discount, args.tau, args.policy_noise,
                args.noise_clip, args.policy_freq, graphs=args.graphs, envs_train_names=[name],
                envs_test_names=[], extra_args={"steps": counted},
            )  # fmt: skip


def main(argv: list[str]) -> int:
    options = parse_options(argv, DEFAULTS, __doc__)
    if not options["reference"]:
        print(
            "error: reference=PATH (a checkout of github.com/drdh/Synergy-RL) is required",
            file=sys.stderr,
        )
        return 2
    if options["method"] not in ("solar", "amorpheus"):
        print(f"error: method={options['method']}: expected solar or amorpheus", file=sys.stderr)
        return 2
    rows = run(options)
    out = ROOT / "benchmarks" / "results" / "reference"
    out.mkdir(parents=True, exist_ok=True)
    o = options
    path = out / f"{o['robot']}_{o['net']}_{o['method']}_seed{o['seed']}.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
