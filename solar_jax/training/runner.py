"""The host loop of one run or many: rounds, evaluation, logging and checkpoints.

``Runner(configs, programs)`` drives S runs as the lanes of one compiled round
(``solar_jax.training.lanes``, ``solar_jax.training.programs``): a single run is S = 1,
a sweep's seeds and swept values are S lanes; every line below serves both. Python runs
between the jitted round pieces only. Each run directory holds ``config.json`` (the
resolved config), ``metrics.jsonl`` (one record per round and per evaluation),
``checkpoints/`` (orbax) and, when asked, ``tensorboard/`` (``solar_jax.training.rundir``).
``resume=RUN_DIR`` continues a run from its last checkpoint exactly as if it had not
stopped; a lane that has reached its budget idles while the others go on.
"""

import contextlib
import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from solar_jax.config import ConfigError, TrainConfig, config_to_dict
from solar_jax.training.checkpoint import FORMAT_VERSION, Checkpointer
from solar_jax.training.compiling import compile_announced, report_growth
from solar_jax.training.forecast import (
    PROJECT_AFTER_ROUNDS,
    long_run_warning,
    paper_on_cpu_warning,
)
from solar_jax.training.logger import MetricsLog, ProgressBar, read_metrics
from solar_jax.training.memory import check_fits
from solar_jax.training.programs import RoundPrograms, play_round, round_programs
from solar_jax.training.rundir import (
    BEST,
    CHECKPOINTS,
    CONFIG_FILE,
    METRICS_FILE,
    RUN_FILES,
    RunLock,
    check_same_run,
    config_record,
    default_run_dir,
    has_checkpoint,
    make_run_dir,
    write_file,
)
from solar_jax.training.trainer import RoundStats, Trainer, TrainerState

_EVAL_STREAM = 0xE7A1  # folded into the seed's key: evaluation keys never touch training's


def eval_key(seed: int, rounds, episode: int) -> jax.Array:
    """The key of an evaluation episode: from the seed, the round and the episode only."""
    base = jax.random.fold_in(jax.random.PRNGKey(seed), _EVAL_STREAM)
    return jax.random.fold_in(jax.random.fold_in(base, rounds), episode)


def health_problem(train: dict, stats: RoundStats) -> str | None:
    """What makes a lane's round unfit to go on from (its train metrics and stats on the
    host), or None: non-finite losses or parameters (``Trainer.train``'s ``finite``), or no
    counted step (every episode ended at once: the run would never reach its budget)."""
    if not train["finite"]:
        losses = (
            f"critic loss {float(train['critic_loss']):g}, actor {float(train['actor_loss']):g}"
        )
        return f"non-finite losses or parameters ({losses})"
    if int(np.sum(stats.steps)) == 0:
        return "no env step counted (every episode ended at its first step)"
    return None


def restore_run(
    trainer: Trainer, config: TrainConfig, run_dir: Path, writer: bool = False
) -> tuple[TrainerState, dict, Checkpointer]:
    """(state, metadata, checkpointer) of the latest readable checkpoint of the run of
    ``config`` in ``run_dir`` (resume and the videos), its replay as allocated when it
    was saved; a checkpoint of another config (``config.json`` edited) is a
    ``ConfigError``. ``writer``: the caller holds the run's lock and resumes it, so
    damaged checkpoints are moved aside (``Checkpointer.restore``); a reader moves
    nothing."""
    checkpointer = Checkpointer(Path(run_dir) / CHECKPOINTS, config.keep_checkpoints)

    def template(meta):
        check_same_run(run_dir, config, meta["config"])
        slots = meta["replay_slots"]
        return jax.eval_shape(lambda: trainer.init(config.seed, config.td3, slots))

    try:
        state, meta = checkpointer.restore(template, set_aside=writer)
    except BaseException:
        checkpointer.close()
        raise
    return state, meta, checkpointer


def best_score(records: list[dict]) -> float:
    """The best mean training return of a run's evaluations after round 0 (-inf: none)."""
    scores = [r["eval/train_return"] for r in records if r["kind"] == "eval" and r["round"] > 0]
    return max(scores, default=-np.inf)


