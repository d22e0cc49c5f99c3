"""The host loop of a training run: rounds, evaluation, logging and checkpoints.

Python runs between the jitted round pieces of ``solar_jax.training.trainer`` only. A run
directory holds ``config.json`` (the resolved config), ``metrics.jsonl`` (one record
per round and per evaluation), ``checkpoints/`` (orbax) and, when asked,
``tensorboard/``. ``resume=RUN_DIR`` continues from the last checkpoint exactly as if
the run had not stopped.
"""

import hashlib
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from solar_jax.compilation_cache import last_compile_time, save_compile_time
from solar_jax.config import ConfigError, TrainConfig, config_to_dict
from solar_jax.training.checkpoint import FORMAT_VERSION, Checkpointer
from solar_jax.training.logger import MetricsLog, ProgressBar, duration
from solar_jax.training.rundir import (
    BOOKKEEPING,
    CHECKPOINTS,
    CONFIG_FILE,
    METRICS_FILE,
    default_run_dir,
    has_checkpoint,
)
from solar_jax.training.trainer import RoundStats, Trainer, TrainerState

_EVAL_STREAM = 0xE7A1  # folded into the seed's key: evaluation keys never touch training's


def resolved_config(config: TrainConfig, trainer: Trainer) -> dict:
    """``config.json``: the config as given plus what it resolved to."""
    return {
        "config": config_to_dict(config),
        "resolved": {
            "format_version": FORMAT_VERSION,
            "morphologies": list(trainer.names),
            "num_train": trainer.num_train,
            "n_max": trainer.env.n_max,
            "replay_capacity": trainer.capacity,  # the ring's full size (allocated as it fills)
        },
    }


def timed_round(trainer: Trainer, state: TrainerState) -> tuple:
    """One training round: (state, RoundStats, train metrics, (collect s, train s)),
    stats and metrics on the host."""

    def collect(state):
        return trainer.collect(state, jax.random.PRNGKey(0), jnp.bool_(False))

    return time_round(collect, trainer.train, state)


def time_round(collect: Callable, train: Callable, state) -> tuple:
    """``collect(state) -> (state, stats)`` then ``train(state, stats.steps)``, timed."""
    start = time.perf_counter()
    state, stats = collect(state)
    stats = jax.device_get(stats)
    collected = time.perf_counter()
    state, metrics = train(state, stats.steps)
    metrics = jax.device_get(metrics)
    return state, stats, metrics, (collected - start, time.perf_counter() - collected)


def report_growth(trainer: Trainer, before: int, state) -> None:
    if state.replay.capacity > before:
        slots = state.replay.capacity
        print(f"replay grown to {slots:,} slots per morphology (of {trainer.capacity:,})")


def program_key(config: TrainConfig, slots: int) -> str:
    """What a run's compiled programs depend on (the config less its bookkeeping keys, the
    replay allocation, JAX and the backend), hashed: the key of their compile time."""
    fields = {k: v for k, v in config_to_dict(config).items() if k not in BOOKKEEPING}
    text = json.dumps([fields, slots, jax.__version__, jax.default_backend()], sort_keys=True)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def compile_announced(compiler, state, config: TrainConfig, robots: int, lanes: int = 1):
    """``compiler.compile(state)`` (a ``Trainer``, or a sweep's ``SweepTrainer`` of
    ``lanes`` lanes), saying first what compiles and how long it took last time on this
    machine; the seconds it took (0 when that replay size was compiled already)."""
    slots = state.replay.capacity
    if slots in compiler.programs:
        compiler.compile(state)
        return 0.0
    first = compiler.episodes_program is None
    key = program_key(config, slots) + ("" if first else "-grown")
    key += f"-{lanes}lanes" if lanes > 1 else ""
    last = last_compile_time(key)
    what = f"{robots} robot{'s' if robots > 1 else ''}" + (f", {lanes} lanes" if lanes > 1 else "")
    programs = (
        "collection and update programs" if first else "the update program for the grown replay"
    )
    print(
        f"compiling {config.morph} ({what}, {config.method}, net {config.net}, replay "
        f"{slots:,} slots) on {jax.default_backend()}: {programs}; "
        + (f"last time {last:.0f} s" if last is not None else "first time on this machine"),
        flush=True,
    )
    start = time.perf_counter()
    compiler.compile(state)
    seconds = time.perf_counter() - start
    save_compile_time(key, seconds)
    return seconds


