"""Lockstep learner parity: our TD3 update beside the authors' ``train_single`` from the
same parameters, on the same minibatches, target noise and re-clustering batch, with the
reference run in float64 and several times in float32, so that its own rounding drift
is the envelope ours must stay inside.

    python benchmarks/lockstep.py reference=PATH/TO/Synergy-RL [lr=1e-4] [seed=0]
        [iterations=2000] [every=100] [transitions=3000] [data=REPLAY.npz] [variants=3]
        [out=PATH.json] [fixture=PATH.npz]
    python benchmarks/lockstep.py method=amorpheus amorpheus=PATH/TO/amorpheus ...

SOLAR runs beside Synergy-RL's ``train_single`` (github.com/drdh/Synergy-RL), Amorpheus
beside the original Amorpheus's (github.com/yobibyte/amorpheus): per-limb TD targets,
as ours (algorithm.md §4), where Synergy-RL with its synergy off averages them.

Robot hopper_3, ``net=tiny`` at the reference's fixed gate (256) and embedding (64)
widths, batch 100. Data: ``transitions`` uniform-random transitions from MuJoCo C
(``reference.random_transitions``, data seed 0 for every run), or with ``data=PATH`` a
replay that ``reference.py save_replay=PATH`` wrote (on-policy states). ``seed`` draws the
reference's initial parameters (``torch.manual_seed``; ours loads them through
``tests/networks/reference_params.py``), the minibatch indices (with replacement, as the
reference's replay samples), the target-policy noise (drawn as our update draws it and
fed to the reference in place of its ``normal_``) and one 1,000-sample batch shared by
every re-clustering. Every ``every`` iterations (a multiple of 4, so that both sides'
actor and synergy delays agree) each learner re-clusters from ΔQ on that batch under its
own first critic (ours: affinity propagation in JAX; the reference: scikit-learn), then
runs ``every`` iterations (the reference: one ``train_single`` call, as its loop does).

Logged at the start and after every block, for ours and the reference in float32 and
float64: each parameter group's distance to the float64 reference relative to its norm,
the block's mean critic loss, Q1 and the actuated agents' pre-tanh RMS and saturation
(share of |a| > 0.99) on the shared batch, and the cluster labels. Training is chaotic
(at lr 1e-3 a rounding difference grows by five orders of magnitude within a few
hundred iterations), so one float32 run is one sample of the drift: the
envelope of a group is the largest distance to float64 of the float32 reference and
``variants`` more float32 runs whose initial parameters are each one float32 step away
(``Reference.nudge``). ``verdict``: ours passes where its distance to float64 is within
``ENVELOPE`` times the envelope at every row and group, and its labels equal the
reference's.
"""

import contextlib
import hashlib
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script: make the repository importable
    sys.path.insert(0, str(ROOT))

import jax  # noqa: E402

from benchmarks.options import parse_options  # noqa: E402
from benchmarks.our_learner import (  # noqa: E402
    REFERENCE_WIDTHS,
    Ours,
    action_stats,
    split_groups,
    to_ours,
)
from benchmarks.reference import (  # noqa: E402
    amorpheus_args,
    import_amorpheus,
    import_reference,
    one_robot_args,
    random_transitions,
    reference_parameters,
)
from solar_jax.agent.state import Hyper  # noqa: E402
from solar_jax.config import NetworkConfig  # noqa: E402
from solar_jax.morphology import load  # noqa: E402

DEFAULTS = dict(
    reference="",
    amorpheus="",
    method="solar",
    lr="1e-4",
    seed="0",
    iterations="2000",
    every="100",
    transitions="3000",
    data="",
    variants="3",
    out="",
    fixture="",
)
ROBOT = "hopper_3"
CONFIG = NetworkConfig.tiny(**REFERENCE_WIDTHS)
BATCH = 100
PROBE = 1000  # the reference's ΔQ batch (train_single samples 1,000)
ENVELOPE = 4.0
"""Ours may be this many times farther from the float64 reference than the farthest
float32 reference: another float32 evaluation order, not a different computation."""


