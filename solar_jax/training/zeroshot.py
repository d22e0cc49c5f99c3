"""Zero-shot to new dynamics and kinematics: a trained policy on variants of its robots
(``python -m solar_jax.evaluate``; ``morphology.variants``, ``env.variants``).

Each robot of the suite runs as itself and as ``per_property`` variants of each
property, one property varied at a time: ``P = 1 + properties × per_property``
environments per robot in one ``MultiEnv``, one episode each under the deterministic
policy, one program per trainer config (the parameters are its arguments)."""

import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from solar_jax.env.batch import MultiEnv
from solar_jax.morphology.variants import Variation, make_variants
from solar_jax.stats import mean_ci
from solar_jax.training.policy import restore_policy
from solar_jax.training.trainer import Trainer
from solar_jax.xla.options import jit_physics

NOMINAL = "nominal"


def variant_sets(morphs, properties, per_property: int, seed: int, variation: Variation):
    """Per robot, its nominal self and ``per_property`` variants of each property (one
    property varied at a time), and each one's label: ``(variants [M][P], labels [P])``
    with ``P = 1 + len(properties) * per_property``."""
    labels = [NOMINAL] + [p for p in properties for _ in range(per_property)]
    sets = []
    for morph in morphs:
        own = [morph]
        for prop in properties:
            own += [v.morph for v in make_variants(morph, (prop,), per_property, seed, variation)]
        sets.append(own)
    return sets, labels


class _Episodes:
    """One episode of the deterministic policy on every environment of an env of the
    suite's robots ``ids``: a program per trainer config (parameters are arguments),
    which stops when every episode has ended."""

    def __init__(self, trainer: Trainer, env: MultiEnv, ids: np.ndarray):
        n_env, n_max = env.n_max, trainer.env.n_max
        steps = trainer.config.env.max_episode_steps

        def run(actor, synergy, key):
            def step(carry):
                t, state, total, length, alive = carry
                obs = jnp.pad(state.obs, ((0, 0), (0, 0), (0, n_max - n_env), (0, 0)))
                action = trainer.policy(actor, obs, synergy, ids)[..., :n_env]
                state, transition = env.step(state, action)
                total = total + jnp.where(alive, transition.reward, 0.0)
                length = length + alive
                return t + 1, state, total, length, alive & ~transition.done

            def going(carry):
                t, *_, alive = carry
                return (t < steps) & alive.any()

            shape = (env.num_morphs, env.batch_size)
            zeros = jnp.zeros(shape)
            start = (0, env.reset(key), zeros, zeros.astype(jnp.int32), jnp.ones(shape, bool))
            _, _, total, length, _ = jax.lax.while_loop(going, step, start)
            return total, length

        self.run = jit_physics(run)

    def __call__(self, state, key) -> tuple[np.ndarray, np.ndarray]:
        total, length = self.run(state.agent.actor, state.synergy, key)
        return np.asarray(total), np.asarray(length)


def evaluate_run(run_dir: Path, options, programs: dict) -> dict:
    """One run's returns on the variants of its robots (``[M, P]``), with their labels.
    ``options``: ``evaluate.EvaluateOptions``; ``programs``: the episode programs built so
    far, by trainer fingerprint and options (reused by runs of one config)."""
    variation, properties = Variation.parse(options.variants)
    trainer, state, round_ = restore_policy(run_dir, options.checkpoint)
    count = trainer.num_train if options.robots == "train" else trainer.num_morphs
    ids = np.arange(count)
    morphs = trainer.env.morphs[:count]
    key = (trainer.fingerprint, options.variants, options.per_property, options.seed, count)
    if key not in programs:
        sets, labels = variant_sets(
            morphs, properties, options.per_property, options.seed, variation
        )
        env = MultiEnv(morphs, len(labels), trainer.config.env, variants=sets)
        programs[key] = (_Episodes(trainer, env, ids), labels)
    episodes, labels = programs[key]
    start = time.perf_counter()
    returns, lengths = episodes(state, jax.random.key(options.seed))
    return {
        "run": str(run_dir),
        "method": trainer.config.method,
        "round": round_,
        "robots": [m.name for m in morphs],
        "labels": labels,
        "returns": returns.tolist(),
        "lengths": lengths.tolist(),
        "seconds": time.perf_counter() - start,  # the first run's includes the compile
    }


def property_means(result: dict) -> dict[str, float]:
    """A run's mean return per label (nominal and each property), over robots and variants."""
    returns, labels = np.asarray(result["returns"]), np.asarray(result["labels"])
    return {label: float(returns[:, labels == label].mean()) for label in dict.fromkeys(labels)}


def summarise(groups: dict[str, list[dict]]) -> dict[str, dict[str, dict]]:
    """``{group: {label: {mean, ci95, ratio, runs}}}``: over the group's runs (seeds) the
    mean of each run's property mean; one run: its robots' and variants' spread."""
    table = {}
    for name, results in groups.items():
        labels = list(dict.fromkeys(results[0]["labels"]))
        if len(results) > 1:
            values = np.asarray([[property_means(r)[label] for label in labels] for r in results])
            mean, low, high = mean_ci(values)
        else:
            returns, own = np.asarray(results[0]["returns"]), np.asarray(results[0]["labels"])
            rows = [mean_ci(returns[:, own == label].reshape(-1, 1)) for label in labels]
            mean, low, high = (np.array([row[i][0] for row in rows]) for i in range(3))
        nominal = mean[labels.index(NOMINAL)]
        table[name] = {
            label: {
                "mean": float(mean[i]),
                "ci95": [float(low[i]), float(high[i])],
                "ratio": float(mean[i] / nominal) if nominal else float("nan"),
                "runs": len(results),
            }
            for i, label in enumerate(labels)
        }
    return table
