"""Model.from_pysindy: a fitted PySINDy model with control inputs as a uavgen Model.

Layers: the converted JSON evaluated term by term here (a tiny independent evaluator of the term
grammar) equals PySINDy's ``predict``; uavgen's compiled ``Model.f`` equals it to 1e-10; uavgen's
fixed-step ``simulate`` equals PySINDy's ``simulate`` to 1e-6 under the same input interpolation
(zero-order hold) with tight tolerances; conversion errors name the feature.
"""

import json
import math
import warnings

import numpy as np
import pytest

ps = pytest.importorskip("pysindy")

import uavgen  # noqa: E402
from uavgen.pysindy import PySindyConversionError, from_pysindy, pysindy_to_model_json  # noqa: E402

DT = 0.005


def true_rhs(x, u):
    """A stable 3-state vehicle-like system with two inputs (no noise: PySINDy recovers it)."""
    p, v, a = x
    f, g = u
    return np.array([
        v,
        -2.0 * p - 0.8 * v + 1.5 * f + 0.3 * math.sin(a) - 0.1 * v * v,
        -3.0 * a + 2.0 * g + 0.5 * v * g,
    ])


def inputs(t):
    return np.column_stack([0.8 * np.sin(0.9 * t) + 0.3 * np.sin(2.3 * t + 0.5), 0.5 * np.cos(1.3 * t)])


@pytest.fixture(scope="module")
def fitted():
    t = np.arange(1500) * 0.01
    U = inputs(t)
    X = np.zeros((len(t), 3))
    X[0] = [0.3, -0.2, 0.1]
    h = 0.01
    for k in range(len(t) - 1):  # RK4 with the input held: exact enough for a fit
        x, u = X[k], U[k]
        k1 = true_rhs(x, u)
        k2 = true_rhs(x + h / 2 * k1, u)
        k3 = true_rhs(x + h / 2 * k2, u)
        k4 = true_rhs(x + h * k3, u)
        X[k + 1] = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    Xdot = np.array([true_rhs(X[k], U[k]) for k in range(len(t))])
    library = ps.GeneralizedLibrary([
        ps.PolynomialLibrary(degree=2),  # "1", "x0", "x0 x1", "x1^2", "x1 u1", …
        ps.FourierLibrary(n_frequencies=1),  # "sin(1 x0)", "cos(1 x0)", …
        ps.IdentityLibrary(),  # "x0" again: the same term as the polynomial's (merged)
    ])
    model = ps.SINDy(feature_library=library, optimizer=ps.STLSQ(threshold=0.05, alpha=1e-6))
    model.fit(X, t=t, x_dot=Xdot, u=U)
    return model, X, U


def as_model(model, **kw):
    hook = getattr(uavgen.Model, "from_pysindy", None)
    return hook(model, **kw) if hook is not None else from_pysindy(model, **kw)


# ---------------------------------------------------------------- the conversion itself
def eval_term(term, env):
    if term == "1":
        return 1.0
    value = 1.0
    for factor in term.split("*"):
        base, _, power = factor.partition("^")
        if base.startswith(("sin(", "cos(")):
            fn = math.sin if base.startswith("sin") else math.cos
            b = fn(env[base[4:-1]])
        else:
            b = env[base]
        value *= b ** (int(power) if power else 1)
    return value


def eval_json(doc, x, u):
    env = dict(zip(doc["states"], x))
    env.update(zip(doc["inputs"], u))
    out = np.zeros(len(doc["states"]))
    for e in doc["coefficients"]:
        out[doc["states"].index(e["state"])] += e["coefficient"] * eval_term(e["term"], env)
    return out


def test_converted_terms_reproduce_predict(fitted):
    model, X, U = fitted
    doc = json.loads(pysindy_to_model_json(model, name="toy"))
    assert doc["states"] == ["x0", "x1", "x2"] and doc["inputs"] == ["u0", "u1"]
    assert doc["kinematic"] == [] and doc["provenance"]["tool"] == "uavgen.from_pysindy"
    # "sin(1 x0)" became "sin(x0)"; the IdentityLibrary's x0 merged with the polynomial's.
    assert "sin(x2)" in doc["library"] and doc["library"].count("x0") == 1
    assert len(doc["library"]) < len(model.get_feature_names())
    pred = model.predict(X[:300], u=U[:300])
    mine = np.array([eval_json(doc, X[k], U[k]) for k in range(300)])
    np.testing.assert_allclose(mine, pred, rtol=0, atol=1e-12)
    # The fit recovered the system (a sanity check of the fixture, not of the conversion).
    rows = {(e["state"], e["term"]): e["coefficient"] for e in doc["coefficients"]}
    assert abs(rows[("x1", "sin(x2)")] - 0.3) < 1e-6 and abs(rows[("x2", "x1*u1")] - 0.5) < 1e-6


def test_names_are_renamed_in_every_term(fitted):
    model, X, U = fitted
    doc = json.loads(pysindy_to_model_json(model, state_names=["p", "v", "a"], input_names=["f", "g"]))
    assert doc["states"] == ["p", "v", "a"] and doc["inputs"] == ["f", "g"]
    assert "v*g" in doc["library"] and "sin(a)" in doc["library"]
    assert not any("x0" in t or "u1" in t for t in doc["library"])
    np.testing.assert_allclose(eval_json(doc, X[7], U[7]), model.predict(X[7:8], u=U[7:8])[0], atol=1e-12)


