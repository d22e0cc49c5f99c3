"""The round's programs, compiled (jitted, or ahead of time per replay size), and the
host's side of a round's collection.

``RoundPrograms(lanes)`` jits the pure functions of ``lanes`` (a ``SingleLane`` or
``Lanes``, ``solar_jax.training.lanes``) and counts their traces:

    collect(state, keys[S], evaluate[S], idle[S]) -> (state, RoundStats)
        one round of every lane (``evaluate``: deterministic, nothing stored or
        counted; ``idle``: no episode at all): each part's episodes, then ``close``
    train(state, steps, live[S])                  -> (state, metrics)
    evaluate(state, keys[S])                      -> (return, length) [S, M, eval_envs]
        with ``eval_envs``: a deterministic episode of each evaluation environment, in
        each part's program of its own (else evaluations go through ``collect``)

A round's collection calls each part's program (``Trainer.part_episodes``; one per MJX
world, or one for all, ``trainer.collection_parts``) to the end of its own episodes,
then the parts that finished first again, to the loop step where the last one ended,
and ``close``. The one round that crosses the warm-up's end is first run at random
throughout for its episodes' lengths (``Trainer.warmup_switch``). So each part is the
same computation as in a program of all parts, with the same keys.

``compile(state)`` points them at programs compiled ahead of time (so timings exclude
compilation): each part's episodes once with ``physics_compiler_options``, ``close``
and ``train`` the first time a replay size is seen, all through the programs kept on
disk under the trainer's fingerprint (``compile_program``), each traced in turn and
compiled in a thread of its own (``compile_programs``): the parts side by side, so
that on enough cores the cold start is the largest part's. After it, a call with other
shapes fails instead of retracing.
"""

import time

import jax
import numpy as np

from solar_jax.config import TrainConfig
from solar_jax.training.lanes import Lanes, SingleLane
from solar_jax.training.trainer import Control, RoundStats, Trainer, TrainerState
from solar_jax.xla.options import jit_physics, physics_compiler_options
from solar_jax.xla.programs import compile_programs


