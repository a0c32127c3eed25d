"""The Python package against hand-checked cases, finite differences and the CLI (docs/python.md)."""

import json
import pathlib

import numpy as np
import pytest

import uavgen

MODELS = ["sindy_m100.json", "pd_m100.json"]


def _random_point(model, seed):
    rng = np.random.default_rng(seed)
    x = rng.normal(0.0, 0.3, model.nx)
    x[2] = 5.0 + rng.normal()
    u = rng.normal(0.0, 0.2, model.nu)
    return x, u


@pytest.mark.parametrize("name", MODELS)
def test_kinematic_rows_by_hand(repo, name):
    # Position rates are the velocities and the angles' rates the logged rates, in both models.
    m = uavgen.Model.load(repo / "models" / name)
    x, u = _random_point(m, 1)
    f = m.f(x, u)
    assert f.shape == (12,)
    np.testing.assert_array_equal(f[0:3], x[6:9])
    np.testing.assert_array_equal(f[3:6], x[9:12])


@pytest.mark.parametrize("name", MODELS)
def test_jacobians_match_finite_differences(repo, name):
    m = uavgen.Model.load(repo / "models" / name)
    for seed in range(3):
        x, u = _random_point(m, seed)
        a, b = m.jacobians(x, u)
        assert a.shape == (m.nx, m.nx) and b.shape == (m.nx, m.nu)
        h = 1e-6
        for j in range(m.nx):
            e = np.zeros(m.nx)
            e[j] = h
            fd = (m.f(x + e, u) - m.f(x - e, u)) / (2 * h)
            np.testing.assert_allclose(a[:, j], fd, rtol=1e-6, atol=1e-6)
        for j in range(m.nu):
            e = np.zeros(m.nu)
            e[j] = h
            fd = (m.f(x, u + e) - m.f(x, u - e)) / (2 * h)
            np.testing.assert_allclose(b[:, j], fd, rtol=1e-6, atol=1e-6)


def test_f_and_jacobians_broadcast(repo):
    m = uavgen.Model.load(repo / "models/sindy_m100.json")
    xs = np.stack([_random_point(m, s)[0] for s in range(5)])
    us = np.stack([_random_point(m, s)[1] for s in range(5)])
    f = m.f(xs, us)
    a, b = m.jacobians(xs, us)
    assert f.shape == (5, 12) and a.shape == (5, 12, 12) and b.shape == (5, 12, 4)
    for k in range(5):
        np.testing.assert_array_equal(f[k], m.f(xs[k], us[k]))
        np.testing.assert_array_equal(a[k], m.jacobians(xs[k], us[k])[0])
    # One input for every state row.
    np.testing.assert_array_equal(m.f(xs, us[0]), np.stack([m.f(x, us[0]) for x in xs]))


def test_simulate_is_fixed_step_rk4(repo):
    m = uavgen.Model.load(repo / "models/sindy_m100.json")
    x0, _ = _random_point(m, 7)
    U = np.random.default_rng(3).normal(0.0, 0.1, (25, 4))
    dt, substeps = 1 / 30, 2
    X = m.simulate(x0, U, dt, substeps=substeps)
    assert X.shape == (26, 12)
    # The same RK4 by hand through model.f.
    x, h = x0.copy(), dt / substeps
    for k in range(25):
        for _ in range(substeps):
            k1 = m.f(x, U[k])
            k2 = m.f(x + h / 2 * k1, U[k])
            k3 = m.f(x + h / 2 * k2, U[k])
            k4 = m.f(x + h * k3, U[k])
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        np.testing.assert_allclose(X[k + 1], x, rtol=1e-12, atol=1e-12)
    # Default: the automatic substep rule.
    auto = m.auto_substeps(dt)
    np.testing.assert_array_equal(m.simulate(x0, U, dt), m.simulate(x0, U, dt, substeps=auto))