def test_conversion_errors_name_the_feature(fitted):
    model, X, U = fitted
    t = np.arange(len(X)) * 0.01
    fourier2 = ps.SINDy(feature_library=ps.FourierLibrary(n_frequencies=2), optimizer=ps.STLSQ(threshold=0.0))
    fourier2.fit(X, t=t, u=U)
    with pytest.raises(PySindyConversionError, match=r"'sin\(2 x0\)'.*not a uavgen term"):
        pysindy_to_model_json(fourier2)
    # The same library, every frequency-2 coefficient zero: those features are dropped, not fatal.
    fourier2.optimizer.coef_[:, [i for i, n in enumerate(fourier2.get_feature_names()) if "(2 " in n]] = 0.0
    doc = json.loads(pysindy_to_model_json(fourier2))
    assert "sin(2 x0)" in doc["provenance"]["dropped_unused_features"]
    with pytest.raises(PySindyConversionError, match="2 state_names for 3 states"):
        pysindy_to_model_json(model, state_names=["a", "b"])
    with pytest.raises(PySindyConversionError, match="not a uavgen variable name"):
        pysindy_to_model_json(model, input_names=["f", "2g"])
    with pytest.raises(PySindyConversionError, match="not fitted"):
        pysindy_to_model_json(ps.SINDy())


# ---------------------------------------------------------------- through uavgen's Model
def test_f_equals_predict(fitted):
    model, X, U = fitted
    m = as_model(model, name="toy")
    rng = np.random.default_rng(3)
    xs = X[rng.integers(0, len(X), 200)] + rng.normal(0, 0.5, (200, 3))
    us = U[rng.integers(0, len(U), 200)] + rng.normal(0, 0.5, (200, 2))
    pred = model.predict(xs, u=us)
    ours = np.array([np.asarray(m.f(xs[k], us[k]), dtype=float) for k in range(200)])
    err = np.max(np.abs(ours - pred))
    assert err <= 1e-10, err


def zoh(t, U):
    """The input held over each sample: u(t) = U[k] for t_k ≤ t < t_{k+1}."""
    dt = t[1] - t[0]

    def u(tt):
        k = int(math.floor((tt - t[0]) / dt + 1e-9))
        return U[min(max(k, 0), len(U) - 1)]

    return u


def simulate_states(m, x0, U, dt):
    """uavgen's simulate as the states x_0 … x_n for n held inputs."""
    out = m.simulate(x0, U, dt)
    xs = np.asarray(out[0] if isinstance(out, tuple) else out, dtype=float)
    if xs.shape[0] == len(U) + 1:
        return xs
    assert xs.shape[0] == len(U), xs.shape
    return xs if np.array_equal(xs[0], x0) else np.vstack([x0, xs[:-1]])


def test_simulate_matches_pysindy(fitted):
    model, X, U = fitted
    m = as_model(model, name="toy")
    # 0.5 s at 200 Hz, the commands stepping every 0.25 s (PySINDy's predict costs ~5-10 ms a call
    # and its adaptive integrator shortens its steps at every jump: keep the reference cheap).
    n = 100
    t = np.arange(n + 1) * DT
    Useq = inputs(np.floor(t[:-1] / 0.25) * 0.25)
    x0 = np.array([0.5, -0.3, 0.2])
    ours = simulate_states(m, x0, Useq, DT)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = model.simulate(x0, t, u=zoh(t, Useq),
                             integrator_kws={"method": "DOP853", "rtol": 1e-10, "atol": 1e-10})
    err = np.max(np.abs(ours[: len(ref)] - ref))
    assert err <= 1e-6, err


# ---------------------------------------------------------------- compiled: the round trip's end
def test_compiled_dynamics_and_closed_loop(fitted, tmp_path):
    """The fitted PySINDy model compiled (uavgen.compile): its discrete dynamics are RK4 over
    PySINDy's predict with the input held, and its MPC holds a setpoint of the toy vehicle."""
    from uavgen.compile import Controller

    model, X, U = fitted
    m = as_model(model, name="toy", state_names=["p", "v", "a"], input_names=["f", "g"])
    mpc = uavgen.compile(m, horizon=20, cache_dir=tmp_path, q=[10.0, 1.0, 0.0], q_terminal=[10.0, 1.0, 0.0],
                         r=[0.1, 0.1], r_delta=[0.0, 0.0], u_min=[-2.0, -2.0], u_max=[2.0, 2.0])
    assert (mpc.nx, mpc.nu, mpc.state_names, mpc.input_names) == (3, 2, ["p", "v", "a"], ["f", "g"])

    def rk4(x, u):
        f = lambda z: model.predict(z[None, :], u=u[None, :])[0]  # noqa: E731
        h = mpc.dt / mpc.substeps
        for _ in range(mpc.substeps):
            k1 = f(x)
            k2 = f(x + h / 2 * k1)
            k3 = f(x + h / 2 * k2)
            k4 = f(x + h * k3)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return x

    for k in range(0, 1500, 150):
        np.testing.assert_allclose(mpc.discrete_dynamics(X[k], U[k]), rk4(X[k], U[k]), rtol=0, atol=1e-12)

    setpoint = np.array([1.0, 0.0, 0.0])
    ctl = Controller(mpc, lambda t: setpoint)
    x = np.zeros(3)
    ctl.initialize(x)
    ctl.start(0.0)
    for _ in range(150):  # 5 s at 30 Hz
        u, status = ctl.step(x)
        assert status.produced_input and np.all(np.abs(u) <= 2.0)
        x = mpc.discrete_dynamics(x, u)
    assert abs(x[0] - 1.0) < 0.02 and abs(x[1]) < 0.02, x