class RoundPrograms:
    """The compiled round of ``lanes``; ``traces`` counts each program's traces
    (``collect``: every part's)."""

    def __init__(self, lanes):
        self.lanes = lanes
        self.trainer = lanes.trainer
        self.traces = {"collect": 0, "close": 0, "train": 0, "evaluate": 0}
        self.part_programs = None  # compiled ahead of time by ``compile``
        self.evaluation_programs = None  # likewise
        self.programs = {}  # replay slots -> (close, train), compiled ahead of time
        count = len(self.trainer.parts)
        self._functions = (
            [
                self._counted("collect", lanes.part_episodes(p), f"episodes_{p}of{count}")
                for p in range(count)
            ],
            self._counted("close", lanes.close, "close"),
            self._counted("train", lanes.train, "train"),
            [
                self._counted("evaluate", lanes.part_evaluation(p), f"evaluation_{p}of{count}")
                for p in range(len(self.trainer.eval_parts))
            ],
        )
        parts, close, train, evaluations = self._functions
        self.parts = [jit_physics(part, donate_argnums=3) for part in parts]  # as ``compile``'s
        self.evaluations = [jit_physics(evaluation) for evaluation in evaluations]
        self.close = jax.jit(close, donate_argnums=0)
        self.train_program = jax.jit(train, donate_argnums=0)
        self._carries = None  # each part's last round, its buffers reused by the next
        self.compile_timings = []  # each program compiled ahead of time (``compile_programs``)

    def _counted(self, what: str, fn, name: str):
        def counted(*args):
            self.traces[what] += 1  # runs only while tracing
            return fn(*args)

        counted.__name__ = name  # names the program's file on disk
        return counted

    @property
    def compiled(self) -> bool:
        return bool(self.programs)

    def _episodes(self, state, keys, control: dict, parts: list[int]) -> None:
        """Parts ``parts``' episodes under ``control`` (host arrays ``[S]`` per field), their
        carries updated in ``self._carries``."""
        dtypes = dict(evaluate=bool, idle=bool, start=bool, switch=np.int32, until=np.int32)
        control = Control(**{k: np.asarray(v, dtypes[k]) for k, v in control.items()})
        args = self.lanes.episodes_args(state, keys, control)
        for p in parts:
            self._carries[p] = self.parts[p](*args, self.lanes.placed(self._carries[p]))

    def collect(self, state: TrainerState, keys, evaluate, idle) -> tuple[TrainerState, RoundStats]:
        """One round's episodes of every lane, stored (module docstring)."""
        trainer, s = self.trainer, self.lanes.num_lanes
        evaluate, idle = np.asarray(evaluate, bool), np.asarray(idle, bool)
        quiet = evaluate | idle  # lanes that act without the warm-up, or not at all
        if self._carries is None:
            self._carries = self.lanes.carries()
        parts = list(range(len(self._carries)))
        env_steps = np.atleast_1d(jax.device_get(state.env_steps)).tolist()
        switch = [
            0 if q else trainer.warmup_switch(e) for q, e in zip(quiet, env_steps, strict=True)
        ]
        control = dict(evaluate=evaluate, idle=idle, start=np.ones(s, bool), until=np.zeros(s))
        crossing = [x is None for x in switch]
        if any(crossing):  # the warm-up ends in this round: its episodes' lengths first
            limit = trainer.config.env.max_episode_steps
            at_random = [limit if c else x for c, x in zip(crossing, switch, strict=True)]
            self._episodes(state, keys, control | dict(switch=at_random), parts)
            lengths = np.concatenate([_lanes(c.length, s) for c in self._carries], axis=1)
            switch = [
                trainer.warmup_switch(e, lengths[i]) if crossing[i] else switch[i]
                for i, e in enumerate(env_steps)
            ]
        control["switch"] = switch
        self._episodes(state, keys, control, parts)
        if not quiet.all():
            # Parts that finished first step on to where the last one ended (per lane).
            ends = np.stack([_lanes(c.t, s)[:, 0] for c in self._carries])  # [P, S]
            last = np.where(quiet, 0, ends.max(axis=0))
            behind = [p for p in parts if (ends[p] < last).any()]
            control |= dict(start=np.zeros(s, bool), until=last)
            self._episodes(state, keys, control, behind)
        return self.close(*self.lanes.close_args(state, tuple(self._carries), evaluate))

    @property
    def evaluates_apart(self) -> bool:
        """Whether evaluations run in programs of their own (``eval_envs``)."""
        return bool(self.evaluations)

    def evaluate(self, state: TrainerState, keys) -> tuple[np.ndarray, np.ndarray]:
        """(return, length) of a deterministic episode of every evaluation environment of
        every lane from its key (``keys [S]``), ``[M, eval_envs]`` (lanes: ``[S, M,
        eval_envs]``) on the host; the state is left as it was."""
        args = self.lanes.evaluation_args(state, keys)
        outs = jax.device_get([evaluation(*args) for evaluation in self.evaluations])
        order = self.trainer._suite_order  # the parts' robots in suite order

        def suite(i: int) -> np.ndarray:
            return np.concatenate([out[i] for out in outs], axis=-2)[..., order, :]

        return suite(0), suite(1)

    def train(self, state: TrainerState, steps, live) -> tuple[TrainerState, dict]:
        """The round's re-clustering and TD3 iterations of every ``live`` lane."""
        return self.train_program(*self.lanes.train_args(state, steps, live))

    def compile(self, state: TrainerState) -> None:
        """The programs for ``state``'s shapes, compiled ahead of time (module docstring);
        nothing is compiled or traced when they exist already."""
        slots = state.replay.capacity
        new_parts = self.part_programs is None
        new_update = slots not in self.programs
        if new_parts or new_update:
            episodes_args, close_args, train_args, evaluation_args = self.lanes.compile_args(state)
            options = dict(donate_argnums=(0,), fingerprint=self.lanes.fingerprint)
            physics = dict(
                donate_argnums=(3,),
                fingerprint=self.lanes.fingerprint,
                compiler_options=physics_compiler_options(),
            )
            physics_kept = physics | dict(donate_argnums=())
            parts, close, train, evaluations = self._functions
            # The largest part first (its compile starts soonest), then the update, whose
            # compile is as long as a large part's; the evaluations after them.
            order = sorted(range(len(parts)), key=lambda p: -_size(self.trainer.parts[p]))
            jobs = [(("part", p), (parts[p], episodes_args[p], physics)) for p in order]
            if evaluations:
                jobs += [
                    (("evaluation", p), (evaluations[p], evaluation_args, physics_kept))
                    for p in order
                ]
            jobs = jobs if new_parts else []
            if new_update:
                at = min(1, len(jobs))
                jobs[at:at] = [("train", (train, train_args, options))]
                jobs += [("close", (close, close_args, options))]
            compiled = compile_programs([job for _, job in jobs], self.compile_timings)
            compiled = dict(zip([name for name, _ in jobs], compiled, strict=True))
            if new_parts:
                self.part_programs = [compiled["part", p] for p in range(len(parts))]
                self.evaluation_programs = [
                    compiled["evaluation", p] for p in range(len(evaluations))
                ]
            if new_update:
                self.programs[slots] = (compiled["close"], compiled["train"])
        self.parts = list(self.part_programs)
        self.evaluations = list(self.evaluation_programs)
        self.close, self.train_program = self.programs[slots]


def round_programs(config: TrainConfig, num_lanes: int = 1) -> RoundPrograms:
    """The round of ``num_lanes`` runs of ``config``'s trainer (one: ``SingleLane``)."""
    trainer = Trainer(config)
    return RoundPrograms(SingleLane(trainer) if num_lanes == 1 else Lanes(trainer, num_lanes))


def play_round(programs: RoundPrograms, state, live: np.ndarray | None = None) -> tuple:
    """One training round of every ``live`` lane (default: all; the others idle), timed:
    (state, RoundStats, train metrics, (collect s, train s)), stats and metrics on the
    host."""
    count = programs.lanes.num_lanes
    live = np.ones(count, bool) if live is None else live
    keys = jax.random.split(jax.random.PRNGKey(0), count)  # read by no live lane
    start = time.perf_counter()
    state, stats = programs.collect(state, keys, ~live, ~live)
    stats = jax.device_get(stats)
    collected = time.perf_counter()
    state, metrics = programs.train(state, stats.steps, live)
    metrics = jax.device_get(metrics)
    return state, stats, metrics, (collected - start, time.perf_counter() - collected)


def _size(env) -> int:
    """A part's degrees of freedom: what its compile grows with."""
    return sum(world.model.nv for world in env.worlds)


def _lanes(x, lanes: int) -> np.ndarray:
    """A carry's field on the host as ``[S, ...]`` (a single run's has no lane axis)."""
    x = np.asarray(jax.device_get(x))
    return x.reshape(lanes, -1)
