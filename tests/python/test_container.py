"""The container setup (docker/Dockerfile, docker/compose.yaml) through
scripts/check_container.py, which CI runs in place of `docker build` (no
registry access there): the shipped files pass, with the built binary's
libraries when $OUTCORE_BINARY is set; and the checker rejects each kind of
broken file, naming the problem and its line. Each broken file is the shipped
one with a single change, so exactly one problem is expected.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from support import REPO, binary

CHECKER = REPO / "scripts" / "check_container.py"
DOCKERFILE = (REPO / "docker" / "Dockerfile").read_text()
COMPOSE = (REPO / "docker" / "compose.yaml").read_text()


def run_checker(*args, cwd=REPO) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(CHECKER), *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=120)


def problems(result: subprocess.CompletedProcess) -> list[str]:
    return [line.strip() for line in result.stderr.splitlines() if line.startswith("  ")]


def changed(text: str, old: str, new: str) -> str:
    assert old in text, f"the shipped file no longer contains {old!r}: update this test"
    return text.replace(old, new, 1)


def line_of(text: str, fragment: str) -> int:
    """The last line holding fragment (the runtime stage is the last)."""
    return max(n for n, line in enumerate(text.splitlines(), 1) if fragment in line)


def check_copy(tmp_path: Path, dockerfile: str = DOCKERFILE, compose: str = COMPOSE, *args, apt=False):
    """The checker on a copy of the docker/ folder (compose.yaml's build
    context, .., is then tmp_path) holding the given texts. apt-cache (about a
    second a run) is asked only when the test is about it."""
    args = args if apt else (*args, "--skip-apt-cache")
    folder = tmp_path / "docker"
    folder.mkdir(exist_ok=True)
    (folder / "Dockerfile").write_text(dockerfile)
    (folder / "compose.yaml").write_text(compose)
    return run_checker("--dockerfile", folder / "Dockerfile", "--compose", folder / "compose.yaml", *args,
                       cwd=tmp_path)


def rejected_once(result, where: str, *fragments: str) -> str:
    assert result.returncode == 1, result.stdout + result.stderr
    found = problems(result)
    assert len(found) == 1, "expected exactly one problem:\n" + result.stderr
    assert found[0].startswith(where + ":"), found[0]
    for fragment in fragments:
        assert fragment in found[0], found[0]
    return found[0]


def test_shipped_files_pass():
    """As the suite runs it: with the built binary when OUTCORE_BINARY is set
    (every library it loads must come from the runtime image's packages)."""
    args = ["--binary", binary()] if "OUTCORE_BINARY" in os.environ else []
    result = run_checker(*args)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "ok    runtime stage HEALTHCHECK runs outcore health" in result.stdout
    assert "ok    compose publishes 50051 9464" in result.stdout
    if args and shutil.which("ldd") and shutil.which("dpkg-query"):
        assert "libraries ldd lists for" in result.stdout


def test_unchanged_copy_passes(tmp_path):
    result = check_copy(tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr


RUNTIME_FROM = "FROM debian:12-slim AS runtime"
# Package problems are reported on the line the RUN starts on, where Docker
# reports the instruction, not on the continuation line holding the name.
INSTALL_RUN = "RUN apt-get update"
INSTALLED = "libembree3-3 libtbb12"
USER = "USER 10001:10001"
HEALTHCHECK = 'CMD ["/usr/local/bin/outcore", "health", "--server", "127.0.0.1:50051", "--timeout-s", "5"]'
COPY = "COPY --from=build /out/outcore /usr/local/bin/outcore"
ENTRYPOINT = 'ENTRYPOINT ["/usr/local/bin/outcore"]'


# (old, new, the line the problem is reported on, what its message says);
# an instruction's line is the one it starts on, as in Docker's own messages.
@pytest.mark.parametrize("old, new, at, fragments", [
    (RUNTIME_FROM, "FROM debian:12 AS runtime", "FROM debian:12 AS", ["FROM debian:12,", "not debian:12-slim"]),
    (RUNTIME_FROM, "FROM build AS runtime", "FROM build AS", ["stage 'build'", "compiler"]),
    (USER, "USER root", "USER root", ["runs as root"]),
    (USER, "USER 0:0", "USER 0:0", ["runs as root"]),
    (USER + "\n", "", RUNTIME_FROM, ["no USER"]),
    (INSTALLED, "libgrpc++-dev libembree3-3 libtbb12", INSTALL_RUN, ["libgrpc++-dev", "-dev package"]),
    (INSTALLED, "cmake libembree3-3 libtbb12", INSTALL_RUN, ["cmake", "build tool"]),
    (INSTALLED, "g++-12 libembree3-3 libtbb12", INSTALL_RUN, ["g++-12", "build tool"]),
    ("--no-install-recommends \\\n      libgrpc", "\\\n      libgrpc", INSTALL_RUN, ["--no-install-recommends"]),
    (" \\\n && rm -rf /var/lib/apt/lists/*\nCOPY", "\nCOPY", INSTALL_RUN, ["/var/lib/apt/lists"]),
    ("HEALTHCHECK --interval=30s --timeout=10s --start-period=60s --retries=3 \\\n  " + HEALTHCHECK + "\n", "",
     RUNTIME_FROM, ["no HEALTHCHECK"]),
    (HEALTHCHECK, 'CMD ["true"]', "HEALTHCHECK", ["does not run `outcore health`"]),
    (COPY, COPY + "\nCOPY . /src", "COPY . /src", ["without --from", "source tree"]),
    (COPY, COPY + "\nCOPY --from=build /src/outcore /src", "COPY --from=build /src/", ["whole tree"]),
    ("EXPOSE 50051 9464", "EXPOSE 50051", "EXPOSE 50051", ["does not EXPOSE 9464"]),
    (ENTRYPOINT + "\n", "", RUNTIME_FROM, ["no ENTRYPOINT"]),
    (ENTRYPOINT, "ENTRYPOINT /usr/local/bin/outcore", "ENTRYPOINT", ["shell form", "SIGTERM"]),
    (ENTRYPOINT, 'ENTRYPOINT ["/usr/bin/outcore"]', "ENTRYPOINT", ["/usr/bin/outcore", "no COPY --from"]),
])
def test_broken_dockerfile_is_rejected(tmp_path, old, new, at, fragments):
    text = changed(DOCKERFILE, old, new)
    rejected_once(check_copy(tmp_path, text), f"docker/Dockerfile:{line_of(text, at)}", *fragments)


def test_single_stage_is_rejected(tmp_path):
    runtime = DOCKERFILE[DOCKERFILE.index(RUNTIME_FROM):]
    result = check_copy(tmp_path, runtime)
    assert result.returncode == 1
    assert any("1 stage(s)" in p and "multi-stage" in p for p in problems(result)), result.stderr


def test_package_missing_from_debian_12_is_rejected(tmp_path):
    result = check_copy(tmp_path, changed(DOCKERFILE, "libfmt9", "libfmt99"), apt=True)
    if "not checked that the runtime packages exist" in result.stdout:
        pytest.skip("this machine cannot answer for Debian 12's packages: " + result.stdout)
    rejected_once(result, f"docker/Dockerfile:{line_of(DOCKERFILE, INSTALL_RUN)}", "libfmt99",
                  "Debian 12 does not have")


@pytest.mark.parametrize("old, new, fragments", [
    ("      - json\n", "      - text\n", ["--log-format json"]),
    (":/data:ro", ":/data", ["read-write", ":ro"]),
    (":/data:ro", ":/scenes:ro", ["no volume at /data"]),
    ('      - "${OUTCORE_PUBLISH:-127.0.0.1}:9464:9464"\n', "", ["does not publish 9464"]),
    ("dockerfile: docker/Dockerfile", "dockerfile: docker/Dockerfile.dev", ["no service is built from"]),
    ("    restart: unless-stopped\n", "", ["restart: no"]),
    ('/outcore", "health"', '/outcore", "query"', ["does not run `outcore health`"]),
    ("      - serve\n", "      - trace\n", ["does not start with serve"]),
])
def test_broken_compose_is_rejected(tmp_path, old, new, fragments):
    text = changed(COMPOSE, old, new)
    rejected_once(check_copy(tmp_path, compose=text), "docker/compose.yaml", *fragments)


@pytest.mark.parametrize("old, new, fragment", [
    ("    restart: unless-stopped", "\trestart: unless-stopped", "tab in indentation"),
    ("    restart: unless-stopped", "    restart: &r unless-stopped", "anchors"),
    ("    restart: unless-stopped", "    restart: unless-stopped\n    restart: always", "duplicate key"),
    ("    restart: unless-stopped", "     restart: unless-stopped", "unexpected indentation"),
])
def test_compose_outside_the_yaml_subset_is_refused_with_its_line(tmp_path, old, new, fragment):
    text = changed(COMPOSE, old, new)
    line = line_of(text, "restart: always" if fragment == "duplicate key" else "restart:")
    rejected_once(check_copy(tmp_path, compose=text), f"docker/compose.yaml:{line}", fragment)


def _checker_module():
    spec = importlib.util.spec_from_file_location("check_container", CHECKER)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_yaml_subset():
    checker = _checker_module()
    text = (
        "# a comment\n"
        "services:\n"
        "  a:\n"
        "    command: [\"serve\", 'it''s', plain , \"x # not a comment\"]  # a comment\n"
        "    ports:\n"
        "    - \"1:2\"\n"
        "    - target: 3\n"
        "      published: 4\n"
        "    env: ${X:-a:b}\n"
        "    empty:\n"
    )
    root = checker.parse_yaml(text)

    def plain(node):
        if isinstance(node.value, dict):
            return {k: plain(v) for k, v in node.value.items()}
        if isinstance(node.value, list):
            return [plain(v) for v in node.value]
        return node.value

    assert plain(root) == {"services": {"a": {
        "command": ["serve", "it's", "plain", "x # not a comment"],
        "ports": ["1:2", {"target": "3", "published": "4"}],
        "env": "${X:-a:b}",
        "empty": None,
    }}}
    assert root.value["services"].value["a"].value["ports"].value[1].line == 7
    assert checker.interpolate("${A:-../scenes}:/data:ro $${B} ${C}") == "../scenes:/data:ro ${B} "


@pytest.mark.skipif(not (shutil.which("ldd") and shutil.which("dpkg-query")), reason="needs ldd and dpkg")
def test_binary_needing_a_library_the_image_lacks_is_rejected(tmp_path):
    """dpkg itself loads libmd and libselinux: neither installed by the
    runtime stage nor relied on from the base."""
    result = check_copy(tmp_path, DOCKERFILE, COMPOSE, "--binary", shutil.which("dpkg"))
    assert result.returncode == 1
    found = problems(result)
    assert found and all("which the runtime stage does not install" in p for p in found), result.stderr
    assert any("libselinux.so.1" in p and "from libselinux1," in p for p in found), result.stderr


@pytest.mark.skipif(not (shutil.which("ldd") and shutil.which("dpkg-query")), reason="needs ldd and dpkg")
def test_binary_needing_only_libc_passes(tmp_path):
    result = check_copy(tmp_path, DOCKERFILE, COMPOSE, "--binary", shutil.which("cat"))
    assert result.returncode == 0, result.stdout + result.stderr
    assert "debian:12-slim's base (libc6)" in result.stdout