class Schedule:
    """What both learners are fed: ``data`` (the transitions), ``probe`` (indices of the
    shared re-clustering batch), ``indices [iterations, B]`` and ``noise [iterations, B,
    N]`` (the clipped-before target-policy noise, σ applied)."""

    def __init__(self, data: dict, iterations: int, seed: int, hyper: Hyper):
        self.data, t = data, len(data["reward"])
        n = data["action"].shape[1]
        rng = np.random.default_rng(seed)
        self.probe = rng.choice(t, PROBE, replace=False)
        self.indices = rng.integers(0, t, size=(iterations, BATCH))
        self.keys = [jax.random.fold_in(jax.random.key(seed), i) for i in range(iterations)]
        # Our critic loss draws hyper.policy_noise · normal(key, [B, N]) from the key it
        # gets: the same numbers go to the reference.
        draw = jax.jit(lambda k: hyper.policy_noise * jax.random.normal(k, (BATCH, n)))
        self.noise = np.stack([np.asarray(draw(k)) for k in self.keys])

    def torch_batch(self, idx: np.ndarray, dtype) -> tuple:
        """The reference replay's ``sample``: (x, y, u, r, d), r and d as [B, 1]."""
        d = self.data
        fields = (d["obs"], d["next_obs"], d["action"], d["reward"][:, None], d["done"][:, None])
        return tuple(f[idx].astype(dtype) for f in fields)


def our_learner(method: str, lr: float, initial: dict, morph) -> Ours:
    """Ours from the reference's initial parameters ``initial`` (``reference_parameters``
    with tag "ref")."""
    params = to_ours(initial, "ref", method, CONFIG, len(morph.parents), online=True)
    return Ours(method, CONFIG, lr, morph, params=params)


def ours_block(ours: Ours, schedule: Schedule, start: int, stop: int) -> float:
    """Our iterations ``start..stop-1`` on the schedule's batches; the mean critic loss."""
    losses = [
        ours.update(*schedule.torch_batch(schedule.indices[i], np.float32), i, schedule.keys[i])
        for i in range(start, stop)
    ]
    return float(np.mean(jax.device_get(losses)))


