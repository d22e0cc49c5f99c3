"""The authors' PyTorch TD3, unmodified, learning one robot on MuJoCo C, and ours in the
same loop: the yardstick for "does ours learn as the reference does".

    python benchmarks/reference.py reference=PATH/TO/Synergy-RL [agent=reference|ours]
        [robot=hopper_3] [method=solar|amorpheus] [net=tiny|small|default] [lr=1e-4]
        [seed=0] [total_steps=30000] [eval_every=2500] [threads=1] [save_replay=PATH.npz]
        [out=PATH.jsonl] [init=ours|reference]

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

``agent=ours`` puts our learner in the reference's place (``OurPolicy``: our networks,
initialisation, update and re-clustering; the same loop, replay, exploration,
environment and evaluation), so that only the learner differs between the two arms;
``init=reference`` starts it from the reference's initial parameters of the same seed
(the harness check: at lr 1e-4 both arms then follow one trajectory for thousands of
steps).

Sizes: the ``net`` preset's width, feed-forward, layers and d (``--d_model``); the
reference's gate (256) and embedding (64) widths are fixed in its code, and ours takes
them too. The reference's Amorpheus (``enable_synergy_*`` 0) averages its per-agent Q
into one TD target, unlike ours (per-agent targets, algorithm.md §4). Writes one JSON
line per evaluation to ``benchmarks/results/reference/<robot>_<net>_<method>_lr<lr>_
<agent>_seed<seed>.jsonl``; run seeds as separate processes (one thread each by
default). ``save_replay`` also writes the replay at the end (``lockstep.py data=``).
"""

import dataclasses
import importlib.util
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
from solar_jax.config import EnvConfig, NetworkConfig  # noqa: E402
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
    lr="1e-4",
    agent="reference",
    save_replay="",
    out="",
    init="ours",
)
RESULTS = ROOT / "benchmarks" / "results" / "reference"


def import_reference(root: Path):
    """The reference's ``arguments``, ``utils`` and ``algs.TD3`` modules."""
    src = Path(root) / "modular-rl" / "src"
    if not (src / "algs" / "TD3.py").is_file():
        raise SystemExit(f"error: reference={root} is not a Synergy-RL checkout (no {src}/algs)")
    _stub_gym()
    sys.path.insert(0, str(src))
    import arguments
    import utils
    from algs import TD3

    return arguments, utils, TD3


def import_amorpheus(root: Path):
    """The original Amorpheus's (github.com/yobibyte/amorpheus, MIT) ``arguments``,
    ``utils`` and ``TD3`` modules, for its per-limb TD targets, which ours follows
    (algorithm.md §4). Import it in a process apart from ``import_reference``: both
    name their modules alike."""
    src = Path(root) / "modular-rl" / "src"
    if not (src / "TD3.py").is_file():
        raise SystemExit(f"error: amorpheus={root} is not an amorpheus checkout (no {src}/TD3.py)")
    _stub_gym()
    sys.modules["torchfold"] = types.ModuleType("torchfold")  # SMP's batching, unused here
    sys.path.insert(0, str(src))
    import arguments
    import TD3
    import utils

    return arguments, utils, TD3


def import_smp(amorpheus: Path, synergy_rl: Path, hidden: tuple[int, int] | None = None):
    """SMP as the SOLAR paper ran it: the Amorpheus code base's ``utils``, ``arguments``
    and ``TD3`` (github.com/yobibyte/amorpheus), its ``ModularActor`` and
    ``ModularCritic`` with torchfold on (Synergy-RL's copy of it, kept on the CPU).
    ``hidden``: its MLPBase's two hidden sizes in place of 400-300 (the fixtures' small
    sizes); the rest runs unmodified. A process apart from ``import_reference``."""
    src = amorpheus / "modular-rl" / "src"
    fold = synergy_rl / "modular-rl" / "src" / "algs" / "torchfold.py"
    if not (src / "ModularActor.py").is_file() or not fold.is_file():
        raise SystemExit("error: amorpheus= or reference= is not the checkout named")
    _stub_gym()
    spec = importlib.util.spec_from_file_location("torchfold", fold)
    torchfold = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(torchfold)
    torchfold.Fold.cuda = lambda self: self  # the reference moves folds to CUDA; stay here
    sys.modules["torchfold"] = torchfold
    sys.path.insert(0, str(src))
    import arguments
    import ModularActor
    import ModularCritic
    import TD3
    import torch.nn as nn
    import utils

    class SmallBase(nn.Module):
        """The reference's MLPBase (ReLU, ReLU, linear) at ``hidden``."""

        def __init__(self, num_inputs, num_outputs):
            super().__init__()
            self.l1 = nn.Linear(num_inputs, hidden[0])
            self.l2 = nn.Linear(hidden[0], hidden[1])
            self.l3 = nn.Linear(hidden[1], num_outputs)

        def forward(self, inputs):
            return self.l3(nn.functional.relu(self.l2(nn.functional.relu(self.l1(inputs)))))

    if hidden is not None:
        ModularActor.MLPBase = ModularCritic.MLPBase = SmallBase
    return utils, arguments, TD3