LONG_RUN_S = 2 * 3600  # a projection above this is worth a warning
PROJECT_AFTER_ROUNDS = 3


def long_run_warning(done: int, total: int, steps: int, seconds: float) -> str | None:
    """A warning when, at ``steps`` counted steps in ``seconds`` so far, the remaining
    ``total - done`` steps take more than ``LONG_RUN_S``; else None."""
    if steps <= 0 or seconds <= 0 or done >= total:
        return None
    remaining = (total - done) * seconds / steps
    if remaining <= LONG_RUN_S:
        return None
    return (
        f"warning: at this run's rate so far ({steps / seconds:,.0f} counted env steps/s on "
        f"{jax.default_backend()}), the remaining {total - done:,} steps take about "
        f"{duration(remaining)}; a smaller net= or total_steps=, or an accelerator, finishes "
        "sooner (README: the quickstart). Continuing."
    )


CPU_PAPER_UPDATE_S = 0.026
"""The fastest TD3 update measured at the paper's network sizes on the project's 2-core
CPU (hopper_3; humanoid_2d_9_full: 0.065-0.072 s; benchmarks/results/learner_paper_*)."""


def paper_on_cpu_warning(config: TrainConfig, num_train: int, num_morphs: int) -> str | None:
    """Before compiling: the paper's networks on a CPU backend cannot finish a long run
    in reasonable time; a lower bound from the measured update cost, or None."""
    if jax.default_backend() != "cpu" or config.net != "default":
        return None
    updates = config.total_steps * num_train / num_morphs  # one per counted step per robot
    floor = updates * CPU_PAPER_UPDATE_S
    if floor <= LONG_RUN_S:
        return None
    return (
        f"warning: the paper's network sizes on a CPU: {config.total_steps:,} steps need "
        f"~{updates:,.0f} TD3 updates, at least {CPU_PAPER_UPDATE_S * 1000:.0f} ms each "
        f"here (benchmarks/learner.py), so at least {duration(floor)}; net=small or tiny, "
        "or an accelerator, finishes sooner (README: the quickstart). The run's own rate "
        "follows its first rounds. Continuing."
    )


def eval_key(seed: int, rounds, episode: int) -> jax.Array:
    """The key of an evaluation episode: from the seed, the round and the episode only."""
    base = jax.random.fold_in(jax.random.PRNGKey(seed), _EVAL_STREAM)
    return jax.random.fold_in(jax.random.fold_in(base, rounds), episode)


def _due(every: int, before: int, after: int) -> bool:
    return every > 0 and after // every > before // every


