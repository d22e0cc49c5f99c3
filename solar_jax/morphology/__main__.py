"""``python -m solar_jax.morphology list | show NAME | build [out=DIR] [check=true]``

- ``list``: every suite (training and held-out robots, N_max) and robot.
- ``show NAME``: one robot (a name or an MJCF path): its tree, joint ranges, limb types,
  gears, hop distances and traversal indices.
- ``build``: writes ``morphologies/<name>.xml`` for every robot; ``check=true`` only
  compares them with the committed files (exit 1 when stale).
"""

import dataclasses
import sys
import tempfile
from pathlib import Path

import numpy as np

from solar_jax.cli import help_text, parse_overrides, wants_help
from solar_jax.config import ConfigError
from solar_jax.experiments import one_line_errors
from solar_jax.morphology import ROBOTS, SUITES, load, write_all

_DEFAULT_OUT = Path(__file__).resolve().parents[2] / "morphologies"


@dataclasses.dataclass(frozen=True)
class BuildOptions:
    """The ``key=value`` options of ``build``."""

    out: str = str(_DEFAULT_OUT)
    """Folder the MJCF files are written to (or compared with)."""

    check: bool = False
    """Compare the files in ``out`` with what ``build`` would write; write nothing."""


def _list() -> None:
    robots = {name: load(name) for name in ROBOTS}  # each compiled once
    print("suites (train | held out):")
    for suite in SUITES.values():
        n_max = max(robots[name].num_agents for name in suite.members)
        train, held_out = " ".join(suite.train), " ".join(suite.held_out)
        print(f"  {suite.name:<11} N_max {n_max}  train {len(suite.train):>2}: {train}")
        if suite.held_out:
            print(f"  {'':<11} {'':<7}  held out {len(suite.held_out)}: {held_out}")
    print("\nrobots (agents = bodies, actuators = agents - 1):")
    for name, m in robots.items():
        print(f"  {name:<26} {m.family:<12} agents {m.num_agents}  actuators {m.num_actuators}")


def _show(name: str) -> None:
    m = load(name)
    print(f"{m.name} ({m.family}, {m.source}): {m.num_agents} agents, {m.num_actuators} actuators")
    print(f"dt {m.dt:g} s = timestep {m.model.opt.timestep:g} x frame_skip {m.task.frame_skip}")
    print(f"task: {m.task}")
    print("\ntree (agent, parent, joint, range in degrees, limb type, actuator, gear):")
    depth = [0] * m.num_agents
    for i, (body, parent) in enumerate(zip(m.agents, m.parents, strict=True)):
        depth[i] = depth[parent] + 1 if parent >= 0 else 0
        kind = m.limb_types[i]
        kind_name = m.limb_type_names[kind] if kind >= 0 else "none"
        a = m.actuators[i]
        drive = f"actuator {a} gear {m.model.actuator_gear[a, 0]:g}" if a >= 0 else "root"
        lo, hi = m.joint_range[i]
        print(
            f"  {i:>2} {'  ' * depth[i]}{body:<{20 - 2 * depth[i]}} parent {parent:>2}  "
            f"{m.joints[i] or '-':<16} [{lo:>6.1f}, {hi:>6.1f}]  {kind_name:<10} {drive}"
        )
    with np.printoptions(linewidth=120):
        print("\nhop distances:")
        print(m.hop_distances)
        print("\nleft-child right-sibling traversal indices (pre, in, post) per agent:")
        print(m.traversal.tolist())


def _build(out: Path, check: bool) -> int:
    if not check:
        paths = write_all(out)
        print(f"wrote {len(paths)} files to {out}")
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        stale = [
            p.name
            for p in write_all(tmp)
            if not (out / p.name).is_file() or (out / p.name).read_text() != p.read_text()
        ]
    if stale:
        print(f"out of date in {out}: {', '.join(stale)}; run without check=true", file=sys.stderr)
        return 1
    print(f"{len(ROBOTS)} files in {out} are up to date")
    return 0


COMMANDS = ("list", "show", "build")


def run(argv: list[str]) -> int:
    """One command line; bad input raises (``one_line_errors`` turns it into one line)."""
    if not argv or argv[0] not in COMMANDS:
        raise ConfigError(f"expected one of {', '.join(COMMANDS)}: python -m solar_jax.morphology")
    command, rest = argv[0], argv[1:]
    if command == "list" and not rest:
        _list()
    elif command == "show" and len(rest) == 1 and "=" not in rest[0]:
        _show(rest[0])
    elif command == "build":
        options = parse_overrides(BuildOptions(), rest)
        return _build(Path(options.out), options.check)
    else:
        usage = {"list": "list", "show": "show NAME", "build": "build [out=DIR] [check=true]"}
        raise ConfigError(f"{' '.join(argv)}: expected {usage[command]}")
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if wants_help(argv)[0]:
        print(help_text(BuildOptions(), __doc__))
        return 0
    return one_line_errors(run, argv)


if __name__ == "__main__":
    sys.exit(main())
