#!/usr/bin/env python3
"""Checks the container setup (docker/Dockerfile, docker/compose.yaml) without
Docker: the CI machine cannot pull base images, so this is what stands in for
`docker build` there.

    scripts/check_container.py [--dockerfile F] [--compose F] [--binary build/client/outcore]

The Dockerfile's last stage (the image that ships) must start from
debian:12-slim, install no compiler or -dev package, take only files from the
build stage (never the source tree), run as a non-root user, expose 50051
(gRPC) and 9464 (metrics), have a HEALTHCHECK running `outcore health`, and an
ENTRYPOINT. The packages it installs must exist in Debian 12 (asked of
apt-cache when this machine is Debian 12 with package lists). With --binary,
every shared library `ldd` reports for the binary must come (by `dpkg -S`)
from a package the runtime stage installs or from one debian:12-slim already
has (SLIM_BASE). compose.yaml must run a service built from the Dockerfile
that publishes both ports, mounts the store read-only at /data, logs JSON and
restarts.

Every problem is reported with FILE:LINE; exit 0 when there is none, 1 when
there are (a file that cannot be parsed is one), 2 when a file is missing. Standard library only:
compose.yaml is read by a small, strict YAML subset parser (block mappings and
sequences, one-line flow sequences of scalars, quoted and plain scalars) that
refuses anything else rather than guess.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
REQUIRED_PORTS = (50051, 9464)
STORE_MOUNT = "/data"

# Packages debian:12-slim ships (Priority: required, kept by the slim variant)
# that the runtime stage relies on without installing them. Only these count:
# a library from any other package must be installed explicitly, so the image
# does not depend on what happens to be in the base today.
SLIM_BASE = {
    "libc6": "libc, libm, the dynamic loader: everything depends on it",
    "libgcc-s1": "needed by apt and libstdc++6",
    "libstdc++6": "needed by apt (libapt-pkg)",
    "zlib1g": "needed by dpkg",
}

# Build tools the runtime image must not carry (besides every *-dev package).
BUILD_TOOLS = re.compile(
    r"^(build-essential|cmake|ninja-build|make|pkg-config|pkgconf|"
    r"(gcc|g\+\+|cpp|clang|clang\+\+|gfortran)(-\d+)?)$")
SLIM_IMAGE = re.compile(r"^debian:(12(\.\d+)*|bookworm(-\d{8})?)-slim$")


# --------------------------------------------------------------------------
# Problems and output


class Report:
    def __init__(self):
        self.problems: list[str] = []
        self.checked: list[str] = []
        self.notes: list[str] = []

    def problem(self, path: Path, line: int | None, message: str):
        where = f"{shown(path)}:{line}" if line else shown(path)
        self.problems.append(f"{where}: {message}")

    def ok(self, message: str):
        self.checked.append(message)

    def note(self, message: str):
        self.notes.append(message)


def shown(path: Path) -> str:
    try:
        return str(Path(path).resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


class ParseError(Exception):
    def __init__(self, line: int, message: str):
        super().__init__(message)
        self.line = line


# --------------------------------------------------------------------------
# Dockerfile


@dataclass
class Instruction:
    line: int
    keyword: str  # upper case
    args: str     # continuation lines joined


@dataclass
class Stage:
    line: int
    base: str
    name: str | None
    instructions: list[Instruction] = field(default_factory=list)

    def all(self, keyword: str) -> list[Instruction]:
        return [i for i in self.instructions if i.keyword == keyword]


def read_instructions(text: str) -> list[Instruction]:
    escape = "\\"
    # Parser directives (`# escape=``), only at the very top, can change the
    # continuation character.
    for raw in text.splitlines():
        directive = re.match(r"^#\s*(\w+)\s*=\s*(\S+)\s*$", raw)
        if not directive:
            break
        if directive.group(1).lower() == "escape":
            escape = directive.group(2)
    instructions: list[Instruction] = []
    parts: list[str] = []
    start = 0
    for number, raw in enumerate(text.splitlines(), 1):
        stripped = raw.strip()
        # Docker drops comment and empty lines, also inside a continuation.
        if not stripped or stripped.startswith("#"):
            continue
        if not parts:
            start = number
        body = raw.rstrip()
        if body.endswith(escape):
            parts.append(body[:-1])
            continue
        parts.append(body)
        instructions.append(_instruction(start, " ".join(p.strip() for p in parts)))
        parts = []
    if parts:
        instructions.append(_instruction(start, " ".join(p.strip() for p in parts)))
    return instructions


def _instruction(line: int, text: str) -> Instruction:
    keyword, _, args = text.partition(" ")
    if keyword.upper() in ("RUN", "COPY", "ADD") and re.search(r"<<-?\s*['\"]?[A-Za-z_]", args):
        raise ParseError(line, "heredocs (<<EOF) are not understood by this checker; write the "
                               "command on continuation lines")
    return Instruction(line, keyword.upper(), args.strip())


def split_stages(instructions: list[Instruction]) -> list[Stage]:
    args_before: dict[str, str] = {}
    stages: list[Stage] = []
    for ins in instructions:
        if ins.keyword == "FROM":
            words = [w for w in ins.args.split() if not w.startswith("--")]
            if not words:
                raise ParseError(ins.line, "FROM without an image")
            base = _expand(words[0], args_before)
            name = words[2] if len(words) >= 3 and words[1].lower() == "as" else None
            stages.append(Stage(ins.line, base, name))
        elif not stages:
            if ins.keyword == "ARG":
                key, _, value = ins.args.partition("=")
                args_before[key.strip()] = value.strip().strip('"\'')
            else:
                raise ParseError(ins.line, f"{ins.keyword} before the first FROM")
        else:
            stages[-1].instructions.append(ins)
    return stages


def _expand(text: str, values: dict[str, str]) -> str:
    def one(match):
        name = match.group(1) or match.group(3)
        default = match.group(2)
        return values.get(name) or (default or "")
    return re.sub(r"\$\{(\w+)(?::?-([^}]*))?\}|\$(\w+)", one, text)


def normalise_image(image: str) -> str:
    image = image.split("@", 1)[0]  # a digest pins, it does not rename
    for prefix in ("docker.io/library/", "docker.io/", "library/"):
        if image.startswith(prefix):
            image = image[len(prefix):]
    return image


def shell_commands(ins: Instruction) -> list[list[str]]:
    """The simple commands of a RUN (shell or exec form), each as its words,
    redirections removed."""
    if ins.args.startswith("["):
        try:
            words = json.loads(ins.args)
        except json.JSONDecodeError as error:
            raise ParseError(ins.line, f"exec form is not a JSON array: {error}") from None
        if len(words) >= 3 and os.path.basename(words[0]) in ("sh", "bash") and words[1] == "-c":
            script = words[2]
        else:
            return [words]
    else:
        script = ins.args
    lexer = shlex.shlex(script, posix=True, punctuation_chars=True)
    lexer.whitespace_split = True
    try:
        tokens = list(lexer)
    except ValueError as error:
        raise ParseError(ins.line, f"cannot split the shell command: {error}") from None
    commands, current, skip = [], [], False
    for token in tokens:
        if skip:
            skip = False
            continue
        if token in ("&&", "||", ";", "|", "&", "(", ")", ";;", "|&"):
            if current:
                commands.append(current)
            current = []
        elif token and set(token) <= set("<>&"):
            skip = True  # the redirection's target
            if current and current[-1].isdigit():
                current.pop()  # its file descriptor (2>)
        else:
            current.append(token)
    if current:
        commands.append(current)
    return commands


APT_OPTIONS_WITH_VALUE = {"-o", "-c", "-t", "--option", "--config-file", "--target-release"}


def apt_installs(ins: Instruction) -> list[tuple[list[str], list[str]]]:
    """(packages, options) of each `apt-get install` / `apt install` in a RUN."""
    found = []
    for words in shell_commands(ins):
        while words and (re.match(r"^\w+=", words[0]) or words[0] in ("sudo", "env", "command")):
            words = words[1:]
        if not words or os.path.basename(words[0]) not in ("apt-get", "apt", "aptitude"):
            continue
        rest = words[1:]
        options, operands, expect_value = [], [], False
        for word in rest:
            if expect_value:
                expect_value = False
            elif word.startswith("-"):
                options.append(word)
                expect_value = word in APT_OPTIONS_WITH_VALUE
            else:
                operands.append(word)
        if operands and operands[0] == "install":
            found.append((operands[1:], options))
    return found


def package_name(word: str) -> str:
    # foo=1.2, foo/bookworm-backports, foo:amd64 all install foo.
    return re.split(r"[=/]", word, maxsplit=1)[0].split(":", 1)[0]


@dataclass
class Runtime:
    packages: dict[str, int]  # package -> line of the RUN installing it


def check_dockerfile(path: Path, report: Report) -> Runtime | None:
    try:
        stages = split_stages(read_instructions(path.read_text()))
    except ParseError as error:
        report.problem(path, error.line, str(error))
        return None
    if len(stages) < 2:
        report.problem(path, stages[0].line if stages else None,
                       f"{len(stages)} stage(s): the image needs a build stage and a runtime stage "
                       "(multi-stage), so the compiler and sources stay out of it")
        if not stages:
            return None
    runtime = stages[-1]
    label = "the runtime stage"
    earlier = {s.name.lower(): s for s in stages[:-1] if s.name}
    base = normalise_image(runtime.base)
    if base.lower() in earlier:
        report.problem(path, runtime.line, f"{label} is FROM stage '{runtime.base}': it inherits that "
                                           "stage's compiler, -dev packages and sources; start it FROM "
                                           "debian:12-slim")
    elif not SLIM_IMAGE.match(base):
        report.problem(path, runtime.line, f"{label} is FROM {runtime.base}, not debian:12-slim")
    else:
        report.ok(f"{len(stages)} stages; runtime stage FROM {runtime.base}")

    packages = _check_packages(path, runtime, label, report)
    copies = _check_copies(path, runtime, stages, label, report)
    _check_user(path, runtime, label, report)
    _check_expose(path, runtime, label, report)
    _check_healthcheck(path, runtime, label, report)
    _check_entrypoint(path, runtime, label, copies, report)
    return Runtime(packages)


def _check_packages(path, runtime, label, report) -> dict[str, int]:
    packages: dict[str, int] = {}
    for ins in runtime.all("RUN"):
        try:
            installs = apt_installs(ins)
        except ParseError as error:
            report.problem(path, error.line, str(error))
            continue
        for words, options in installs:
            if "--no-install-recommends" not in options:
                report.problem(path, ins.line, f"{label}: apt-get install without --no-install-recommends "
                                               "(recommended packages bloat the image)")
            for word in words:
                if "$" in word:
                    report.problem(path, ins.line, f"{label} installs '{word}': the checker cannot see "
                                                   "package names through a variable; list them")
                    continue
                packages[package_name(word)] = ins.line
        if installs and not ("/var/lib/apt/lists" in ins.args and re.search(r"\brm\b", ins.args)):
            report.problem(path, ins.line, f"{label}: the RUN installing packages does not remove "
                                           "/var/lib/apt/lists/* (the package lists would stay in the layer)")
    for name, line in packages.items():
        if name.endswith("-dev") or name.endswith("-dev-bin"):
            report.problem(path, line, f"{label} installs {name}, a -dev package (headers and link "
                                       "files, no use at run time); install the runtime library instead")
        elif BUILD_TOOLS.match(name):
            report.problem(path, line, f"{label} installs {name}, a build tool; the runtime image "
                                       "needs only the binary's shared libraries")
    if packages:
        report.ok(f"runtime stage installs {len(packages)} packages, none -dev or a build tool: "
                  + " ".join(sorted(packages)))
    return packages


def _check_copies(path, runtime, stages, label, report) -> set[str]:
    """Checks that files come only from other stages; returns where they land."""
    workdirs = {}
    for stage in stages[:-1]:
        workdir = "/"
        for ins in stage.all("WORKDIR"):
            workdir = os.path.normpath(os.path.join(workdir, ins.args.strip('"')))
        for key in (stage.name, str(stages.index(stage))):
            if key:
                workdirs[key.lower()] = workdir
    destinations, workdir, count = set(), "/", 0
    for ins in runtime.instructions:
        if ins.keyword == "WORKDIR":
            workdir = os.path.normpath(os.path.join(workdir, ins.args.strip('"')))
        if ins.keyword not in ("COPY", "ADD"):
            continue
        count += 1
        try:
            words = json.loads(ins.args) if ins.args.startswith("[") else ins.args.split()
        except json.JSONDecodeError as error:
            report.problem(path, ins.line, f"{label}: {ins.keyword} is not a JSON array: {error}")
            continue
        flags = [w for w in words if w.startswith("--")]
        operands = [w for w in words if not w.startswith("--")]
        source_stage = next((f.split("=", 1)[1] for f in flags if f.startswith("--from=")), None)
        if ins.keyword == "ADD" or source_stage is None:
            report.problem(path, ins.line, f"{label}: {ins.keyword} without --from copies from the build "
                                           "context (the source tree); take only the built binary from "
                                           "the build stage with COPY --from=build")
            continue
        if len(operands) < 2:
            report.problem(path, ins.line, f"{label}: COPY needs a source and a destination")
            continue
        *sources, destination = operands
        tree = workdirs.get(source_stage.lower())
        for source in sources:
            normal = os.path.normpath(source) if source.startswith("/") else source.rstrip("/")
            if normal in ("", ".", "/", "*") or (tree and normal in (tree, os.path.join(tree, "."))):
                report.problem(path, ins.line, f"{label} copies {source} from stage {source_stage}: its "
                                               "whole tree (sources included); copy the binary only")
        into_directory = destination.endswith("/") or len(sources) > 1
        destination = os.path.normpath(os.path.join(workdir, destination))
        if into_directory:
            destinations.update(os.path.join(destination, os.path.basename(s.rstrip("/"))) for s in sources)
        else:
            destinations.add(destination)
    if count:
        report.ok(f"runtime stage copies only from other stages: {' '.join(sorted(destinations))}")
    return destinations


def _check_user(path, runtime, label, report):
    users = runtime.all("USER")
    if not users:
        report.problem(path, runtime.line, f"{label} has no USER: the server would run as root")
        return
    user = users[-1]
    name = user.args.split(":", 1)[0].strip()
    if "$" in name:
        report.problem(path, user.line, f"{label}: USER {user.args} uses a variable the checker "
                                        "cannot resolve; give the user or uid")
    elif name in ("root", "0"):
        report.problem(path, user.line, f"{label} runs as root (USER {user.args}); use a non-root user")
    else:
        report.ok(f"runtime stage runs as USER {user.args}")


def _check_expose(path, runtime, label, report):
    exposed = set()
    for ins in runtime.all("EXPOSE"):
        for word in ins.args.split():
            port = word.split("/", 1)[0]
            low, _, high = port.partition("-")
            if low.isdigit() and (not high or high.isdigit()):
                exposed.update(range(int(low), int(high or low) + 1))
    missing = [p for p in REQUIRED_PORTS if p not in exposed]
    line = runtime.all("EXPOSE")[-1].line if runtime.all("EXPOSE") else runtime.line
    if missing:
        report.problem(path, line, f"{label} does not EXPOSE {', '.join(map(str, missing))} "
                                   "(50051: gRPC, 9464: metrics)")
    else:
        report.ok("runtime stage EXPOSEs " + " ".join(map(str, REQUIRED_PORTS)))


def runs_outcore_health(words: list[str]) -> bool:
    for i, word in enumerate(words[:-1]):
        if os.path.basename(word) == "outcore" and words[i + 1] == "health":
            return True
    # A shell string: CMD-SHELL or a shell-form HEALTHCHECK.
    return any(re.search(r"(^|[\s/])outcore\s+health(\s|$)", w) for w in words)


def _check_healthcheck(path, runtime, label, report):
    checks = runtime.all("HEALTHCHECK")
    if not checks:
        report.problem(path, runtime.line, f"{label} has no HEALTHCHECK (`outcore health --server "
                                           "127.0.0.1:50051`)")
        return
    check = checks[-1]
    words = check.args.split(None, 1)
    if words and words[0].upper() == "NONE":
        report.problem(path, check.line, f"{label}: HEALTHCHECK NONE disables the health check")
        return
    match = re.match(r"^((?:--\S+\s+)*)CMD\s+(.*)$", check.args, re.IGNORECASE | re.DOTALL)
    if not match:
        report.problem(path, check.line, f"{label}: HEALTHCHECK without CMD")
        return
    command = match.group(2).strip()
    try:
        argv = json.loads(command) if command.startswith("[") else [command]
    except json.JSONDecodeError as error:
        report.problem(path, check.line, f"{label}: HEALTHCHECK CMD is not a JSON array: {error}")
        return
    if not runs_outcore_health(argv):
        report.problem(path, check.line, f"{label}: the HEALTHCHECK does not run `outcore health` "
                                         f"(it runs {command})")
    else:
        report.ok("runtime stage HEALTHCHECK runs outcore health")


def _check_entrypoint(path, runtime, label, copies, report):
    entries = runtime.all("ENTRYPOINT")
    if not entries:
        report.problem(path, runtime.line, f"{label} has no ENTRYPOINT")
        return
    entry = entries[-1]
    if not entry.args.startswith("["):
        # sh -c would be PID 1 and not pass SIGTERM on: no drain on `docker stop`.
        report.problem(path, entry.line, f"{label}: ENTRYPOINT in shell form; use the exec form "
                                         "([\"/usr/local/bin/outcore\"]) so the server gets SIGTERM and drains")
        return
    try:
        argv = json.loads(entry.args)
    except json.JSONDecodeError as error:
        report.problem(path, entry.line, f"{label}: ENTRYPOINT is not a JSON array: {error}")
        return
    if not argv:
        report.problem(path, entry.line, f"{label}: empty ENTRYPOINT")
    elif argv[0].startswith("/") and copies and os.path.normpath(argv[0]) not in copies:
        report.problem(path, entry.line, f"{label}: ENTRYPOINT runs {argv[0]}, which no COPY --from "
                                         f"puts there (copied: {', '.join(sorted(copies))})")
    else:
        report.ok(f"runtime stage ENTRYPOINT {argv[0]}")


# --------------------------------------------------------------------------
# Debian: packages and libraries


def check_packages_exist(path: Path, runtime: Runtime, report: Report):
    if not runtime.packages:
        return
    if shutil.which("apt-cache") is None:
        report.note("apt-cache not found: not checked that the runtime packages exist in Debian 12")
        return
    release = _os_release()
    if release.get("ID") != "debian" or release.get("VERSION_ID") != "12":
        report.note(f"this machine is {release.get('PRETTY_NAME', 'not Debian')}, not Debian 12: not "
                    "checked that the runtime packages exist in Debian 12")
        return
    if not glob.glob("/var/lib/apt/lists/*_Packages*"):
        report.note("no apt package lists (apt-get update): not checked that the runtime packages "
                    "exist in Debian 12")
        return
    # One call for all (apt-cache takes about a second to load its lists): it
    # shows the packages it knows and passes over the others (and virtual ones).
    names = sorted(runtime.packages)
    result = subprocess.run(["apt-cache", "show", "--no-all-versions", *names], capture_output=True, text=True)
    known = set(re.findall(r"^Package:\s*(\S+)", result.stdout, re.MULTILINE))
    unknown = [name for name in names if name not in known]
    for name in unknown:
        report.problem(path, runtime.packages[name], f"the runtime stage installs {name}, which Debian 12 "
                                                     "does not have (apt-cache show finds no such package)")
    if not unknown:
        report.ok(f"all {len(runtime.packages)} runtime packages exist in Debian 12 (apt-cache)")


def _os_release() -> dict[str, str]:
    values = {}
    try:
        for line in Path("/etc/os-release").read_text().splitlines():
            key, _, value = line.partition("=")
            values[key] = value.strip().strip('"')
    except OSError:
        pass
    return values


def ldd_libraries(binary: Path) -> list[tuple[str, str | None]]:
    """(name, resolved path or None when not found) for every library ldd lists."""
    result = subprocess.run(["ldd", str(binary)], capture_output=True, text=True)
    if "not a dynamic executable" in result.stdout + result.stderr:
        return []
    if result.returncode != 0:
        raise RuntimeError(f"ldd {binary} failed: {result.stderr.strip() or result.stdout.strip()}")
    libraries = []
    for line in result.stdout.splitlines():
        line = line.strip()
        found = re.match(r"^(\S+)\s+=>\s+(.*?)\s*(\(0x[0-9a-f]+\))?$", line)
        if found:
            target = found.group(2)
            libraries.append((found.group(1), None if target == "not found" or not target else target))
        elif line.startswith("/"):  # the dynamic loader, listed by its path
            libraries.append((os.path.basename(line.split()[0]), line.split()[0]))
        # linux-vdso.so.1 is the kernel's, no file.
    return libraries


def _path_variants(path: str) -> list[str]:
    # Debian 12 is merged-/usr: dpkg knows /lib/x/libc.so.6, ldd may say
    # /usr/lib/x/libc.so.6 (or the other way round), and sonames are symlinks.
    variants = []
    for candidate in (path, os.path.realpath(path)):
        variants.append(candidate)
        for short, long in (("/lib", "/usr/lib"), ("/lib64", "/usr/lib64"), ("/lib32", "/usr/lib32")):
            if candidate.startswith(short + "/"):
                variants.append(long + candidate[len(short):])
            elif candidate.startswith(long + "/"):
                variants.append(short + candidate[len(long):])
    return list(dict.fromkeys(variants))


def owning_packages(paths: list[str]) -> dict[str, set[str]]:
    variants = {p: _path_variants(p) for p in paths}
    every = sorted({v for vs in variants.values() for v in vs})
    # Exits 1 when some variant is not known; the known ones are still listed.
    result = subprocess.run(["dpkg-query", "-S", *every], capture_output=True, text=True)
    by_file: dict[str, set[str]] = {}
    for line in result.stdout.splitlines():
        if line.startswith("diversion "):
            continue
        packages, sep, file = line.rpartition(": ")
        if sep:
            by_file.setdefault(file, set()).update(p.strip().split(":")[0] for p in packages.split(","))
    return {p: set().union(*(by_file.get(v, set()) for v in vs)) for p, vs in variants.items()}


def check_binary(binary: Path, dockerfile: Path, runtime: Runtime, report: Report):
    if not binary.is_file():
        report.problem(binary, None, "no such binary (build it, or drop --binary)")
        return
    for tool in ("ldd", "dpkg-query"):
        if shutil.which(tool) is None:
            report.note(f"{tool} not found: the binary's libraries not matched to packages")
            return
    try:
        libraries = ldd_libraries(binary)
    except RuntimeError as error:
        report.problem(binary, None, str(error))
        return
    if not libraries:
        report.ok(f"{shown(binary)} is static: it needs no shared library")
        return
    owners = owning_packages([p for _, p in libraries if p])
    allowed = set(runtime.packages) | set(SLIM_BASE)
    install_line = min(runtime.packages.values()) if runtime.packages else None
    used, before = set(), len(report.problems)
    for name, file in libraries:
        if file is None:
            report.problem(binary, None, f"ldd: {name} not found on this machine; cannot tell its package")
            continue
        packages = owners.get(file, set())
        if not packages:
            report.problem(binary, None, f"{name} ({file}) belongs to no Debian package: the image "
                                         "would not have it")
        elif not packages & allowed:
            report.problem(dockerfile, install_line,
                           f"{shown(binary)} loads {name} ({file}) from {', '.join(sorted(packages))}, "
                           "which the runtime stage does not install and debian:12-slim does not have")
        used |= packages & allowed
    unused = sorted(set(runtime.packages) - used)
    if unused:
        report.note("installed in the runtime stage, though no library ldd lists comes from them "
                    f"(loaded another way, or not needed): {' '.join(unused)}")
    if len(report.problems) == before:
        report.ok(f"all {len(libraries)} libraries ldd lists for {shown(binary)} come from installed "
                  f"packages or debian:12-slim's base ({' '.join(sorted(used & set(SLIM_BASE)))})")


# --------------------------------------------------------------------------
# A strict YAML subset, enough for a compose file


@dataclass
class Node:
    value: object  # str, None, dict[str, Node] or list[Node]
    line: int


class _YamlParser:
    def __init__(self, text: str):
        self.lines: list[tuple[int, int, str]] = []  # (line number, indent, content)
        for number, raw in enumerate(text.splitlines(), 1):
            content = _strip_comment(raw).rstrip()
            if not content.strip():
                continue
            indent = len(content) - len(content.lstrip(" "))
            if content[indent] == "\t":
                raise ParseError(number, "tab in indentation")
            body = content.strip()
            if body == "---" and not self.lines:
                continue
            if body in ("---", "..."):
                raise ParseError(number, "more than one YAML document")
            self.lines.append((number, indent, body))
        self.pos = 0

    def document(self) -> Node:
        if not self.lines:
            raise ParseError(1, "empty file")
        node = self.block(self.lines[0][1])
        if self.pos < len(self.lines):
            raise ParseError(self.lines[self.pos][0], "unexpected indentation")
        return node

    def block(self, indent: int) -> Node:
        body = self.lines[self.pos][2]
        return self.sequence(indent) if _is_item(body) else self.mapping(indent)

    def mapping(self, indent: int) -> Node:
        entries: dict[str, Node] = {}
        first = self.lines[self.pos][0]
        while self.pos < len(self.lines) and self.lines[self.pos][1] == indent:
            number, _, body = self.lines[self.pos]
            if _is_item(body):
                raise ParseError(number, "a sequence item where a key was expected")
            pair = _split_key(body, number)
            if pair is None:
                raise ParseError(number, f"expected 'key: value', found {body!r}")
            key, rest = pair
            if key in entries:
                raise ParseError(number, f"duplicate key {key!r}")
            self.pos += 1
            if rest:
                entries[key] = _scalar(rest, number)
            elif self.pos < len(self.lines) and (
                    self.lines[self.pos][1] > indent
                    or (self.lines[self.pos][1] == indent and _is_item(self.lines[self.pos][2]))):
                entries[key] = self.block(self.lines[self.pos][1])
            else:
                entries[key] = Node(None, number)
            if self.pos < len(self.lines) and self.lines[self.pos][1] > indent:
                raise ParseError(self.lines[self.pos][0], "unexpected indentation")
        return Node(entries, first)

    def sequence(self, indent: int) -> Node:
        items: list[Node] = []
        first = self.lines[self.pos][0]
        while (self.pos < len(self.lines) and self.lines[self.pos][1] == indent
               and _is_item(self.lines[self.pos][2])):
            number, _, body = self.lines[self.pos]
            rest = body[1:].lstrip()
            if not rest:
                self.pos += 1
                if self.pos >= len(self.lines) or self.lines[self.pos][1] <= indent:
                    raise ParseError(number, "empty sequence item")
                items.append(self.block(self.lines[self.pos][1]))
            elif _is_item(rest) or _split_key(rest, number) is not None:
                # "- key: value": a nested block starting at rest's column.
                column = indent + len(body) - len(rest)
                self.lines[self.pos] = (number, column, rest)
                items.append(self.block(column))
            else:
                items.append(_scalar(rest, number))
                self.pos += 1
            if self.pos < len(self.lines) and self.lines[self.pos][1] > indent:
                raise ParseError(self.lines[self.pos][0], "unexpected indentation")
        return Node(items, first)


def parse_yaml(text: str) -> Node:
    return _YamlParser(text).document()


def _is_item(body: str) -> bool:
    return body == "-" or body.startswith("- ")


def _strip_comment(raw: str) -> str:
    quote, i = None, 0
    while i < len(raw):
        char = raw[i]
        if quote == '"' and char == "\\":
            i += 1  # whatever is escaped cannot close the string
        elif quote is not None:
            if char == quote:
                quote = None  # '' (an escaped ') closes and reopens: the same state
        elif char in "\"'" and (i == 0 or raw[i - 1] in " [,:-{"):
            quote = char
        elif char == "#" and (i == 0 or raw[i - 1] in " \t"):
            return raw[:i]
        i += 1
    return raw


def _quoted_end(text: str, number: int) -> int:
    """Index just past the quoted scalar text starts with."""
    quote, i = text[0], 1
    while i < len(text):
        if quote == '"' and text[i] == "\\":
            i += 2
            continue
        if text[i] == quote:
            if quote == "'" and text[i + 1:i + 2] == "'":
                i += 2
                continue
            return i + 1
        i += 1
    raise ParseError(number, f"unterminated quoted string: {text}")


def _split_key(body: str, number: int) -> tuple[str, str] | None:
    if body[0] in "\"'":
        end = _quoted_end(body, number)
        after = body[end:].lstrip()
        if not after.startswith(":") or (len(after) > 1 and after[1] != " "):
            return None
        return _scalar(body[:end], number).value, after[1:].strip()
    match = re.match(r"^([^\s:#\[\]{},&*!|>%@`][^:]*?)\s*:(\s+|$)(.*)$", body)
    if not match:
        return None
    return match.group(1), match.group(3).strip()


def _scalar(text: str, number: int) -> Node:
    text = text.strip()
    if text[0] in "\"'":
        end = _quoted_end(text, number)
        if end != len(text):
            raise ParseError(number, f"text after a quoted string: {text}")
        if text[0] == "'":
            return Node(text[1:-1].replace("''", "'"), number)
        try:
            return Node(json.loads(text), number)
        except json.JSONDecodeError:
            raise ParseError(number, f"unsupported escape in {text}") from None
    if text[0] == "[":
        if not text.endswith("]"):
            raise ParseError(number, "a flow sequence must close on its line")
        return Node(_flow_items(text[1:-1], number), number)
    if text[0] in "{&*!|>%@`":
        raise ParseError(number, f"{text[0]!r}: flow mappings, anchors, aliases, tags and block "
                                 "scalars are not supported by this checker")
    return Node(text, number)


def _flow_items(inner: str, number: int) -> list[Node]:
    items, i = [], 0
    while True:
        while i < len(inner) and inner[i] == " ":
            i += 1
        if i >= len(inner):
            return items
        if inner[i] in "\"'":
            end = i + _quoted_end(inner[i:], number)
        else:
            end = inner.find(",", i)
            end = len(inner) if end < 0 else end
            if any(c in inner[i:end] for c in "[]{}"):
                raise ParseError(number, "nested flow collections are not supported by this checker")
        items.append(_scalar(inner[i:end], number))
        rest = inner[end:].lstrip()
        if rest and not rest.startswith(","):
            raise ParseError(number, f"expected ',' in flow sequence: {inner}")
        i = len(inner) - len(rest) + 1


# --------------------------------------------------------------------------
# compose.yaml


def interpolate(text: str) -> str:
    """Compose's variable substitution, with each variable's default (the file
    as shipped, whatever this machine's environment says)."""
    def one(match):
        if match.group(0) == "$$":
            return "$"
        default = match.group(3)
        return default if default is not None and match.group(2) in ("-", ":-") else ""
    return re.sub(r"\$\$|\$\{(\w+)(?:(:?[-?])([^}]*))?\}|\$\w+", one, text)


def _words(node: Node | None) -> list[str]:
    if node is None or node.value is None:
        return []
    if isinstance(node.value, list):
        return [interpolate(str(item.value)) for item in node.value]
    if isinstance(node.value, str):
        try:
            return shlex.split(interpolate(node.value))
        except ValueError:
            return [node.value]
    return []


def _container_port(entry: Node) -> tuple[int, int] | None:
    if isinstance(entry.value, dict):
        target = entry.value.get("target")
        text = interpolate(str(target.value)) if target else ""
    else:
        text = interpolate(str(entry.value)).split("/", 1)[0].rsplit(":", 1)[-1]
    low, _, high = text.partition("-")
    if low.isdigit() and (not high or high.isdigit()):
        return int(low), int(high or low)
    return None


def check_compose(path: Path, dockerfile: Path, report: Report):
    try:
        root = parse_yaml(path.read_text())
    except ParseError as error:
        report.problem(path, error.line, f"cannot read as YAML: {error}")
        return
    services = root.value.get("services") if isinstance(root.value, dict) else None
    if services is None or not isinstance(services.value, dict):
        report.problem(path, root.line, "no 'services' mapping")
        return
    service, name = None, None
    for key, node in services.value.items():
        build = node.value.get("build") if isinstance(node.value, dict) else None
        if build is None:
            continue
        if isinstance(build.value, dict):
            context = interpolate(str(build.value["context"].value)) if "context" in build.value else "."
            file = interpolate(str(build.value["dockerfile"].value)) if "dockerfile" in build.value \
                else "Dockerfile"
        else:
            context, file = interpolate(str(build.value)), "Dockerfile"
        if (path.parent / context / file).resolve() == dockerfile.resolve():
            service, name = node, key
            break
    if service is None:
        report.problem(path, services.line, f"no service is built from {shown(dockerfile)} (build: "
                                            "context and dockerfile relative to this file)")
        return
    report.ok(f"compose service '{name}' builds {shown(dockerfile)}")
    spec: dict[str, Node] = service.value

    ports = spec.get("ports")
    published = [_container_port(p) for p in (ports.value if ports and isinstance(ports.value, list) else [])]
    missing = [p for p in REQUIRED_PORTS if not any(r and r[0] <= p <= r[1] for r in published)]
    if missing:
        report.problem(path, (ports or service).line, f"service '{name}' does not publish "
                                                      f"{', '.join(map(str, missing))} (gRPC, metrics)")
    else:
        report.ok(f"compose publishes {' '.join(map(str, REQUIRED_PORTS))}")

    volumes = spec.get("volumes")
    mount = None
    for entry in (volumes.value if volumes and isinstance(volumes.value, list) else []):
        if isinstance(entry.value, dict):
            target = interpolate(str(entry.value["target"].value)) if "target" in entry.value else ""
            read_only = "read_only" in entry.value and str(entry.value["read_only"].value).lower() == "true"
        else:
            parts = interpolate(str(entry.value)).split(":")
            target = parts[1] if len(parts) > 1 else parts[0]
            read_only = len(parts) > 2 and "ro" in parts[2].split(",")
        if os.path.normpath(target) == STORE_MOUNT:
            mount = (entry, read_only)
    if mount is None:
        report.problem(path, (volumes or service).line, f"service '{name}' mounts no volume at {STORE_MOUNT} "
                                                        "(the store)")
    elif not mount[1]:
        report.problem(path, mount[0].line, f"service '{name}' mounts {STORE_MOUNT} read-write; the "
                                            "server only reads its store: add :ro")
    else:
        report.ok(f"compose mounts the store read-only at {STORE_MOUNT}")

    command = spec.get("command")
    words = _words(command)
    if not words or words[0] != "serve":
        report.problem(path, (command or service).line, f"service '{name}': the command does not start "
                                                        "with serve")
    if "--log-format=json" not in words and not any(
            a == "--log-format" and b == "json" for a, b in zip(words, words[1:])):
        report.problem(path, (command or service).line, f"service '{name}': the command has no "
                                                        "--log-format json (logs for a collector)")
    elif words and words[0] == "serve":
        report.ok("compose command: serve ... --log-format json")

    check = spec.get("healthcheck")
    if check is not None and isinstance(check.value, dict):
        disabled = check.value.get("disable")
        test = check.value.get("test")
        argv = _words(test)
        if (disabled is not None and str(disabled.value).lower() == "true") or argv[:1] == ["NONE"]:
            report.problem(path, check.line, f"service '{name}' disables the image's health check")
        elif test is not None and not runs_outcore_health(argv[1:] if argv[:1] in (["CMD"], ["CMD-SHELL"])
                                                           else argv):
            report.problem(path, test.line, f"service '{name}': the healthcheck does not run "
                                            "`outcore health`")
        else:
            report.ok("compose healthcheck runs outcore health" if test else
                      "compose healthcheck: the image's")
    else:
        report.ok("compose healthcheck: the image's")

    restart = spec.get("restart")
    policy = interpolate(str(restart.value)) if restart else "no"
    if policy not in ("always", "unless-stopped") and not policy.startswith("on-failure"):
        report.problem(path, (restart or service).line, f"service '{name}' has restart: {policy}; a "
                                                        "service should come back (unless-stopped)")
    else:
        report.ok(f"compose restart: {policy}")


# --------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--dockerfile", type=Path, default=REPO / "docker" / "Dockerfile")
    parser.add_argument("--compose", type=Path, default=REPO / "docker" / "compose.yaml")
    parser.add_argument("--binary", type=Path, help="a built outcore (build/client/outcore) whose "
                                                    "libraries the runtime stage must provide")
    parser.add_argument("--skip-apt-cache", action="store_true",
                        help="do not ask apt-cache whether the packages exist (a second or so)")
    args = parser.parse_args(argv)
    for path in (args.dockerfile, args.compose):
        if not path.is_file():
            print(f"check_container: {path}: no such file", file=sys.stderr)
            return 2
    report = Report()
    runtime = check_dockerfile(args.dockerfile, report)
    if runtime is not None:
        if args.skip_apt_cache:
            report.note("--skip-apt-cache: not checked that the runtime packages exist in Debian 12")
        else:
            check_packages_exist(args.dockerfile, runtime, report)
        if args.binary:
            check_binary(args.binary, args.dockerfile, runtime, report)
    elif args.binary:
        report.note("binary not checked: the Dockerfile could not be read")
    check_compose(args.compose, args.dockerfile, report)

    for line in report.checked:
        print(f"ok    {line}")
    for line in report.notes:
        print(f"note  {line}")
    if report.problems:
        print(f"check_container: {len(report.problems)} problem(s):", file=sys.stderr)
        for line in report.problems:
            print(f"  {line}", file=sys.stderr)
        return 1
    print(f"check_container: {shown(args.dockerfile)} and {shown(args.compose)} ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