def test_model_json_round_trip(repo, tmp_path):
    path = repo / "models/pd_m100.json"
    m = uavgen.Model.load(path)
    assert m.to_json() == path.read_text()
    again = uavgen.Model.from_json(m.to_json(), "copy.json")
    assert again == m and again.kind == "pd" and again.states == m.states
    m.save(tmp_path / "m.json")
    assert (tmp_path / "m.json").read_text() == path.read_text()
    with pytest.raises(uavgen.UavgenError, match="exists"):
        m.save(tmp_path / "m.json")
    m.save(tmp_path / "m.json", force=True)


def test_errors_are_exceptions_naming_the_file(repo, tmp_path, cli):
    bad = tmp_path / "bad_model.json"
    bad.write_text('{"format": "uavgen-model/1", "kind": "pd",\n "name": 3}\n')
    with pytest.raises(uavgen.UavgenError) as e:
        uavgen.Model.load(bad)
    assert str(bad) in str(e.value)
    # The CLI's message, word for word.
    out = cli("check", "--model", bad, check=False)
    assert out.returncode != 0 and f"error: {e.value}" in out.stderr
    with pytest.raises(uavgen.UavgenError, match="thing.json"):
        uavgen.Model.from_json("{", "thing.json")
    log = tmp_path / "bad_log.csv"
    log.write_text("t,x\n0,1\n")
    with pytest.raises(uavgen.UavgenError, match=str(log)):
        uavgen.read_log(log)
    with pytest.raises(uavgen.UavgenError, match="no_such_file"):
        uavgen.read_log(tmp_path / "no_such_file.csv")
    m = uavgen.Model.load(repo / "models/pd_m100.json")
    with pytest.raises(uavgen.UavgenError, match="12 states"):
        m.f(np.zeros(11), np.zeros(4))
    with pytest.raises(uavgen.UavgenError):
        m.simulate(np.zeros(12), np.zeros((3, 4)), dt=0.0)


def test_log_arrays_round_trip(sim_log):
    log = uavgen.read_log(sim_log)
    assert log.source == str(sim_log) and log.rows == 600
    a = log.to_numpy()
    assert a["x"].shape == (600, 12) and a["u"].shape == (600, 4)
    again = uavgen.Log.from_numpy(a["t"], a["x"], a["u"], segment=a["segment"],
                                  battery_voltage=a["battery_voltage"], rate_hz=30.0)
    b = again.to_numpy()
    for k in ("t", "x", "u", "segment", "battery_voltage"):
        np.testing.assert_array_equal(a[k], b[k])
    # The arrays are those of the file (yaw unwrapped by the reader).
    lines = [line for line in sim_log.read_text().splitlines() if not line.startswith("#")]
    header = lines[0].split(",")
    raw = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    np.testing.assert_array_equal(a["t"], raw[:, header.index("t")])
    np.testing.assert_array_equal(a["x"][:, 0], raw[:, header.index("x")])
    np.testing.assert_array_equal(a["u"][:, 3], raw[:, header.index("u_yaw_rate")])
    with pytest.raises(uavgen.UavgenError, match="<numpy>"):
        uavgen.Log.from_numpy(a["t"][::-1], a["x"], a["u"])


def test_log_pandas_round_trip(sim_log):
    pd = pytest.importorskip("pandas")
    log = uavgen.read_log(sim_log)
    df = log.to_pandas()
    assert isinstance(df, pd.DataFrame) and len(df) == 600
    again = uavgen.Log.from_pandas(df, rate_hz=30.0)
    np.testing.assert_array_equal(again.to_numpy()["x"], log.to_numpy()["x"])


def test_simulate_writes_the_cli_log(repo, sim_log, tmp_path):
    out = tmp_path / "py.csv"
    log = uavgen.simulate(repo / "plants/m100_like.json", duration=20, out=out)
    assert out.read_bytes() == sim_log.read_bytes()
    assert log.rows == 600 and log.source == str(out)


def test_evaluate_equals_cli_json(repo, sim_log, cli, tmp_path):
    model = repo / "models/sindy_m100.json"
    cli("evaluate", "--model", model, "--log", sim_log, "--json", tmp_path / "cli.json")
    expected = json.loads((tmp_path / "cli.json").read_text())
    got = uavgen.evaluate(uavgen.Model.load(model), [uavgen.read_log(sim_log)])
    assert got == expected
    # Paths instead of objects, and the file written by json=.
    uavgen.evaluate(model, sim_log, json=tmp_path / "py.json")
    assert (tmp_path / "py.json").read_bytes() == (tmp_path / "cli.json").read_bytes()
    with pytest.raises(uavgen.UavgenError, match="--horizon"):
        uavgen.evaluate(model, sim_log, horizon=0)


