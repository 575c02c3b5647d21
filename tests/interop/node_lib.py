"""Node.js and vda-5050-lib for the interoperability tests, installed once into a cache we own.

``install_vda_lib()`` runs ``npm install --prefix <repo>/.cache/interop/vda-5050-lib-<version>
vda-5050-lib@<version>`` the first time and reuses the folder afterwards; a lock file keeps two
test runs from installing into the same folder at once. Only this install talks to the npm
registry: the peers themselves run offline against the private broker.

Tests skip when ``node`` or ``npm`` is missing, unless ``VDA_REQUIRE_NODE`` is set (CI sets it),
in which case they fail instead of hiding behind a skip.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.spec_files import REPO

VDA_LIB_VERSION = "1.4.0"
CACHE = REPO / ".cache" / "interop"
PEERS = Path(__file__).resolve().parent / "peer"
INSTALL_TIMEOUT_S = 300.0


@dataclass(frozen=True, slots=True)
class NodeRuntime:
    """The ``node`` binary and the ``node_modules`` folder that holds vda-5050-lib."""

    node: str
    node_modules: Path
    version: str

    def env(self) -> dict[str, str]:
        """Environment of a peer process: the library found through NODE_PATH, no debug noise."""
        env = {k: v for k, v in os.environ.items() if not k.startswith(("VDA_", "DEBUG"))}
        env["NODE_PATH"] = str(self.node_modules)
        return env


def require_node() -> tuple[str, str]:
    """``node`` and ``npm``, or skip (fail when VDA_REQUIRE_NODE is set) when one is missing."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        missing = " and ".join(n for n, p in (("node", node), ("npm", npm)) if p is None)
        if os.environ.get("VDA_REQUIRE_NODE"):
            pytest.fail(f"{missing} required (VDA_REQUIRE_NODE is set) but not installed")
        pytest.skip(f"{missing} not installed")
    return node, npm


#: Written into the install folder after npm succeeded: a half-finished install has none.
COMPLETE_MARKER = ".install-complete"


def installed_version(node_modules: Path) -> str | None:
    """The version of vda-5050-lib in ``node_modules``, or None (also for an unfinished
    install)."""
    manifest = node_modules / "vda-5050-lib" / "package.json"
    if not (node_modules.parent / COMPLETE_MARKER).is_file():
        return None
    try:
        return str(json.loads(manifest.read_text())["version"])
    except (OSError, ValueError, KeyError):
        return None


def install_vda_lib(version: str = VDA_LIB_VERSION, cache: Path = CACHE) -> NodeRuntime:
    """vda-5050-lib ``version`` in ``cache``, installed from the npm registry on first use."""
    node, npm = require_node()
    prefix = cache / f"vda-5050-lib-{version}"
    node_modules = prefix / "node_modules"
    if installed_version(node_modules) != version:
        cache.mkdir(parents=True, exist_ok=True)
        with (cache / f"vda-5050-lib-{version}.lock").open("w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # another run may be installing: wait for it
            if installed_version(node_modules) != version:
                prefix.mkdir(exist_ok=True)
                (prefix / COMPLETE_MARKER).unlink(missing_ok=True)
                _npm_install(npm, prefix, version)
    return NodeRuntime(node, node_modules, version)


def _npm_install(npm: str, prefix: Path, version: str) -> None:
    command = [
        npm,
        "install",
        "--prefix",
        str(prefix),
        "--no-audit",
        "--no-fund",
        "--save-exact",
        f"vda-5050-lib@{version}",
    ]
    try:
        done = subprocess.run(  # noqa: S603 - npm from PATH, fixed arguments
            command, capture_output=True, text=True, timeout=INSTALL_TIMEOUT_S, check=False
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"npm install vda-5050-lib@{version} took over {INSTALL_TIMEOUT_S:.0f} s")
    if done.returncode == 0:
        (prefix / COMPLETE_MARKER).write_text(version + "\n")
    if done.returncode != 0 or installed_version(prefix / "node_modules") != version:
        output = (done.stdout + done.stderr)[-3000:]
        pytest.fail(f"npm install vda-5050-lib@{version} failed ({done.returncode}):\n{output}")
