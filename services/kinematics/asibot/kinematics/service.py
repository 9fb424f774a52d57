"""The kinematics service: one Cartesian control server per robot (`--robot asibot-sim`)."""

from __future__ import annotations

import argparse
import dataclasses

from asibot import robots, runtime
from asibot.bus import Bus
from asibot.kinematics.model import solver_for
from asibot.kinematics.server import KinematicsServer

NAME = "kinematics"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--rate", type=float, default=100.0, help="control loop rate, Hz (default 100)")
    parser.add_argument("--solver", choices=["asibot", "pinocchio"], default=None,
                        help="kinematics solver (default: the robot catalog's; the ASIBOT can use "
                             "the generic Pinocchio solver instead of its closed form)")


def build(bus: Bus, args: argparse.Namespace) -> KinematicsServer:
    # No default: which arm to control is the user's choice.
    robot = runtime.robot_id(args, example="asibot-sim, asibot, pioneer-sim or pioneer")
    try:
        spec = robots.get(robot)
    except KeyError as exc:
        raise ValueError(exc.args[0]) from None
    if args.solver:
        if args.solver == "asibot" and spec.arm != "asibot":
            raise ValueError(f"--solver asibot is the ASIBOT's closed form; {robot} has a {spec.arm} arm")
        spec = dataclasses.replace(spec, solver=args.solver)
    return KinematicsServer(bus, robot, solver_for(spec), spec, rate=args.rate)