def test_generate_equals_cli(repo, cli, tmp_path):
    model = repo / "models/pd_m100.json"
    cli("--model", model, "--horizon", "20", "--out", tmp_path / "cli_crate")
    info = uavgen.generate(uavgen.Model.load(model), horizon=20, out=tmp_path / "py_crate")
    assert info["out"] == str(tmp_path / "py_crate") and info["substeps"] >= 1
    files = sorted(p.relative_to(tmp_path / "cli_crate") for p in (tmp_path / "cli_crate").rglob("*") if p.is_file())
    assert files
    for f in files:
        assert (tmp_path / "py_crate" / f).read_bytes() == (tmp_path / "cli_crate" / f).read_bytes(), f
    with pytest.raises(uavgen.UavgenError, match="refusing to write"):
        uavgen.generate(model, horizon=20, out=tmp_path / "cli_crate" / "src")
    # MPC options as keywords: a wrong length is the options file's message.
    with pytest.raises(uavgen.UavgenError, match="q"):
        uavgen.generate(model, out=tmp_path / "x", q=[1.0, 2.0])


def test_diagnose_equals_cli(repo, sim_log, cli, tmp_path):
    model = repo / "models/sindy_m100.json"
    cli("diagnose", "--model", model, "--log", sim_log, "--out", tmp_path / "cli")
    report, corrected = uavgen.diagnose(model, [sim_log], out=tmp_path / "py")
    assert report == json.loads((tmp_path / "cli" / "report.json").read_text())
    for name in ("report.json", "corrected.json", "report.md"):
        assert (tmp_path / "py" / name).read_bytes() == (tmp_path / "cli" / name).read_bytes(), name
    assert isinstance(corrected, uavgen.Model)
    assert json.loads(corrected.to_json()) == json.loads((tmp_path / "cli" / "corrected.json").read_text())


def test_track_generic_equals_cli(repo, cli, tmp_path):
    model, plant = repo / "models/pd_m100.json", repo / "plants/m100_like.json"
    cli("track", "--model", model, "--plant", plant, "--trajectory", "circle", "--generic", "--duration", "2",
        "--max-rmse", "inf", "--out", tmp_path / "cli", check=False)
    expected = json.loads((tmp_path / "cli" / "report.json").read_text())
    got = uavgen.track(model, plant, "circle", duration=2, generic=True, max_rmse=float("inf"))["circle"]
    timing = ("feedback", "prepare")
    assert {k: v for k, v in got["report"].items() if k not in timing} == \
        {k: v for k, v in expected.items() if k not in timing}
    assert got["samples"]["x"].shape == (60,)


@pytest.mark.parametrize("method", ["sindy", "pd"])
def test_identify_equals_cli_byte_for_byte(sim_log, cli, tmp_path, method):
    cli_out, py_out = tmp_path / "cli" / f"{method}.json", tmp_path / "py" / f"{method}.json"
    cli_out.parent.mkdir()
    py_out.parent.mkdir()
    cli("identify", "--method", method, "--log", sim_log, "--out", cli_out)
    model = uavgen.identify([uavgen.read_log(sim_log)], method=method, out=py_out)
    # The provenance names the logs and the tool; both are the same here, so the whole file is.
    assert py_out.read_bytes() == cli_out.read_bytes()
    assert model.to_json() == cli_out.read_text() and model.kind == method
    if method == "pd":  # (the cheaper fit) Without a file: the same text, the model named as given.
        again = uavgen.identify(sim_log, method=method, name=method)
        assert again.to_json() == cli_out.read_text()
    with pytest.raises(uavgen.UavgenError, match="--input-delay"):
        uavgen.identify(sim_log, method=method, input_delay="u_nope=0.1")