def _stub_gym():
    """Empty ``gym`` and ``wrappers`` modules: the references import them for their
    environments, which these benchmarks replace with MuJoCo C."""
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


def amorpheus_args(arguments, utils, config: NetworkConfig, morph, extra=()):
    """The original Amorpheus's flags (its ``scripts/amorpheus``) at ``config``'s sizes,
    for training ``morph`` alone."""
    sys.argv = [
        "main.py",
        *("--actor_type", "transformer", "--critic_type", "transformer"),
        *("--grad_clipping_value", "0.1", "--lr", "0.0001"),
        *("--attention_layers", str(config.num_layers), "--attention_heads", str(config.heads)),
        *("--attention_hidden_size", str(config.feedforward)),
        *("--attention_embedding_size", str(config.width)),
        *("--transformer_norm", "1", "--condition_decoder_on_features", "1"),
        *extra,
    ]
    args = arguments.get_args()
    args.graphs = {morph.name: list(morph.parents)}
    args.limb_obs_size, args.max_action = 19, 1.0
    args.max_children = utils.findMaxChildren([morph.name], args.graphs)
    return args


def reference_args(arguments, config: NetworkConfig, method: str, extra: list[str] = ()):
    """The README's SOLAR flags (algorithm.md §5) at ``config``'s sizes; Amorpheus with
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


def one_robot_args(arguments, utils, config: NetworkConfig, method: str, morph, extra=()):
    """``reference_args`` for training ``morph`` alone (its name is ``morph.name``)."""
    args = reference_args(arguments, config, method, extra)
    args.graphs = {morph.name: [[p] for p in morph.parents]}
    args.envs_train_names, args.envs_test_names = [morph.name], []
    args.agent_obs_size, args.max_action = 19, 1.0
    args.max_num_agents = len(morph.parents)
    args.max_children = utils.findMaxChildren([morph.name], args.graphs)
    return args


def reference_parameters(policy, name: str, method: str, tag: str, targets: bool = False):
    """``{tag/module/parameter: array}`` of the parameters the forward pass reads, and the
    clustering (``tag/labels``, ``tag/exemplars``), as ``tests/networks/reference_params``
    reads them."""
    modules = {
        "actor": policy.actor.actor,
        "critic1": policy.critic.critic1,
        "critic2": policy.critic.critic2,
    }
    if targets:
        modules |= {
            "target_actor": policy.actor_target.actor,
            "target_critic1": policy.critic_target.critic1,
            "target_critic2": policy.critic_target.critic2,
        }
    out = {}
    if hasattr(policy, "synergy"):  # the original Amorpheus has none
        modules["synergy"] = policy.synergy
        out[f"{tag}/labels"] = np.asarray(policy.synergy.synergy_cluster[name])
        out[f"{tag}/exemplars"] = np.asarray(policy.synergy.synergy_cluster_center[name])
    for prefix, module in modules.items():
        for key, value in module.state_dict().items():
            if _used(method, prefix.removeprefix("target_"), key):
                out[f"{tag}/{prefix}/{key}"] = value.detach().numpy().copy()
    return out


def _used(method: str, prefix: str, key: str) -> bool:
    """Parameters the forward pass reads (the reference builds a gate into every
    TransformerModel and a second, unused set of embeddings into the synergy module)."""
    if "embeds2" in key or "aggregate2" in key:
        return False
    if method == "amorpheus":
        return prefix != "synergy" and "act_weight" not in key
    return prefix in ("actor", "synergy") or "act_weight" not in key


def random_transitions(morph, count: int, seed: int) -> dict[str, np.ndarray]:
    """``count`` transitions of uniform actions for all N agents (the reference's first
    2000 steps), stored as its loop stores them: ``obs``/``next_obs`` [T, N * 19],
    ``action`` [T, N], ``reward`` [T], ``done`` [T] (0 at the time limit, whose
    ``next_obs`` is the auto-reset observation)."""
    env, rng = OracleEnv(morph, seed), np.random.default_rng(seed)
    rows, obs = [], env.reset()
    while len(rows) < count:
        action = rng.uniform(-1, 1, size=len(morph.parents))
        next_obs, reward, terminated, truncated = env.step(action[1:])
        if terminated or truncated:
            next_obs = env.reset()
        done = 0.0 if truncated else float(terminated)
        rows.append((obs, next_obs, action.astype(np.float32), reward, done))
        obs = next_obs
    fields = zip(*rows, strict=True)
    names = ("obs", "next_obs", "action", "reward", "done")
    return {k: np.stack(v).astype(np.float32) for k, v in zip(names, fields, strict=True)}


def save_replay(path: Path, buffer) -> None:
    """The reference replay's transitions as ``random_transitions`` returns them (float32),
    for ``lockstep.py data=PATH``."""
    storage = np.stack(buffer.storage)  # rows [obs, next_obs, action, reward, done]
    cuts = np.cumsum(buffer.slicing_size)[:-1]
    obs, next_obs, action, reward, done = np.split(storage.astype(np.float32), cuts, axis=1)
    fields = dict(obs=obs, next_obs=next_obs, action=action, reward=reward[:, 0], done=done[:, 0])
    np.savez_compressed(path, **fields)
    print(f"-> {path} ({len(storage)} transitions)")


class OracleEnv:
    """One robot in MuJoCo C: ``reset() -> obs [N * 19]``, ``step(actuator actions)``."""

    def __init__(self, morph, seed: int, max_episode_steps: int = EnvConfig.max_episode_steps):
        self.morph, self.rng = morph, np.random.default_rng(seed)
        self.max_episode_steps = max_episode_steps  # the reference's 1,000 by default

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
        return self._obs(), reward, terminated, self.t >= self.max_episode_steps

    def _obs(self) -> np.ndarray:
        return reference_observation(self.morph, self.qpos, self.qvel).astype(np.float32).ravel()


class OurPolicy:
    """Our learner (``our_learner.Ours``, our initialisation from ``seed``, the
    reference's gate and embedding widths) behind the two calls the loop makes of the
    reference's TD3, doing what its ``train_single`` does: re-cluster from ΔQ on 1,000
    replay samples, then the iterations, each on ``replay.sample(batch_size)``, the
    delays counted from the call's start."""

    def __init__(self, method, config: NetworkConfig, lr: float, morph, seed: int, start=None):
        """``start``: the reference's TD3 whose initial parameters ours loads (the
        harness check: both arms from one start), or None for our own initialisation."""
        import jax

        from benchmarks.our_learner import REFERENCE_WIDTHS, Ours, to_ours

        self.jax, self.key = jax, jax.random.key(seed)
        config = dataclasses.replace(config, **REFERENCE_WIDTHS)
        params = None
        if start is not None:
            ref = reference_parameters(start, morph.name, method, "ref")
            params = to_ours(ref, "ref", method, config, len(morph.parents), online=True)
        key = jax.random.fold_in(self.key, 0)
        self.learner = Ours(method, config, lr, morph, params=params, key=key)
        self.iterations = 0

    def select_action(self, obs: np.ndarray, name: str) -> np.ndarray:
        return self.learner.act(obs)

    def train(self, replay: dict, iterations: list[int], batch_size: int, *args, **kwargs):
        (buffer,) = replay.values()
        x, _, u, _, _ = buffer.sample(1000)
        self.learner.recluster(x, u)
        for it in range(sum(iterations)):
            self.iterations += 1
            key = self.jax.random.fold_in(self.key, self.iterations)
            self.learner.update(*buffer.sample(batch_size), it, key)


def run(o: dict) -> list[dict]:
    import torch

    torch.set_num_threads(int(o["threads"]))
    arguments, utils, TD3 = import_reference(Path(o["reference"]))
    morph, name, seed = load(o["robot"]), o["robot"], int(o["seed"])
    config = NetworkConfig.preset(o["net"])
    extra = ["--seed", o["seed"], "--lr", o["lr"]]
    args = one_robot_args(arguments, utils, config, o["method"], morph, extra)
    n = len(morph.parents)
    torch.manual_seed(seed)
    np.random.seed(seed)  # noqa: NPY002 (the reference's replay samples from the global state)
    rng = np.random.default_rng(seed)
    if o["agent"] == "reference" or o["init"] == "reference":
        policy = TD3.TD3(args)
        policy.change_morphology(args.graphs[name])
    if o["agent"] == "ours":
        start = policy if o["init"] == "reference" else None
        policy = OurPolicy(o["method"], config, float(o["lr"]), morph, seed, start)
    replay = {name: utils.ReplayBuffer()}
    limit = args.max_episode_steps  # the reference's time limit, as its done flags read it
    env, eval_env = OracleEnv(morph, seed, limit), OracleEnv(morph, 10_000 + seed, limit)

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
            if o["save_replay"]:
                save_replay(Path(o["save_replay"]), replay[name])
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
    if options["init"] not in ("ours", "reference"):
        print(f"error: init={options['init']}: expected ours or reference", file=sys.stderr)
        return 2
    if options["agent"] not in ("reference", "ours"):
        print(f"error: agent={options['agent']}: expected reference or ours", file=sys.stderr)
        return 2
    if options["method"] not in ("solar", "amorpheus"):
        print(f"error: method={options['method']}: expected solar or amorpheus", file=sys.stderr)
        return 2
    rows = run(options)
    o = options
    name = f"{o['robot']}_{o['net']}_{o['method']}_lr{o['lr']}_{o['agent']}_seed{o['seed']}"
    path = Path(o["out"]) if o["out"] else RESULTS / f"{name}.jsonl"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