class Runner:
    """One run: ``Runner(config).run()``; ``on_round(state, record)`` is called after
    every round (tests use it to stop a run as a crash would)."""

    def __init__(self, config: TrainConfig, trainer: Trainer | None = None):
        self.config = config
        self.trainer = trainer or Trainer(config)
        self.run_dir = Path(config.resume or config.out or default_run_dir(config))
        self.names = self.trainer.names
        self.num_train = self.trainer.num_train

    # ------------------------------------------------------------------------- records
    def _per_morph(self, prefix: str, values: np.ndarray, suffix: str) -> dict:
        return {f"{prefix}/{n}/{suffix}": float(v) for n, v in zip(self.names, values, strict=True)}

    def _split_means(self, prefix: str, values: np.ndarray) -> dict:
        record = {f"{prefix}/train_return": float(np.mean(values[: self.num_train]))}
        if self.num_train < len(self.names):
            record[f"{prefix}/heldout_return"] = float(np.mean(values[self.num_train :]))
        return record

    def _counters(self, state: TrainerState) -> dict:
        """``env_steps`` counts every morphology, held-out ones included, as the reference
        does (what ``total_steps`` and the intervals read); ``train_env_steps`` only the
        training morphologies'."""
        env_steps, heldout = int(state.env_steps), int(state.heldout_steps)
        return {
            "round": int(state.rounds),
            "env_steps": env_steps,
            "train_env_steps": env_steps - heldout,
            "heldout_steps": heldout,
            "updates": int(state.updates),
        }

    def round_record(self, state, stats: RoundStats, train: dict, times: tuple) -> dict:
        collect_s, train_s = times
        record = {"kind": "round", **self._counters(state)}
        record |= self._split_means("episode", stats.episode_return)
        record |= self._per_morph("episode", stats.episode_return, "return")
        record |= self._per_morph("episode", stats.episode_length, "length")
        record |= {
            "loss/critic": float(train["critic_loss"]),
            "loss/actor": float(train["actor_loss"]),
            "loss/q": float(train["q"]),
            "perf/env_sps": float(stats.steps.sum() / collect_s),
            "perf/update_sps": float(train["iterations"] / train_s),
            "perf/round_s": collect_s + train_s,
            "perf/collect_s": collect_s,
            "perf/train_s": train_s,
            "env/nonfinite_resets": int(np.sum(state.nonfinite_resets)),
        }
        for name, values in train["actions"].items():  # saturation, pre-tanh and gate RMS
            record |= self._per_morph("actions", values, name)
        if self.trainer.networks.uses_synergy:
            synergy = jax.device_get(state.synergy)
            record["synergy/mean_clusters"] = float(np.mean(synergy.num_synergies))
            for i, name in enumerate(self.names):
                real = synergy.agent_mask[i]
                k = int(synergy.num_synergies[i])
                record[f"synergy/{name}/num_clusters"] = k
                record[f"synergy/{name}/labels"] = synergy.labels[i][real].tolist()
                record[f"synergy/{name}/exemplars"] = synergy.exemplars[i][:k].tolist()
        return record

    def eval_record(self, state, returns: list, lengths: list) -> dict:
        """The record of ``eval_episodes`` deterministic episodes (returns, lengths: one
        ``[M]`` array per episode)."""
        ret, length = np.mean(returns, axis=0), np.mean(lengths, axis=0)
        record = {"kind": "eval", **self._counters(state)} | self._split_means("eval", ret)
        return (
            record
            | self._per_morph("eval", ret, "return")
            | self._per_morph("eval", length, "length")
        )

    def evaluate(self, state: TrainerState) -> tuple[TrainerState, dict]:
        """Deterministic episodes (``eval_episodes`` per environment) on every morphology."""
        returns, lengths = [], []
        for episode in range(self.config.eval_episodes):
            key = eval_key(self.config.seed, state.rounds, episode)
            state, stats = self.trainer.collect(state, key, jnp.bool_(True))
            returns.append(np.asarray(stats.episode_return))
            lengths.append(np.asarray(stats.episode_length))
        return state, self.eval_record(state, returns, lengths)

    def due(self, before: int, after: int) -> tuple[bool, bool]:
        """(evaluate?, checkpoint?) after a round that took env steps from ``before`` to
        ``after``: on crossing a multiple of the interval, and at the end."""
        finished = after >= self.config.total_steps
        return (
            finished or _due(self.config.eval_every, before, after),
            finished or _due(self.config.checkpoint_every, before, after),
        )

    # ---------------------------------------------------------------------------- loop
    def start(self) -> tuple[TrainerState, Checkpointer, MetricsLog]:
        """The run's first state (fresh, or restored with ``resume``), its checkpointer and
        its metrics log; a fresh run writes ``config.json``."""
        config, trainer = self.config, self.trainer
        checkpoints = self.run_dir / CHECKPOINTS
        if config.resume:
            checkpointer = Checkpointer(checkpoints, config.keep_checkpoints)

            def template(meta):  # the replay as allocated when it was saved
                slots = meta["replay_slots"]
                return jax.eval_shape(lambda: trainer.init(config.seed, config.td3, slots))

            state, _ = checkpointer.restore(template)
            log = MetricsLog(self.run_dir, config.tensorboard, keep_rounds=int(state.rounds))
            return state, checkpointer, log
        if has_checkpoint(self.run_dir):
            raise ConfigError(
                f"out={self.run_dir} already holds a run; continue it with "
                f"resume={self.run_dir} or choose another out="
            )
        self.run_dir.mkdir(parents=True, exist_ok=True)
        (self.run_dir / CONFIG_FILE).write_text(
            json.dumps(resolved_config(config, trainer), indent=2)
        )
        (self.run_dir / METRICS_FILE).unlink(missing_ok=True)
        checkpointer = Checkpointer(checkpoints, config.keep_checkpoints)
        state = trainer.init(config.seed, config.td3)
        return state, checkpointer, MetricsLog(self.run_dir, config.tensorboard)

    def run(
        self,
        on_round: Callable[[TrainerState, dict], None] | None = None,
        on_eval: Callable[[dict], None] | None = None,
    ) -> TrainerState:
        """Rounds until ``total_steps``; ``on_eval(record)`` after each evaluation is
        logged and checkpointed (``train`` writes its figures there). Every record
        carries its wall times as ``perf/*``: a round's ``collect_s`` and ``train_s``, an
        evaluation's ``eval_s``, and ``compile_s`` on the first record after a compilation
        (0 elsewhere)."""
        config, trainer = self.config, self.trainer
        state, checkpointer, log = self.start()
        progress = ProgressBar(config.total_steps, config.progress)
        warning = paper_on_cpu_warning(config, trainer.num_train, trainer.num_morphs)
        if warning and int(state.env_steps) < config.total_steps:
            print(warning, file=sys.stderr, flush=True)
        compile_s = compile_announced(trainer, state, config, trainer.num_morphs)
        print(f"compiled in {compile_s:.0f} s; run directory {self.run_dir}", flush=True)

        def evaluate(state, compile_s):
            start = time.perf_counter()
            state, record = self.evaluate(state)
            record["perf/eval_s"] = time.perf_counter() - start
            record["perf/compile_s"] = compile_s
            log.write(record)
            return state, record

        if int(state.rounds) == 0:
            state, record = evaluate(state, compile_s)
            compile_s = 0.0
            if on_eval is not None:
                on_eval(record)
        start_steps, rounds_s, rounds_here = int(state.env_steps), 0.0, 0
        try:
            while int(state.env_steps) < config.total_steps:
                before = int(state.env_steps)
                slots = state.replay.capacity
                state = trainer.grown(state)
                report_growth(trainer, slots, state)
                compile_s += compile_announced(trainer, state, config, trainer.num_morphs)
                state, stats, train, times = timed_round(trainer, state)
                record = self.round_record(state, stats, train, times)
                record["perf/compile_s"], compile_s = compile_s, 0.0
                log.write(record)
                after = record["env_steps"]
                rounds_s, rounds_here = rounds_s + sum(times), rounds_here + 1
                if rounds_here == PROJECT_AFTER_ROUNDS:
                    steps_here = after - start_steps
                    warning = long_run_warning(after, config.total_steps, steps_here, rounds_s)
                    if warning:
                        print(warning, file=sys.stderr, flush=True)
                evaluate_now, checkpoint = self.due(before, after)
                if evaluate_now:
                    state, eval_record = evaluate(state, 0.0)
                if checkpoint:
                    checkpointer.save(
                        record["round"],
                        state,
                        config_to_dict(config),
                        replay_slots=state.replay.capacity,
                    )
                if evaluate_now and on_eval is not None:  # after the checkpoint: it is safe
                    on_eval(eval_record)
                shown = {
                    "env_sps": record["perf/env_sps"],
                    "train_return": record["episode/train_return"],
                }
                if "synergy/mean_clusters" in record:
                    shown["clusters"] = record["synergy/mean_clusters"]
                progress.update(after, **shown)
                if on_round is not None:
                    on_round(state, record)
        finally:
            progress.close()
            log.close()
            checkpointer.close()
        return state
