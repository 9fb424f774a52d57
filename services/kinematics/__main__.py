"""`python -m asibot.kinematics --robot asibot-sim [--rate 100]`: the Cartesian control server."""

from __future__ import annotations

import argparse
import dataclasses

from asibot import runtime


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--rate", type=float, default=100.0, help="control loop rate, Hz (default 100)")
    parser.add_argument("--solver", choices=["asibot", "pinocchio"], default=None,
                        help="kinematics solver (default: the robot catalog's; the ASIBOT can use "
                             "the generic Pinocchio solver instead of its closed form)")


def build(bus, args: argparse.Namespace):
    from asibot.kinematics.server import KinematicsServer
    try:
        from asibot import robots
        from asibot.kinematics.model import solver_for
    except ImportError as exc:
        raise RuntimeError(f"the robot catalog or solver is missing ({exc}); "
                           "reinstall the project (pip install -e .)") from exc

    if not args.robot:
        raise SystemExit("--robot is required: asibot-sim, asibot, pioneer-sim or pioneer")
    spec = robots.get(args.robot)
    if args.solver:
        if args.solver == "asibot" and spec.arm != "asibot":
            raise SystemExit(f"--solver asibot is the ASIBOT's closed form; {args.robot} has a {spec.arm} arm")
        spec = dataclasses.replace(spec, solver=args.solver)
    return KinematicsServer(bus, args.robot, solver_for(spec), spec, rate=args.rate)


if __name__ == "__main__":
    raise SystemExit(runtime.run("kinematics", build, add_arguments=add_arguments))
