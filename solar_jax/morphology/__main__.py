"""``python -m solar_jax.morphology list | show NAME | build [--out DIR] [--check]``."""

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

from solar_jax.morphology import ROBOTS, SUITES, MorphologyError, load, write_all

_DEFAULT_OUT = Path(__file__).resolve().parents[2] / "morphologies"


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
        print(f"out of date in {out}: {', '.join(stale)}; run without --check", file=sys.stderr)
        return 1
    print(f"{len(ROBOTS)} files in {out} are up to date")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m solar_jax.morphology", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="every suite and robot")
    show = sub.add_parser("show", help="one robot's tree, distances and traversal indices")
    show.add_argument("name", help="a robot name or an MJCF path")
    build = sub.add_parser("build", help="write morphologies/<name>.xml for every robot")
    build.add_argument("--out", type=Path, default=_DEFAULT_OUT)
    build.add_argument("--check", action="store_true", help="fail if the files are stale")
    args = parser.parse_args(argv)
    try:
        if args.command == "list":
            _list()
        elif args.command == "show":
            _show(args.name)
        else:
            return _build(args.out, args.check)
    except MorphologyError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