def _due(every: int, before: int, after: int) -> bool:
    return every > 0 and after // every > before // every


def _host_view(state: TrainerState) -> TrainerState:
    """The small fields of a state on the host (no parameters, no replay)."""
    return jax.device_get(state.replace(agent=None, replay=None))


def _per_lane(counter) -> np.ndarray:
    """A host counter as ``[S]`` (a single run's is a scalar)."""
    return np.atleast_1d(np.asarray(counter))


class Runner:
    """S runs of one trainer as lanes (module docstring): ``Runner(config).run()`` for one,
    ``Runner(configs, programs)`` for several (``configs`` equal but for ``seed``,
    ``out``/``resume``, the traced ``td3`` values and ``total_steps``). ``programs``: a
    ``RoundPrograms`` of S lanes to share (compiled once for many runners), else built."""

    def __init__(
        self,
        configs: TrainConfig | Sequence[TrainConfig],
        programs: RoundPrograms | None = None,
    ):
        self.configs = [configs] if isinstance(configs, TrainConfig) else list(configs)
        self.config = self.configs[0]
        programs = programs or round_programs(self.config, len(self.configs))
        if programs.lanes.num_lanes != len(self.configs):
            raise ValueError(
                f"{len(self.configs)} runs, but the programs have {programs.lanes.num_lanes} lanes"
            )
        self.programs = programs
        self.layout = programs.lanes  # the lanes' devices, placement and slicing
        self.trainer = programs.trainer
        self.run_dirs = [Path(c.resume or c.out or default_run_dir(c)) for c in self.configs]
        self.names = self.trainer.names
        self.num_train = self.trainer.num_train
        self.totals = np.asarray([c.total_steps for c in self.configs])
        self.failures: list[str] = []  # one line per lane stopped by the health check
        if not self.config.dry_run:
            check_fits(self.trainer, len(self.configs), self.layout.devices, int(self.totals.max()))

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
        """One lane's round (its host view, stats and metrics)."""
        collect_s, train_s = times
        record = {"kind": "round", **self._counters(state)}
        record |= self._split_means("episode", stats.episode_return)
        record |= self._per_morph("episode", stats.episode_return, "return")
        record |= self._per_morph("episode", stats.episode_length, "length")
        ended = zip(self.names, stats.episodes, strict=True)  # episodes that ended in it
        record |= {f"episode/{name}/episodes": int(count) for name, count in ended}
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
            synergy = state.synergy
            record["synergy/mean_clusters"] = float(np.mean(synergy.num_synergies))
            for i, name in enumerate(self.names):
                real = synergy.agent_mask[i]
                k = int(synergy.num_synergies[i])
                record[f"synergy/{name}/num_clusters"] = k
                record[f"synergy/{name}/labels"] = synergy.labels[i][real].tolist()
                record[f"synergy/{name}/exemplars"] = synergy.exemplars[i][:k].tolist()
        return record

    def eval_record(self, state, returns: list, lengths: list) -> dict:
        """One lane's record of ``eval_episodes`` deterministic episodes (returns, lengths:
        one ``[M]`` array per episode)."""
        ret, length = np.mean(returns, axis=0), np.mean(lengths, axis=0)
        record = {"kind": "eval", **self._counters(state)} | self._split_means("eval", ret)
        return (
            record
            | self._per_morph("eval", ret, "return")
            | self._per_morph("eval", length, "length")
        )

    def evaluate(self, state: TrainerState) -> tuple[TrainerState, list[dict]]:
        """Deterministic episodes (``eval_episodes`` per environment: the collection's, or
        ``eval_envs`` of their own) on every morphology of every lane, each from its own
        run's keys: one record per lane."""
        returns, lengths = [], []
        rounds = _per_lane(state.rounds)
        everyone = np.ones(self.layout.num_lanes, bool)
        for episode in range(self.config.eval_episodes):
            keys = jnp.stack(
                [eval_key(c.seed, rounds[i], episode) for i, c in enumerate(self.configs)]
            )
            if self.programs.evaluates_apart:  # eval_envs environments per morphology
                ret, length = self.programs.evaluate(state, keys)
                returns.append(ret.mean(axis=-1))
                lengths.append(length.mean(axis=-1))
                continue
            state, stats = self.programs.collect(state, keys, everyone, ~everyone)
            stats = jax.device_get(stats)
            returns.append(stats.episode_return)
            lengths.append(stats.episode_length)
        view, take = _host_view(state), self.layout.lane
        records = [
            self.eval_record(
                take(view, i), [take(r, i) for r in returns], [take(n, i) for n in lengths]
            )
            for i in range(self.layout.num_lanes)
        ]
        return state, records

    def due(self, index: int, before: int, after: int, stopping: bool) -> tuple[bool, bool]:
        """(evaluate?, checkpoint?) for lane ``index`` after a round that took its env steps
        from ``before`` to ``after``: on crossing a multiple of the interval, and at the
        end (its budget reached, or ``stopping``: ``time_limit`` passed)."""
        config = self.configs[index]
        finished = after >= config.total_steps or stopping
        return (
            finished or _due(config.eval_every, before, after),
            finished or _due(config.checkpoint_every, before, after),
        )

    # ---------------------------------------------------------------------------- loop
    def start(self, index: int) -> tuple[TrainerState, Checkpointer, MetricsLog]:
        """Lane ``index``'s first state (fresh, or restored with ``resume``), its
        checkpointer and its metrics log; a fresh run writes ``config.json``. Its directory
        is locked already (``run``)."""
        config, trainer, run_dir = self.configs[index], self.trainer, self.run_dirs[index]
        checkpoints = run_dir / CHECKPOINTS
        if config.resume and has_checkpoint(run_dir):
            state, _, checkpointer = restore_run(trainer, config, run_dir, writer=True)
            log = MetricsLog(run_dir, config.tensorboard, keep_rounds=int(state.rounds))
            return state, checkpointer, log
        if config.resume:  # killed before its first checkpoint was complete: start over
            kept = run_dir / f"{METRICS_FILE}.before-restart"
            if (run_dir / METRICS_FILE).exists():
                (run_dir / METRICS_FILE).replace(kept)
            print(
                f"note: {run_dir} holds no complete checkpoint; the run starts over from its "
                f"{CONFIG_FILE}" + (f" (its metrics kept as {kept})" if kept.exists() else ""),
                flush=True,
            )
        else:
            written = [name for name in RUN_FILES if (run_dir / name).exists()]
            if written:
                raise ConfigError(
                    f"out={run_dir} already holds a run ({', '.join(written)}); continue it "
                    f"with resume={run_dir} or choose another out="
                )
            resolved = dict(
                format_version=FORMAT_VERSION,
                morphologies=list(trainer.names),
                num_train=trainer.num_train,
                n_max=trainer.env.n_max,
                replay_capacity=trainer.capacity,  # the ring's full size (allocated as it fills)
            )
            write_file(run_dir / CONFIG_FILE, json.dumps(config_record(config, resolved), indent=2))
        checkpointer = Checkpointer(checkpoints, config.keep_checkpoints)
        state = trainer.init(config.seed, config.td3)
        return state, checkpointer, MetricsLog(run_dir, config.tensorboard)

    def run(
        self,
        on_round: Callable[[TrainerState, list[dict]], None] | None = None,
        on_eval: Callable[[list[Path]], None] | None = None,
    ) -> TrainerState:
        """Rounds until every lane has its ``total_steps`` (``rounds``), each run directory
        created and locked (``RunLock``) while they run."""
        with contextlib.ExitStack() as locks:
            for run_dir in self.run_dirs:
                make_run_dir(run_dir)
                locks.enter_context(RunLock(run_dir))
            return self.rounds(on_round, on_eval)

    def save_best(self, index: int, state: TrainerState, record: dict) -> None:
        """Lane ``index``'s policy (actor and clusterings, ``state`` its own) at its best
        evaluation so far (``record``) in ``checkpoints/best`` (``BEST``): small, for the
        videos, kept beside the latest."""
        checkpointer = Checkpointer(self.run_dirs[index] / CHECKPOINTS / BEST, keep=1)
        for step in checkpointer.manager.all_steps():
            if step >= record["round"]:  # saved by rounds a resume redoes: saved again now
                checkpointer.manager.delete(step)
        policy = {"actor": state.agent.actor, "synergy": state.synergy}
        config = config_to_dict(self.configs[index])
        checkpointer.save(record["round"], policy, config, env_steps=record["env_steps"])
        checkpointer.close()

    def _fail(self, index: int, rounds: int, problem: str, checkpointer: Checkpointer) -> None:
        """Lane ``index`` stops at round ``rounds`` for ``problem``: one line now, kept in
        ``failures`` (the commands exit 1 after the run)."""
        last = checkpointer.latest_step()
        saved = "no checkpoint was saved"
        if last is not None:
            saved = (
                f"the last good checkpoint is round {last} ({checkpointer.directory / str(last)})"
            )
        line = f"{self.run_dirs[index]}: round {rounds}: {problem}; stopped unsaved, {saved}"
        self.failures.append(line)
        print(f"error: {line}", file=sys.stderr, flush=True)

    def _announce_compile(self, state) -> float:
        num_lanes = self.layout.num_lanes
        return compile_announced(self.programs, state, self.config, len(self.names), num_lanes)

    def rounds(
        self,
        on_round: Callable[[TrainerState, list[dict]], None] | None = None,
        on_eval: Callable[[list[Path]], None] | None = None,
    ) -> TrainerState:
        """Rounds until every lane has its ``total_steps`` (a finished lane idles);
        ``on_round(state, records)`` after every round with the live lanes' records,
        ``on_eval(run_dirs)`` after the lanes in ``run_dirs`` were evaluated, logged and
        checkpointed (the commands write their figures there). Returns the state (S = 1:
        the run's own; else lane-stacked). Every record carries its wall times as
        ``perf/*``: a round's ``collect_s`` and ``train_s``, an evaluation's ``eval_s``,
        and ``compile_s`` on the first record after a compilation (0 elsewhere). A lane whose
        round fails the health check (``health_problem``) stops there, idle: nothing of
        that round is evaluated or checkpointed, and ``failures`` gets its line."""
        config, take, count = self.config, self.layout.lane, self.layout.num_lanes
        started = time.perf_counter()  # time_limit counts from here: compile included
        starts = [self.start(i) for i in range(count)]
        states, checkpointers, logs = (list(x) for x in zip(*starts, strict=True))
        state = self.layout.place(states)
        del states, starts
        progress = ProgressBar(int(self.totals.sum()), config.progress)
        warning = paper_on_cpu_warning(config, self.num_train, len(self.names))
        view = _host_view(state)
        after = _per_lane(view.env_steps)  # each lane's counted steps, updated every round
        if warning and (after < self.totals).any():
            print(warning, file=sys.stderr, flush=True)
        compile_s = self._announce_compile(state)
        where = f"run directory {self.run_dirs[0]}"
        if count > 1:
            where = f"{count} lanes on {len(self.layout.devices)} device(s), run directories "
            where += ", ".join(str(d) for d in self.run_dirs)
        print(f"compiled in {compile_s:.0f} s; {where}", flush=True)

        best = [best_score(read_metrics(d)) for d in self.run_dirs]  # logs cut on resume

        def evaluate(state, indices: list[int], compile_s: float):
            start = time.perf_counter()
            state, records = self.evaluate(state)
            for i in indices:
                records[i] |= {"perf/eval_s": time.perf_counter() - start}
                records[i] |= {"perf/compile_s": compile_s}
                logs[i].write(records[i])
                score = records[i]["eval/train_return"]
                if records[i]["round"] > 0 and score > best[i]:
                    best[i] = score
                    self.save_best(i, take(state, i), records[i])
            return state

        fresh = np.flatnonzero(_per_lane(view.rounds) == 0).tolist()
        if fresh:
            state = evaluate(state, fresh, compile_s)
            compile_s = 0.0
            if on_eval is not None:
                on_eval([self.run_dirs[i] for i in fresh])
        start_steps, rounds_s, rounds_here = after.sum(), 0.0, 0
        failed = np.zeros(count, bool)  # stopped by the health check: idle from then on
        try:
            while True:
                before = after  # evaluations leave the counters as they were
                live = (before < self.totals) & ~failed
                if not live.any():
                    break
                slots = state.replay.capacity
                state = self.layout.grown(state)
                report_growth(self.trainer, slots, state)
                compile_s += self._announce_compile(state)
                state, stats, train, times = play_round(self.programs, state, live)
                view = _host_view(state)
                limit = config.time_limit
                out_of_time = 0 < limit <= time.perf_counter() - started
                records, evaluating, saving = [], [], []
                for i in np.flatnonzero(live).tolist():
                    record = self.round_record(take(view, i), take(stats, i), take(train, i), times)
                    record["perf/compile_s"] = compile_s
                    logs[i].write(record)
                    records.append(record)
                    problem = health_problem(take(train, i), take(stats, i))
                    if problem is not None:
                        failed[i] = True
                        self._fail(i, record["round"], problem, checkpointers[i])
                        continue
                    evaluate_now, checkpoint = self.due(
                        i, int(before[i]), record["env_steps"], out_of_time
                    )
                    evaluating += [i] if evaluate_now else []
                    saving += [i] if checkpoint else []
                compile_s = 0.0
                after = _per_lane(view.env_steps)
                rounds_s, rounds_here = rounds_s + sum(times), rounds_here + 1
                if rounds_here == PROJECT_AFTER_ROUNDS:
                    done, total = int(np.minimum(after, self.totals).sum()), int(self.totals.sum())
                    steps_here = int(after.sum() - start_steps)
                    warning = long_run_warning(done, total, steps_here, rounds_s)
                    if warning:
                        print(warning, file=sys.stderr, flush=True)
                if evaluating:
                    state = evaluate(state, evaluating, 0.0)
                for i in saving:
                    checkpointers[i].save(
                        int(take(view, i).rounds),
                        take(state, i),
                        config_to_dict(self.configs[i]),
                        replay_slots=state.replay.capacity,
                    )
                if evaluating and on_eval is not None:  # after the checkpoint: it is safe
                    on_eval([self.run_dirs[i] for i in evaluating])
                if records:
                    progress.update(int(np.minimum(after, self.totals).sum()), **_shown(records))
                if on_round is not None:
                    on_round(state, records)
                if out_of_time:
                    if ((after < self.totals) & ~failed).any():
                        note = _stopped_note(limit, after, self.totals, self.run_dirs)
                        print(note, flush=True)
                    break
        finally:
            progress.close()
            for resource in logs + checkpointers:
                resource.close()
        return state


def _stopped_note(limit: float, steps: np.ndarray, totals: np.ndarray, run_dirs) -> str:
    """The line said when ``time_limit`` stops the lanes short of their budgets."""
    counted = ", ".join(f"{int(s):,} of {int(t):,}" for s, t in zip(steps, totals, strict=True))
    return (
        f"time_limit={limit:g} s reached: stopped at {counted} counted steps, evaluated and "
        f"checkpointed; resume={run_dirs[0]}{' (each run directory)' if len(run_dirs) > 1 else ''} "
        "continues"
    )


def _shown(records: list[dict]) -> dict:
    """The progress bar's figures of a round: collection rate, mean return (and clusters)
    over the live lanes, and how many lanes are live when there are several."""
    shown = {
        "env_sps": records[0]["perf/env_sps"],
        "train_return": float(np.mean([r["episode/train_return"] for r in records])),
    }
    if "synergy/mean_clusters" in records[0]:
        shown["clusters"] = float(np.mean([r["synergy/mean_clusters"] for r in records]))
    if len(records) > 1:
        shown["live_lanes"] = len(records)
    return shown
