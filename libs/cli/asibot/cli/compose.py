"""compose.yaml as the single list of services: parsed once, for the launcher and the tests."""

from __future__ import annotations

import dataclasses
import os
import re
import shlex
from pathlib import Path
from typing import Any

import yaml

RESTART_POLICIES = ("no", "always", "on-failure", "unless-stopped")
PROFILES = ("sim", "emulated", "real")
URL_LABEL = "asibot.url"


class ComposeError(ValueError):
    """compose.yaml says something the launcher cannot run; the message says where."""


@dataclasses.dataclass
class ServiceSpec:
    name: str
    command: list[str]
    environment: dict[str, str]
    profiles: list[str]
    restart: str
    depends_on: list[str]
    url: str | None = None

    def active(self, profile: str) -> bool:
        return not self.profiles or profile in self.profiles


def _environment(name: str, env: Any) -> dict[str, str]:
    if env is None:
        return {}
    if isinstance(env, dict):
        return {str(k): "" if v is None else str(v) for k, v in env.items()}
    if isinstance(env, list):
        out = {}
        for item in env:
            k, sep, v = str(item).partition("=")
            out[k] = v if sep else ""
        return out
    raise ComposeError(f"service {name}: environment must be a map or a list of KEY=VALUE")


_VARIABLE = re.compile(r"\$(?:(\$)|\{([A-Za-z_][A-Za-z0-9_]*)(?:(:?[-?])([^}]*))?\}|([A-Za-z_][A-Za-z0-9_]*))")


def interpolate(value: Any, env: dict[str, str], where: str = "compose.yaml") -> Any:
    """Substitute `${VAR}`, `${VAR:-default}`, `${VAR-default}`, `${VAR:?message}` and `$$`
    the way `docker compose` does, so the launcher runs exactly what a container would."""
    if isinstance(value, dict):
        return {k: interpolate(v, env, f"{where}.{k}") for k, v in value.items()}
    if isinstance(value, list):
        return [interpolate(v, env, where) for v in value]
    if not isinstance(value, str):
        return value

    def one(m: re.Match) -> str:
        dollar, name, op, arg, bare = m.groups()
        if dollar:
            return "$"
        name = name or bare
        present = name in env
        empty = not env.get(name)
        if op in (":-", "-"):
            missing = empty if op == ":-" else not present
            return arg if missing else env[name]
        if op in (":?", "?"):
            missing = empty if op == ":?" else not present
            if missing:
                raise ComposeError(f"{where}: {arg or f'set the environment variable {name}'}")
            return env[name]
        return env.get(name, "")

    return _VARIABLE.sub(one, value)


def parse(text: str, env: dict[str, str] | None = None) -> dict[str, ServiceSpec]:
    """Parse compose text; `${VAR}` references are filled from `env` (default: os.environ)."""
    data = yaml.safe_load(text)
    if isinstance(data, dict) and isinstance(data.get("services"), dict):
        data["services"] = interpolate(data["services"], dict(os.environ) if env is None else env,
                                       "services")
    if not isinstance(data, dict) or not isinstance(data.get("services"), dict):
        raise ComposeError("compose.yaml needs a top-level 'services' map")
    services: dict[str, ServiceSpec] = {}
    for name, body in data["services"].items():
        if not isinstance(body, dict):
            raise ComposeError(f"service {name}: expected a map")
        command = body.get("command")
        if isinstance(command, str):
            command = shlex.split(command)
        if not isinstance(command, list) or not command:
            raise ComposeError(f"service {name}: needs a command (the launcher runs it as a process)")
        restart = str(body.get("restart", "no"))
        if restart.split(":")[0] not in RESTART_POLICIES:
            raise ComposeError(f"service {name}: restart must be one of {', '.join(RESTART_POLICIES)}")
        profiles = list(body.get("profiles") or [])
        unknown = [p for p in profiles if p not in PROFILES]
        if unknown:
            raise ComposeError(f"service {name}: unknown profile(s) {unknown}; use {', '.join(PROFILES)}")
        deps = body.get("depends_on") or []
        if isinstance(deps, dict):
            deps = list(deps)
        labels = body.get("labels") or {}
        if isinstance(labels, list):
            labels = dict(str(x).partition("=")[::2] for x in labels)
        services[name] = ServiceSpec(
            name=name, command=[str(c) for c in command],
            environment=_environment(name, body.get("environment")),
            profiles=profiles, restart=restart.split(":")[0], depends_on=[str(d) for d in deps],
            url=labels.get(URL_LABEL),
        )
    for spec in services.values():
        for dep in spec.depends_on:
            if dep not in services:
                raise ComposeError(f"service {spec.name}: depends on unknown service {dep}")
    return services


def load(path: Path | str) -> dict[str, ServiceSpec]:
    p = Path(path)
    if not p.exists():
        raise ComposeError(f"{p} not found: run `asibot up` from the repository root or pass --file")
    return parse(p.read_text())


def select(services: dict[str, ServiceSpec], profile: str, only: list[str] | None = None) -> list[ServiceSpec]:
    """The services to start, dependencies first. `only` keeps those (and what they depend on)."""
    if profile not in PROFILES:
        raise ComposeError(f"unknown profile {profile!r}; use {', '.join(PROFILES)}")
    chosen = [s for s in services.values() if s.active(profile)]
    if only:
        missing = [n for n in only if n not in services]
        if missing:
            raise ComposeError(f"no service named {', '.join(missing)} in compose.yaml "
                               f"(known: {', '.join(services)})")
        keep: set[str] = set()
        todo = list(only)
        while todo:
            n = todo.pop()
            if n not in keep:
                keep.add(n)
                todo.extend(services[n].depends_on)
        chosen = [s for s in chosen if s.name in keep] + [
            services[n] for n in only if not services[n].active(profile)]
    # Topological order, stable with respect to the file.
    ordered: list[ServiceSpec] = []
    placed: set[str] = set()
    names = {s.name for s in chosen}
    while len(ordered) < len(chosen):
        progress = False
        for s in chosen:
            if s.name not in placed and all(d in placed or d not in names for d in s.depends_on):
                ordered.append(s)
                placed.add(s.name)
                progress = True
        if not progress:
            raise ComposeError("depends_on forms a cycle")
    return ordered
