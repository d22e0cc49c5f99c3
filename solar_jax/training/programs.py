"""The round's programs, compiled: jitted, or ahead of time per replay size.

``RoundPrograms(lanes)`` jits the three pure functions of ``lanes`` (a ``SingleLane`` or
``Lanes``, ``solar_jax.training.lanes``) and counts their traces:

    collect(state, keys[S], evaluate[S], idle[S]) -> (state, RoundStats)
        ``episodes`` then ``store``: one round of every lane (``evaluate``: deterministic,
        nothing stored or counted; ``idle``: no episode at all)
    train(state, steps, live[S])                  -> (state, metrics)

``compile(state)`` points them at programs compiled ahead of time (so timings exclude
compilation): ``episodes`` once with ``physics_compiler_options``, ``store`` and
``train`` the first time a replay size is seen, all through the programs kept on disk
under the trainer's fingerprint (``compile_program``), in threads
(``compile_programs``). After it, a call with other shapes fails instead of retracing.
"""

import jax

from solar_jax.compilation_cache import (
    compile_programs,
    jit_physics,
    physics_compiler_options,
)
from solar_jax.training.trainer import RoundStats, TrainerState


class RoundPrograms:
    """The compiled round of ``lanes``; ``traces`` counts each program's traces."""

    def __init__(self, lanes):
        self.lanes = lanes
        self.trainer = lanes.trainer
        self.traces = {"collect": 0, "store": 0, "train": 0}
        self.episodes_program = None  # compiled ahead of time by ``compile``
        self.programs = {}  # replay slots -> (store, train), compiled ahead of time
        self._functions = (
            self._counted("collect", lanes.episodes, "episodes"),
            self._counted("store", lanes.store, "store"),
            self._counted("train", lanes.train, "train"),
        )
        episodes, store, train = self._functions
        self.episodes = jit_physics(episodes, donate_argnums=0)  # as ``compile``'s
        self.store = jax.jit(store, donate_argnums=0)
        self.train_program = jax.jit(train, donate_argnums=0)

    def _counted(self, what: str, fn, name: str):
        def counted(*args):
            self.traces[what] += 1  # runs only while tracing
            return fn(*args)

        counted.__name__ = name  # names the program's file on disk
        return counted

    @property
    def compiled(self) -> bool:
        return bool(self.programs)

    def collect(self, state: TrainerState, keys, evaluate, idle) -> tuple[TrainerState, RoundStats]:
        """One round's episodes of every lane, stored."""
        replay = state.replay
        args = self.lanes.episodes_args(state, keys, evaluate, idle)
        state, stats, staged = self.episodes(*args)
        return state.replace(replay=self.store(replay, staged)), stats

    def train(self, state: TrainerState, steps, live) -> tuple[TrainerState, dict]:
        """The round's re-clustering and TD3 iterations of every ``live`` lane."""
        return self.train_program(*self.lanes.train_args(state, steps, live))

    def compile(self, state: TrainerState) -> None:
        """The programs for ``state``'s shapes, compiled ahead of time (module docstring);
        nothing is compiled or traced when they exist already."""
        slots = state.replay.capacity
        new_episodes = self.episodes_program is None
        new_update = slots not in self.programs
        if new_episodes or new_update:
            episodes_args, store_args, train_args = self.lanes.compile_args(state)
            options = dict(donate_argnums=(0,), fingerprint=self.lanes.fingerprint)
            physics = dict(options, compiler_options=physics_compiler_options())
            episodes, store, train = self._functions
            jobs = [(episodes, episodes_args, physics)] if new_episodes else []
            if new_update:
                jobs += [(store, store_args, options), (train, train_args, options)]
            compiled = compile_programs(jobs)
            if new_episodes:
                self.episodes_program = compiled.pop(0)
            if new_update:
                self.programs[slots] = tuple(compiled)
        self.episodes = self.episodes_program
        self.store, self.train_program = self.programs[slots]
