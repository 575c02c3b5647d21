"""The interop harness itself, without Node.js: installer decisions and the schema judge."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Sequence
from pathlib import Path

import pytest

from tests.interop.node_lib import COMPLETE_MARKER, install_vda_lib, require_node
from tests.interop.wire import LIB_DEVIATIONS, SchemaProblem, Side, judge, side_of


@pytest.fixture
def no_node(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("tests.interop.node_lib.shutil.which", lambda _name: None)


@pytest.fixture
def fake_node(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("tests.interop.node_lib.shutil.which", lambda name: f"/opt/bin/{name}")


def test_missing_node_skips_when_not_required(
    no_node: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Without node/npm and without VDA_REQUIRE_NODE the interop tests are skipped."""
    monkeypatch.delenv("VDA_REQUIRE_NODE", raising=False)
    with pytest.raises(pytest.skip.Exception, match="node and npm not installed"):
        require_node()


def test_missing_node_fails_when_required(no_node: None, monkeypatch: pytest.MonkeyPatch) -> None:
    """With VDA_REQUIRE_NODE set (CI) a missing node fails instead of skipping."""
    monkeypatch.setenv("VDA_REQUIRE_NODE", "1")
    with pytest.raises(pytest.fail.Exception, match="VDA_REQUIRE_NODE is set"):
        require_node()


def _complete_install(prefix: Path, version: str) -> None:
    package = prefix / "node_modules" / "vda-5050-lib"
    package.mkdir(parents=True)
    (package / "package.json").write_text(json.dumps({"version": version}))
    (prefix / COMPLETE_MARKER).write_text(version)


def test_a_complete_install_is_reused_without_npm(
    fake_node: None, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A finished install of the same version is used as it is: npm is not run."""
    _complete_install(tmp_path / "vda-5050-lib-1.4.0", "1.4.0")

    def no_npm(*args: object, **kwargs: object) -> None:
        pytest.fail("npm ran although the cache was complete")

    monkeypatch.setattr("tests.interop.node_lib.subprocess.run", no_npm)
    runtime = install_vda_lib("1.4.0", cache=tmp_path)
    assert runtime.node_modules == tmp_path / "vda-5050-lib-1.4.0" / "node_modules"
    assert runtime.env()["NODE_PATH"] == str(runtime.node_modules)


def test_an_unfinished_install_is_redone_with_the_exact_version(
    fake_node: None, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """Without the completion marker npm installs again, exactly vda-5050-lib@<version>."""
    prefix = tmp_path / "vda-5050-lib-1.4.0"
    _complete_install(prefix, "1.4.0")
    (prefix / COMPLETE_MARKER).unlink()
    calls: list[Sequence[str]] = []

    def npm(command: Sequence[str], **kwargs: object) -> subprocess.CompletedProcess[str]:
        calls.append(command)
        return subprocess.CompletedProcess(command, 0, "added 46 packages", "")

    monkeypatch.setattr("tests.interop.node_lib.subprocess.run", npm)
    install_vda_lib("1.4.0", cache=tmp_path)
    assert len(calls) == 1
    assert calls[0][:4] == ["/opt/bin/npm", "install", "--prefix", str(prefix)]
    assert {"--no-audit", "--no-fund", "vda-5050-lib@1.4.0"} <= set(calls[0])
    assert (prefix / COMPLETE_MARKER).is_file()


def test_a_failed_npm_install_fails_with_its_output(
    fake_node: None, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """npm's own error text ends up in the failure, and the install is not marked complete."""

    def npm(command: Sequence[str], **kwargs: object) -> subprocess.CompletedProcess[str]:
        return subprocess.CompletedProcess(command, 1, "", "npm error code E404")

    monkeypatch.setattr("tests.interop.node_lib.subprocess.run", npm)
    with pytest.raises(pytest.fail.Exception, match="E404"):
        install_vda_lib("1.4.0", cache=tmp_path)
    assert not (tmp_path / "vda-5050-lib-1.4.0" / COMPLETE_MARKER).exists()


def _problem(topic: str, text: str) -> SchemaProblem:
    return SchemaProblem(f"uagv/v2/m/s/{topic}", side_of(f"uagv/v2/m/s/{topic}"), 1, text)


def test_judge_blames_our_side_and_tolerates_only_known_peer_deviations() -> None:
    """Our problems always count; a peer's count unless a known deviation explains them."""
    state = _problem("state", "'errors' is a required property at $")
    known = _problem("instantActions", "'actions' is a required property at $")
    unknown = _problem("instantActions", "'x' is not of type 'integer' at $.headerId")
    verdict = judge([state, known, unknown], Side.VEHICLE, LIB_DEVIATIONS)
    assert (verdict.ours, verdict.known_peer, verdict.unknown_peer) == ([state], [known], [unknown])
    verdict = judge([state, known], Side.MASTER, LIB_DEVIATIONS)
    assert (verdict.ours, verdict.known_peer, verdict.unknown_peer) == ([known], [], [state])
    assert len(verdict.failures()) == 2