class Reference:
    """The authors' TD3 on one robot (SOLAR: Synergy-RL's; Amorpheus: the original
    Amorpheus's, whose per-limb TD targets ours follows), in float32 or float64, with
    its batches, noise and re-clustering batch fed from a ``Schedule``."""

    def __init__(self, modules, method: str, lr: float, seed: int, morph, float64: bool):
        import torch

        arguments, utils, TD3 = modules
        self.torch, self.method, self.name = torch, method, morph.name
        self.n = len(morph.parents)
        self.dtype = np.float64 if float64 else np.float32
        extra = ["--lr", str(lr), "--seed", str(seed)]
        if method == "solar":
            args = one_robot_args(arguments, utils, CONFIG, method, morph, extra)
        else:
            args = amorpheus_args(arguments, utils, CONFIG, morph, extra)
        self.args = args
        torch.manual_seed(seed)
        self.policy = p = TD3.TD3(args)
        p.change_morphology(args.graphs[self.name])
        if float64:
            for module in (p.actor, p.actor_target, p.critic, p.critic_target):
                module.double()  # in place: the optimisers keep the same parameters
            if method == "solar":
                p.synergy.double()
                cluster = p.synergy.update_synergy_weights

                def update_synergy_weights(*a, **k):  # its one-hot weights are float32
                    cluster(*a, **k)
                    for key, w in p.synergy.synergy_weights.items():
                        p.synergy.synergy_weights[key] = w.double()

                p.synergy.update_synergy_weights = update_synergy_weights
                update_synergy_weights()

    def parameters(self) -> dict:
        return reference_parameters(self.policy, self.name, self.method, "ref", targets=True)

    def nudge(self, rng: np.random.Generator):
        """Every nonzero initial parameter one float32 step up or down (the targets
        copied again): another float32 rounding of the same start, for the envelope."""
        torch, p = self.torch, self.policy
        online = [p.actor, p.critic] + ([p.synergy] if self.method == "solar" else [])
        with torch.no_grad():
            for module in online:
                for param in module.parameters():
                    x = param.numpy()
                    way = np.where(rng.random(x.shape) < 0.5, -np.inf, np.inf).astype(x.dtype)
                    param.copy_(torch.from_numpy(np.where(x != 0, np.nextafter(x, way), x)))
        p.actor_target.load_state_dict(p.actor.state_dict())
        p.critic_target.load_state_dict(p.critic.state_dict())

    @contextlib.contextmanager
    def _precision(self):
        """``torch.FloatTensor`` and new tensors in this learner's precision (float64:
        the modules are double)."""
        torch = self.torch
        saved = torch.FloatTensor, torch.get_default_dtype()
        dtype = torch.float64 if self.dtype == np.float64 else torch.float32
        torch.FloatTensor = lambda x: torch.tensor(np.asarray(x), dtype=dtype)
        torch.set_default_dtype(dtype)
        try:
            yield dtype
        finally:
            torch.FloatTensor = saved[0]
            torch.set_default_dtype(saved[1])

    @contextlib.contextmanager
    def _fed(self, noise: list[np.ndarray]):
        """``Tensor.normal_`` (train_single's one random draw) taking ``noise`` in turn;
        yields the list that gets every ``F.mse_loss`` (two per critic step, one per
        twin)."""
        torch, queue = self.torch, iter(noise)
        normal, mse = torch.Tensor.normal_, torch.nn.functional.mse_loss
        losses = []
        torch.Tensor.normal_ = lambda t, *a, **k: t.copy_(torch.from_numpy(next(queue)))

        def mse_loss(*a, **k):
            loss = mse(*a, **k)
            losses.append(loss.item())
            return loss

        torch.nn.functional.mse_loss = mse_loss
        try:
            with self._precision():
                yield losses
            assert next(queue, None) is None, "train_single drew less noise than fed"
        finally:
            torch.Tensor.normal_, torch.nn.functional.mse_loss = normal, mse

    def block(self, schedule: Schedule, start: int, stop: int) -> float:
        """One ``train_single`` call over iterations ``start..stop-1`` (SOLAR's first
        sample is the re-clustering batch); the mean critic loss."""
        batches = [
            schedule.torch_batch(schedule.indices[i], self.dtype) for i in range(start, stop)
        ]
        td3 = dict(
            batch_size=BATCH,
            discount=self.args.discount,
            tau=self.args.tau,
            policy_noise=self.args.policy_noise,
            noise_clip=self.args.noise_clip,
            policy_freq=self.args.policy_freq,
        )
        if self.method == "solar":
            batches.insert(0, schedule.torch_batch(schedule.probe, self.dtype))
        replay = _Queue(batches)
        self.policy.models2train()
        with self._fed(list(schedule.noise[start:stop])) as mse_losses:
            if self.method == "solar":
                self.policy.train_single(
                    self.name, replay, stop - start, update_ac=True, update_sy=True, **td3
                )
            else:
                self.policy.train_single(replay, stop - start, **td3)
        assert replay.empty(), "train_single sampled fewer batches than fed"
        critic_losses = np.add(mse_losses[0::2], mse_losses[1::2])  # the twins' sum
        assert len(critic_losses) == stop - start
        return float(np.mean(critic_losses))

    def stats(self, obs, action) -> dict:
        """Q1 and the actions before and after the tanh on ``obs [P, N * 19]``."""
        torch, p = self.torch, self.policy
        seen, tanh, tanh_method = [], torch.tanh, torch.Tensor.tanh
        torch.tanh = lambda t: seen.append(t.detach().clone()) or tanh(t)
        torch.Tensor.tanh = lambda t: seen.append(t.detach().clone()) or tanh_method(t)
        batch = p.actor.batch_size, p.critic.batch_size
        p.actor.batch_size = p.critic.batch_size = len(obs)  # Amorpheus reshapes by them
        try:
            with torch.no_grad(), self._precision() as dtype:
                state = torch.tensor(obs.reshape(len(obs), -1), dtype=dtype)
                act = torch.tensor(action, dtype=dtype)
                p.models2eval()
                if self.method == "solar":
                    p.actor(state, p.synergy, env_name=self.name)
                    q1, _ = p.critic(state, act, p.synergy, self.name)
                else:
                    p.actor(state)
                    q1, _ = p.critic(state, act)
        finally:
            torch.tanh, torch.Tensor.tanh = tanh, tanh_method
            p.actor.batch_size, p.critic.batch_size = batch
        pre_tanh = seen[-1][..., 0].T.numpy()  # [N, P, 1] -> [P, N]
        labels = None
        if self.method == "solar":
            labels = np.asarray(p.synergy.synergy_cluster[self.name]).tolist()
        return {"q": float(q1.mean()), **action_stats(pre_tanh), "labels": labels}

    def groups(self) -> dict[str, np.ndarray]:
        actor, critic, target_actor, target_critic = to_ours(
            self.parameters(), "ref", self.method, CONFIG, self.n, online=False
        )
        return split_groups(actor, critic, target_actor, target_critic)


