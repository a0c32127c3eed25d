"""Shared fixtures: the repository, the `uavgen` CLI the Python results are compared with, and a
small simulated flight log (20 s of plants/m100_like.json) written by the CLI."""

import os
import pathlib
import subprocess

import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]


def _cli() -> pathlib.Path:
    env = os.environ.get("UAVGEN_BIN")
    if env:
        return pathlib.Path(env)
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    if not target.is_absolute():
        target = REPO / target
    return target / "release" / "uavgen"


@pytest.fixture(scope="session")
def repo() -> pathlib.Path:
    return REPO


@pytest.fixture(scope="session")
def cli():
    """Run the uavgen CLI (UAVGEN_BIN, else <target>/release/uavgen: `cargo build --release -p uavgen`)."""
    binary = _cli()
    if not binary.exists():
        pytest.fail(f"{binary}: the uavgen CLI is not built (cargo build --release -p uavgen, or set UAVGEN_BIN)")

    def run(*args, check=True):
        return subprocess.run([str(binary), *map(str, args)], capture_output=True, text=True,
                              check=check, cwd=REPO)

    return run


@pytest.fixture(scope="session")
def sim_log(cli, tmp_path_factory) -> pathlib.Path:
    """20 s of the excite profile on plants/m100_like.json (CLI: uavgen simulate)."""
    path = tmp_path_factory.mktemp("logs") / "m100_like_20s.csv"
    cli("simulate", "--plant", REPO / "plants/m100_like.json", "--duration", "20", "--out", path)
    return path
