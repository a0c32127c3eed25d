"""uavgen.compile: the generated crate's C ABI built with cargo and called through ctypes.

The reference is the Rust crate's own closed loop: runtime/track-harness (the binary ``uavgen track``
drives, docs/track.md) built against the very crate ``compile`` generated, driven over its
stdin/stdout protocol. Both fly the same plant from the same start; the inputs and the states must
agree to 1e-9 (measured: 0, bit for bit — the same compiled solver, and the Controller's observer
and delay compensation are the runtime's arithmetic in the same order).

Cost: one crate build (~25 s on 2 cores) and one harness build (~15 s, sharing the target
directory), both cached for the session.
"""

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import uavgen
from uavgen.compile import CargoNotFoundError, Controller, MpcError, Status, trajectory_state

REPO = Path(__file__).resolve().parents[3]
MODEL = REPO / "models" / "sindy_m100.json"


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("uavgen-compile-cache")


@pytest.fixture(scope="module")
def model():
    return uavgen.Model.from_json(MODEL.read_text(), str(MODEL))


@pytest.fixture(scope="module")
def mpc(model, cache):
    if shutil.which(os.environ.get("CARGO") or "cargo") is None:
        pytest.fail("cargo is needed for this test (CI installs it)")
    return uavgen.compile(model, horizon=30, cache_dir=cache)


class Harness:
    """runtime/track-harness against the crate compile() generated (track/build.rs's manifest)."""

    def __init__(self, crate_dir: Path, target: Path, work: Path):
        manifest = (crate_dir / "Cargo.toml").read_text()
        name = next(line.split('"')[1] for line in manifest.splitlines() if line.startswith("name = "))
        work.mkdir(parents=True, exist_ok=True)
        (work / "src").mkdir(exist_ok=True)
        (work / "Cargo.toml").write_text(
            f'[package]\nname = "uavgen-track-{name}"\nversion = "0.1.0"\nedition = "2021"\npublish = false\n\n'
            f"[dependencies]\nsolver = {{ package = \"{name}\", path = {json.dumps(str(crate_dir))} }}\n"
            f"uavgen-runtime = {{ path = {json.dumps(str(REPO / 'runtime'))} }}\n\n[workspace]\n"
        )
        shutil.copyfile(REPO / "runtime" / "track-harness" / "src" / "main.rs", work / "src" / "main.rs")
        subprocess.run(
            ["cargo", "build", "--release", "--quiet", "--manifest-path", str(work / "Cargo.toml"),
             "--target-dir", str(target)],
            check=True,
        )
        self.proc = subprocess.Popen(
            [str(target / "release" / f"uavgen-track-{name}")],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
        )

    def request(self, line: str) -> str:
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()
        answer = self.proc.stdout.readline().strip()
        assert not answer.startswith("error"), answer
        return answer

    def start(self, trajectory, x0, u):
        nums = " ".join(repr(float(v)) for v in list(x0) + list(u))
        return self.request(f"start {trajectory} 0.0 {nums}")

    def step(self, x):
        w = self.request("step " + " ".join(repr(float(v)) for v in x)).split()
        nu = len(w) - 6
        return np.array([float(v) for v in w[1:1 + nu]]), w[1 + nu]

    def close(self):
        self.proc.stdin.close()
        self.proc.wait(timeout=10)


class DelayedPlant:
    """The model's own discrete dynamics (through the ABI) as the plant, with the model's input
    delays held for real and a constant disturbance (so that the delay compensation and the
    offset-free observer both have work to do)."""

    def __init__(self, mpc, x0):
        self.mpc = mpc
        self.x = np.array(x0, dtype=float)
        self.delays = mpc.input_delay_samples
        self.sent = [np.zeros(mpc.nu)] * (max(self.delays) + 1)
        self.push = np.zeros(mpc.nx)
        self.push[6], self.push[8] = 0.004, -0.003  # m/s per sample on vx, vz

    def step(self, u):
        self.sent = [np.asarray(u, float)] + self.sent[:-1]
        acting = np.array([self.sent[d][i] for i, d in enumerate(self.delays)])
        self.x = self.mpc.discrete_dynamics(self.x, acting) + self.push
        return self.x