class _Queue:
    def __init__(self, batches):
        self.batches = list(batches)

    def sample(self, batch_size):
        batch = self.batches.pop(0)
        assert len(batch[0]) == batch_size, (len(batch[0]), batch_size)
        return batch

    def empty(self) -> bool:
        return not self.batches


def distances(groups: dict, to: dict) -> dict:
    """‖θ - θ_to‖ / ‖θ_to‖ per group."""
    return {k: float(np.linalg.norm(v - to[k]) / np.linalg.norm(to[k])) for k, v in groups.items()}


def run(o: dict) -> dict:
    import torch

    torch.set_num_threads(1)
    morph = load(ROBOT)
    method, lr, seed = o["method"], float(o["lr"]), int(o["seed"])
    iterations, every = int(o["iterations"]), int(o["every"])
    if every % 4 or iterations % every:
        raise SystemExit(f"error: every={every} must be a multiple of 4 dividing iterations")
    if method == "solar":
        modules = import_reference(Path(o["reference"]))
    else:
        modules = import_amorpheus(Path(o["amorpheus"]))
    start_time = time.perf_counter()
    ref32 = Reference(modules, method, lr, seed, morph, float64=False)
    ref64 = Reference(modules, method, lr, seed, morph, float64=True)
    variants = {}
    for k in range(1, int(o["variants"]) + 1):
        variants[f"ref32_{k}"] = Reference(modules, method, lr, seed, morph, float64=False)
        variants[f"ref32_{k}"].nudge(np.random.default_rng(k))
    initial = ref32.parameters()
    ours = our_learner(method, lr, initial, morph)
    if o["data"]:
        data = dict(np.load(o["data"]))
    else:
        data = random_transitions(morph, int(o["transitions"]), seed=0)
    schedule = Schedule(data, iterations, seed, ours.hyper)
    probe_obs = data["obs"][schedule.probe]
    probe_act = data["action"][schedule.probe]
    references = {"ref32": ref32, "ref64": ref64, **variants}
    learners = {"ours": ours, **references}
    rows, float64_groups = [], {}

    def log(iteration: int, losses: dict):
        groups = {k: v.groups() for k, v in learners.items()}
        float64_groups.update({f"ref64/{iteration}/{k}": v for k, v in groups["ref64"].items()})
        row = {"iteration": iteration, "critic_loss": losses}
        for name, learner in learners.items():
            row[name] = learner.stats(probe_obs, probe_act) | {
                "distance": distances(groups[name], groups["ref64"])
            }
        row["ours"]["distance_to_ref32"] = distances(groups["ours"], groups["ref32"])
        own = [row[k]["distance"] for k in ("ref32", *variants)]
        row["envelope"] = {g: max(d[g] for d in own) for g in own[0]}
        rows.append(row)
        print(json.dumps(summary_line(row)), flush=True)

    log(0, {})
    for start in range(0, iterations, every):
        ours.recluster(probe_obs, probe_act)  # the reference re-clusters in train_single
        losses = {"ours": ours_block(ours, schedule, start, start + every)}
        losses |= {k: v.block(schedule, start, start + every) for k, v in references.items()}
        log(start + every, losses)
    result = {
        "robot": ROBOT,
        "method": method,
        "lr": lr,
        "seed": seed,
        "iterations": iterations,
        "every": every,
        "batch": BATCH,
        "transitions": len(data["reward"]),
        "data": o["data"] or "uniform",
        "network": {"preset": "tiny", "gate_hidden": 256, "embedding_dim": 64},
        "wall_s": time.perf_counter() - start_time,
        "versions": versions(),
        "data_sha256": data_digest(data),
        "rows": rows,
        "verdict": verdict(rows),
    }
    if o["fixture"]:
        write_fixture(Path(o["fixture"]), result, initial, float64_groups)
    return result