def test_closed_loop_equals_the_rust_harness(mpc, cache, tmp_path):
    assert mpc.input_delay_samples == [4, 0, 0, 0]  # sindy_m100's u_vz latency: the compensator runs
    assert mpc.disturbance_gain == 0.5
    harness = Harness(mpc.crate_dir, cache / "target", tmp_path / "harness")
    x0 = np.array([3.0, 3.0, 5.0] + [0.0] * 9)
    hover = np.clip(np.zeros(4), mpc.u_min, mpc.u_max)
    steps = 150  # 5 s of the circle at 30 Hz
    worst_u = worst_x = 0.0
    try:
        for trajectory in ("circle", "spiral"):
            harness.start(trajectory, x0, hover)
            ctl = Controller(mpc, trajectory)
            ctl.initialize(x0, hover)
            ctl.start(0.0)
            py_plant, rs_plant = DelayedPlant(mpc, x0), DelayedPlant(mpc, x0)
            x_py, x_rs = x0.copy(), x0.copy()
            statuses = set()
            for _ in range(steps):
                u_py, status = ctl.step(x_py)
                u_rs, status_rs = harness.step(x_rs)
                statuses.add(status.name)
                # The harness prints the Rust Status's Debug name (Solved, IterationCap, …).
                assert re.sub(r"(?<!^)(?=[A-Z])", "_", status_rs).upper() == status.name, (status_rs, status)
                assert np.all(u_py >= mpc.u_min) and np.all(u_py <= mpc.u_max)
                worst_u = max(worst_u, float(np.max(np.abs(u_py - u_rs))))
                x_py, x_rs = py_plant.step(u_py), rs_plant.step(u_rs)
                worst_x = max(worst_x, float(np.max(np.abs(x_py - x_rs))))
            # The loop flew: near the reference at the end, and the observer estimated something.
            ref = trajectory_state(trajectory, steps * mpc.dt, mpc.nx)
            assert np.linalg.norm(x_py[:3] - ref[:3]) < 1.5, (trajectory, x_py[:3], ref[:3])
            assert np.any(ctl.observer.estimate != 0.0)
            assert "SOLVED" in statuses
    finally:
        harness.close()
    assert worst_u <= 1e-9, worst_u
    assert worst_x <= 1e-9, worst_x
    print(f"max |u_python - u_harness| = {worst_u:.3g}, max |x| difference = {worst_x:.3g}")


def test_solve_equals_prepare_then_feedback_and_the_plan_is_consistent(mpc):
    other = uavgen.Mpc(mpc.library_path, mpc.header_path)
    x0 = np.array([3.0, 3.0, 5.0] + [0.0] * 9)
    reference = np.array([trajectory_state("circle", k * mpc.dt, 12) for k in range(31)])
    for m in (mpc, other):
        assert m.initialize(x0) == Status.SOLVED
    assert mpc.prepare(reference) == Status.OK
    u1, s1 = mpc.feedback(x0)
    u2, s2 = other.solve(x0, reference)
    assert s1 == s2 and s1.produced_input
    np.testing.assert_array_equal(u1, u2)
    np.testing.assert_array_equal(mpc.first_input(), u1)
    assert mpc.qp_iterations >= 1 and np.isfinite(mpc.cost)
    us, xs = mpc.planned_inputs(), mpc.predicted_states()
    assert us.shape == (30, 4) and xs.shape == (31, 12)
    # The plan's states follow the model with the plan's inputs (the lead of u_vz aside: the
    # planned states hold channel 0's inputs already sent, which are the hover's zeros here).
    np.testing.assert_allclose(xs[0], x0, atol=0)
    assert mpc.last_status == s1
    assert mpc.shift() == Status.OK


def test_refusals_and_shapes(mpc):
    fresh = uavgen.Mpc(mpc.library_path, mpc.header_path)
    with pytest.raises(MpcError, match="NO_SOLUTION"):
        fresh.first_input()
    assert fresh.last_status == Status.NO_SOLUTION
    with pytest.raises(ValueError, match=r"shape \(12,\)"):
        fresh.feedback(np.zeros(11))
    with pytest.raises(ValueError, match=r"reference must have shape \(31, 12\)"):
        fresh.prepare(np.zeros((30, 12)))
    # A NaN state still gives a bounded input (the solver's guarantee) and says so.
    fresh.prepare(np.zeros(12) + np.r_[0, 0, 5, [0] * 9])
    u, status = fresh.feedback(np.full(12, np.nan))
    assert status == Status.INVALID_INPUT
    assert np.all(np.isfinite(u)) and np.all(u >= fresh.u_min) and np.all(u <= fresh.u_max)
    x_next = fresh.discrete_dynamics(np.r_[0, 0, 5, [0] * 9], np.zeros(4))
    assert x_next.shape == (12,) and np.all(np.isfinite(x_next))


def test_cached_library_loads_without_cargo(model, mpc, cache, monkeypatch):
    monkeypatch.setenv("PATH", "/nonexistent")
    monkeypatch.setenv("CARGO", "/nonexistent/cargo")
    again = uavgen.compile(model, horizon=30, cache_dir=cache)
    assert again.library_path == mpc.library_path
    # Other options are another entry: that one needs cargo, and says what to install.
    with pytest.raises(CargoNotFoundError, match="rustup"):
        uavgen.compile(model, horizon=30, cache_dir=cache, r=[0.1, 0.1, 0.1, 5.0])


def test_missing_cargo_is_a_clear_error(model, tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path))  # no cargo there
    monkeypatch.delenv("CARGO", raising=False)
    with pytest.raises(CargoNotFoundError) as e:
        uavgen.compile(model, horizon=30, cache_dir=tmp_path / "cache")
    assert "cargo" in str(e.value) and "https://rustup.rs" in str(e.value)