def write_fixture(path: Path, result: dict, initial: dict, float64_groups: dict):
    """What ``tests/networks/test_lockstep.py`` replays ours against without torch: the
    run's JSON, the reference's initial online parameters (its targets start equal) and
    its float64 online groups after the last iteration."""
    initial = {f"initial/{k}": v for k, v in initial.items() if "/target_" not in k}
    last = f"ref64/{result['iterations']}/"
    online = {
        k: v
        for k, v in float64_groups.items()
        if k.startswith(last) and not k.removeprefix(last).startswith("target_")
    }
    np.savez_compressed(path, result=json.dumps(result), **initial, **online)
    print(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB)")


def data_digest(data: dict) -> str:
    """SHA-256 of the transitions, to tell a fixture made from other physics."""
    digest = hashlib.sha256()
    for key in sorted(data):
        digest.update(np.ascontiguousarray(data[key]).tobytes())
    return digest.hexdigest()


def summary_line(row: dict) -> dict:
    out = {"it": row["iteration"]}
    for k in ("ours", "ref32"):
        out[f"{k}_trunk_dist"] = f"{row[k]['distance']['trunk']:.1e}"
    for k in ("ours", "ref32", "ref64"):
        out[f"{k}_sat"] = round(row[k]["saturation"], 3)
    out["labels"] = row["ours"]["labels"]
    return out


def verdict(rows: list[dict]) -> dict:
    """Ours inside the envelope at every logged row and group (a row where the float32
    references are still exactly the float64 one asks ours to be within 1e-6), and the
    labels equal to the float32 reference's (or, where the reference's own runs differ,
    to one of theirs)."""
    worst = {}
    for row in rows:
        for group, d_ours in row["ours"]["distance"].items():
            d_ref = row["envelope"][group]
            ratio = d_ours / d_ref if d_ref > 0 else (0.0 if d_ours < 1e-6 else np.inf)
            worst[group] = max(worst.get(group, 0.0), ratio)
    labels = all(
        row["ours"]["labels"] in [row[k]["labels"] for k in row if k.startswith("ref")]
        for row in rows
    )
    inside = all(r <= ENVELOPE for r in worst.values())
    return {
        "worst_ratio": worst,
        "labels_equal": labels,
        "inside": inside,
        "pass": inside and labels,
    }


def versions() -> dict:
    import sklearn
    import torch

    return {"jax": jax.__version__, "torch": torch.__version__, "sklearn": sklearn.__version__}


def main(argv: list[str]) -> int:
    options = parse_options(argv, DEFAULTS, __doc__)
    method = options["method"]
    needs = {
        "solar": ("reference", "drdh/Synergy-RL"),
        "amorpheus": ("amorpheus", "yobibyte/amorpheus"),
    }
    if method not in needs:
        print(f"error: method={method}: expected solar or amorpheus", file=sys.stderr)
        return 2
    key, repo = needs[method]
    if not options[key]:
        print(f"error: {key}=PATH (a checkout of github.com/{repo}) is required", file=sys.stderr)
        return 2
    if options["data"] and not Path(options["data"]).is_file():
        print(f"error: data={options['data']}: no such replay file", file=sys.stderr)
        return 2
    for name, kind in (("lr", float), ("seed", int), ("iterations", int), ("every", int)):
        try:
            kind(options[name])
        except ValueError:
            print(f"error: {name}={options[name]}: expected a {kind.__name__}", file=sys.stderr)
            return 2
    result = run(options)
    o = options
    data = f"_{Path(o['data']).stem}" if o["data"] else ""
    name = f"{o['method']}_lr{o['lr']}_seed{o['seed']}{data}.json"
    out = Path(o["out"]) if o["out"] else ROOT / "benchmarks" / "results" / "lockstep" / name
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps(result["verdict"]))
    print(f"-> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
