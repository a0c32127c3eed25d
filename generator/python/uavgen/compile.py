"""The firmware's solver from Python: ``uavgen.compile(model, horizon=30, **mpc_options) -> Mpc``.

``compile`` generates the model's crate with its C ABI (``uavgen --c-api``, docs/c-api.md), builds
the ABI package as a shared library with cargo (``cargo rustc --release --lib --crate-type cdylib``
on ``capi/Cargo.toml``: the package is a ``staticlib`` + ``rlib`` for C; the cdylib is the same code
for ``ctypes``), caches it under a hash of the model, the options and the uavgen version, and loads
it with ``ctypes``. The returned :class:`Mpc` calls the C ABI's functions on numpy arrays — the
same compiled code a flight computer runs, as ``AcadosOcpSolver`` wraps acados's generated C.

:class:`Controller` is ``uavgen-runtime``'s ``Controller`` with its ``DelayCompensator`` and
disturbance observer over an :class:`Mpc`: the timeline ``uavgen track`` runs (its harness,
runtime/track-harness), in Python, so a closed loop written here equals ``track``'s.
See docs/python.md, "Compiled MPC".
"""

from __future__ import annotations

import ctypes
import enum
import hashlib
import json
import math
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

__all__ = [
    "compile",
    "Mpc",
    "Status",
    "Controller",
    "CompileError",
    "CargoNotFoundError",
    "MpcError",
    "trajectory_state",
    "default_cache_dir",
]

# The C ABI version this module speaks (<NAME>_ABI_VERSION of the header).
ABI_VERSION = 1

CARGO_HINT = (
    "uavgen.compile builds the generated crate with cargo (Rust), which was not found{where}. "
    "Install Rust with rustup (https://rustup.rs: "
    "curl --proto '=https' --tlsv1.2 -sSf https://sh.rustup.rs | sh), open a new shell or add "
    "~/.cargo/bin to PATH, or set the CARGO environment variable to cargo's path."
)


class CompileError(RuntimeError):
    """Generating or building the crate failed (the message has cargo's output)."""


class CargoNotFoundError(CompileError):
    """cargo is not installed (or not on PATH): the message says what to install."""


class MpcError(RuntimeError):
    """The C ABI refused a call (a negative status: the call changed nothing)."""

    def __init__(self, function: str, status: "Status"):
        super().__init__(f"{function}: {status.name} ({int(status)}): {status.meaning}")
        self.function = function
        self.status = status


class Status(enum.IntEnum):
    """The C ABI's status codes (docs/c-api.md, "Statuses"). 0…5 are the solver's: an input was
    produced, finite and within the bounds whatever the status. Negative codes are refusals (raised
    as :class:`MpcError` by :class:`Mpc`'s methods)."""

    SOLVED = 0
    ITERATION_CAP = 1
    HESSIAN_REGULARISED = 2
    INVALID_INPUT = 3
    NUMERICAL_FAILURE = 4
    OUT_OF_ENVELOPE = 5
    NULL_POINTER = -1
    MISALIGNED = -2
    STORAGE_TOO_SMALL = -3
    NOT_INITIALISED = -4
    OVERLAP = -5
    NO_SOLUTION = -6

    OK = 0  # alias of SOLVED (the call succeeded)

    @property
    def meaning(self) -> str:
        return _MEANINGS[self]

    @property
    def produced_input(self) -> bool:
        """0…5: the solver ran and its input is to be applied."""
        return int(self) >= 0


_MEANINGS = {
    Status.SOLVED: "the QP was solved to optimality",
    Status.ITERATION_CAP: "the QP hit MAX_QP_ITERATIONS or MAX_QP_WORK; the best bounded iterate was applied",
    Status.HESSIAN_REGULARISED: "the condensed Hessian needed a multiple of I to be positive definite",
    Status.INVALID_INPUT: "a non-finite state or reference: the previous plan is kept",
    Status.NUMERICAL_FAILURE: "a non-finite value in the linearisation or the step: the previous plan is kept",
    Status.OUT_OF_ENVELOPE: "x0 or the reference lies outside the model's envelope: the input means nothing",
    Status.NULL_POINTER: "a pointer argument is NULL",
    Status.MISALIGNED: "the storage is not aligned",
    Status.STORAGE_TOO_SMALL: "the storage is smaller than the solver needs",
    Status.NOT_INITIALISED: "the storage was not initialised by init() of this model",
    Status.OVERLAP: "an array argument overlaps the storage",
    Status.NO_SOLUTION: "no feedback() or solve() since init()",
}

# Header enum names -> Status (checked against the header at load).
_HEADER_STATUS = {
    "OK": 0,
    "SOLVED": 0,
    "ITERATION_CAP": 1,
    "HESSIAN_REGULARISED": 2,
    "INVALID_INPUT": 3,
    "NUMERICAL_FAILURE": 4,
    "OUT_OF_ENVELOPE": 5,
    "NULL_POINTER": -1,
    "MISALIGNED": -2,
    "STORAGE_TOO_SMALL": -3,
    "NOT_INITIALISED": -4,
    "OVERLAP": -5,
    "NO_SOLUTION": -6,
}


# --------------------------------------------------------------------------- header
def _parse_value(text: str):
    text = text.strip()
    if text.startswith("{"):
        inner = text.strip("{} ")
        if not inner:
            return []
        return [_parse_value(v) for v in inner.split(",")]
    if text.startswith('"'):
        return json.loads(text)
    try:
        return int(text)
    except ValueError:
        return float(text)


def parse_header(path: Union[str, Path]) -> Dict[str, object]:
    """The ``#define``s and status codes of a generated ``include/<name>.h``: ``{"prefix", "NX", …,
    "STATUS": {name: value}, "real": "double" | "float"}``."""
    text = Path(path).read_text()
    stem = Path(path).stem
    macro = stem.upper()
    out: Dict[str, object] = {"prefix": stem}
    for m in re.finditer(rf"^#define {re.escape(macro)}_([A-Z0-9_]+) (.+)$", text, re.MULTILINE):
        key, value = m.group(1), m.group(2)
        if key in ("H", "ALIGNAS(n)") or key.startswith("ALIGNAS"):
            continue
        try:
            out[key] = _parse_value(value)
        except (ValueError, json.JSONDecodeError):
            out[key] = value
    m = re.search(rf"typedef (double|float) {re.escape(stem)}_real;", text)
    if m is None:
        raise CompileError(f"{path}: no `typedef … {stem}_real;` (not a uavgen C ABI header?)")
    out["real"] = m.group(1)
    out["STATUS"] = {
        k: int(v) for k, v in re.findall(rf"^\s*{re.escape(macro)}_([A-Z_]+) = (-?[0-9]+),", text, re.MULTILINE)
    }
    for key in ("ABI_VERSION", "NX", "NU", "N", "DT"):
        if key not in out:
            raise CompileError(f"{path}: no {macro}_{key}")
    return out


# --------------------------------------------------------------------------- Mpc
class Mpc:
    """A compiled MPC: the C ABI of a generated crate (docs/c-api.md) loaded with ctypes.

    Arrays are numpy arrays (any float dtype in, ``dtype`` out: float64, or float32 for an f32 crate):
    a state is ``(nx,)``, an input ``(nu,)``, a reference ``(N + 1, nx)`` (or one ``(nx,)`` state for
    every stage), a plan ``(N, nu)``. ``feedback`` and ``solve`` return ``(u, Status)``: ``u`` is
    the input to apply, finite and within ``[u_min, u_max]`` whatever the status; ``prepare``,
    ``shift``, ``initialize``, ``set_guess`` and ``set_disturbance`` return the :class:`Status`.
    A refusal of the ABI (a negative code) raises :class:`MpcError`.

    The storage (``storage_size`` bytes) is owned by the object; one ``Mpc`` is one solver, not to
    be used from two threads at once.
    """

    def __init__(self, library: Union[str, Path], header: Union[str, Path], crate_dir: Optional[Path] = None):
        self.library_path = Path(library)
        self.header_path = Path(header)
        self.crate_dir = crate_dir
        h = parse_header(header)
        if h["ABI_VERSION"] != ABI_VERSION:
            raise CompileError(
                f"{header}: C ABI version {h['ABI_VERSION']}, this uavgen speaks {ABI_VERSION}: recompile"
            )
        for name, value in h["STATUS"].items():
            if _HEADER_STATUS.get(name) != value:
                raise CompileError(f"{header}: status {name} = {value}, uavgen.Status has {_HEADER_STATUS.get(name)}")
        self.header = h
        self.prefix: str = h["prefix"]
        self.nx: int = int(h["NX"])
        self.nu: int = int(h["NU"])
        self.horizon: int = int(h["N"])
        self.dt: float = float(h["DT"])
        self.substeps: int = int(h.get("SUBSTEPS", 1))
        self.model_name: str = h.get("MODEL_NAME", self.prefix)
        self.model_sha256: str = h.get("MODEL_SHA256", "")
        self.state_names: List[str] = list(h.get("STATE_NAMES", []))
        self.input_names: List[str] = list(h.get("INPUT_NAMES", []))
        self.dtype = np.float64 if h["real"] == "double" else np.float32
        self.u_min = np.array(h["U_MIN"], dtype=self.dtype)
        self.u_max = np.array(h["U_MAX"], dtype=self.dtype)
        self.input_delay_samples: List[int] = [int(v) for v in h.get("INPUT_DELAY_SAMPLES", [0] * self.nu)]
        self.input_lead: List[int] = [int(v) for v in h.get("INPUT_LEAD", [0] * self.nu)]
        self.disturbance_gain = float(h.get("DISTURBANCE_GAIN", 0.0))
        self.disturbance_bound = np.array(h.get("DISTURBANCE_BOUND", [0.0] * self.nx), dtype=self.dtype)

        self._lib = ctypes.CDLL(str(self.library_path))
        real = ctypes.c_double if self.dtype == np.float64 else ctypes.c_float
        rp = ctypes.POINTER(real)
        vp, st, sz = ctypes.c_void_p, ctypes.c_int32, ctypes.c_size_t
        sigs = {
            "storage_size": (sz, []),
            "storage_align": (sz, []),
            "init": (st, [vp, sz, rp, rp]),
            "set_guess": (st, [vp, rp, rp]),
            "prepare": (st, [vp, rp]),
            "feedback": (st, [vp, rp, rp]),
            "solve": (st, [vp, rp, rp, rp]),
            "shift": (st, [vp]),
            "set_disturbance": (st, [vp, rp]),
            "last_status": (st, [vp]),
            "first_input": (st, [vp, rp]),
            "qp_iterations": (st, [vp, ctypes.POINTER(ctypes.c_uint32)]),
            "cost": (st, [vp, rp]),
            "planned_inputs": (st, [vp, rp]),
            "predicted_states": (st, [vp, rp]),
            "discrete_dynamics": (st, [rp, rp, rp]),
        }
        self._fn = {}
        for name, (restype, argtypes) in sigs.items():
            f = getattr(self._lib, f"{self.prefix}_{name}")
            f.restype, f.argtypes = restype, argtypes
            self._fn[name] = f
        self._real_p = rp
        self.storage_size: int = int(self._fn["storage_size"]())
        align = int(self._fn["storage_align"]())
        self._buffer = np.zeros(self.storage_size + align, dtype=np.uint8)
        offset = (-self._buffer.ctypes.data) % align
        self._storage = ctypes.c_void_p(self._buffer.ctypes.data + offset)
        self.initialize(np.zeros(self.nx), np.clip(np.zeros(self.nu), self.u_min, self.u_max))

    def __repr__(self) -> str:
        return (
            f"<uavgen.Mpc {self.model_name!r}: {self.nx} states, {self.nu} inputs, N = {self.horizon}, "
            f"dt = {self.dt:g} s, {self.library_path}>"
        )

    # -- helpers
    def _array(self, what: str, value, shape: Tuple[int, ...]) -> np.ndarray:
        a = np.asarray(value, dtype=self.dtype)
        if a.shape != shape:
            if len(shape) == 2 and a.shape == shape[1:]:
                a = np.broadcast_to(a, shape)
            elif a.size == math.prod(shape) and a.ndim == 1 and len(shape) == 2:
                a = a.reshape(shape)
            else:
                raise ValueError(f"{self.prefix}: {what} must have shape {shape}, got {a.shape}")
        return np.ascontiguousarray(a, dtype=self.dtype)

    def _p(self, a: np.ndarray):
        return a.ctypes.data_as(self._real_p)

    def _check(self, function: str, code: int) -> Status:
        status = Status(code)
        if code < 0:
            raise MpcError(f"{self.prefix}_{function}", status)
        return status

    # -- the ABI
    def initialize(self, x0, u=None) -> Status:
        """``init``: a fresh solver whose guess is the constant ``x0``, ``u`` (default: 0 clamped into
        the bounds). INVALID_INPUT (zero guess) if they are not finite."""
        x = self._array("x0", x0, (self.nx,))
        uu = np.clip(np.zeros(self.nu), self.u_min, self.u_max) if u is None else u
        uu = self._array("u", uu, (self.nu,))
        return self._check("init", self._fn["init"](self._storage, self.storage_size, self._p(x), self._p(uu)))

    def set_guess(self, xs, us) -> Status:
        xs = self._array("xs", xs, (self.horizon + 1, self.nx))
        us = self._array("us", us, (self.horizon, self.nu))
        return self._check("set_guess", self._fn["set_guess"](self._storage, self._p(xs), self._p(us)))

    def prepare(self, reference) -> Status:
        """Linearise along the guess, condense and factorise for the reference ``(N + 1, nx)``."""
        r = self._array("reference", reference, (self.horizon + 1, self.nx))
        return self._check("prepare", self._fn["prepare"](self._storage, self._p(r)))

    def feedback(self, x0) -> Tuple[np.ndarray, Status]:
        """The measured state in, the input to apply out: ``(u, status)``."""
        x = self._array("x0", x0, (self.nx,))
        u = np.zeros(self.nu, dtype=self.dtype)
        status = self._check("feedback", self._fn["feedback"](self._storage, self._p(x), self._p(u)))
        return u, status

    def solve(self, x0, reference) -> Tuple[np.ndarray, Status]:
        """``prepare`` + ``feedback``: ``(u, status)``."""
        x = self._array("x0", x0, (self.nx,))
        r = self._array("reference", reference, (self.horizon + 1, self.nx))
        u = np.zeros(self.nu, dtype=self.dtype)
        status = self._check("solve", self._fn["solve"](self._storage, self._p(x), self._p(r), self._p(u)))
        return u, status

    def shift(self) -> Status:
        """Guess and stored reference one sample ahead (after applying u, before the next prepare)."""
        return self._check("shift", self._fn["shift"](self._storage))

    def set_disturbance(self, e) -> Status:
        """Predict with x⁺ = F(x, u) + e from the next prepare on (offset-free tracking)."""
        e = self._array("e", e, (self.nx,))
        return self._check("set_disturbance", self._fn["set_disturbance"](self._storage, self._p(e)))

    @property
    def last_status(self) -> Status:
        """The latest feedback/solve's status (NO_SOLUTION before the first)."""
        return Status(self._fn["last_status"](self._storage))

    def first_input(self) -> np.ndarray:
        u = np.zeros(self.nu, dtype=self.dtype)
        self._check("first_input", self._fn["first_input"](self._storage, self._p(u)))
        return u

    @property
    def qp_iterations(self) -> int:
        n = ctypes.c_uint32(0)
        self._check("qp_iterations", self._fn["qp_iterations"](self._storage, ctypes.byref(n)))
        return int(n.value)

    @property
    def cost(self) -> float:
        c = np.zeros(1, dtype=self.dtype)
        self._check("cost", self._fn["cost"](self._storage, self._p(c)))
        return float(c[0])

    def planned_inputs(self) -> np.ndarray:
        """The current plan's inputs u_0 … u_{N−1}, ``(N, nu)``."""
        us = np.zeros((self.horizon, self.nu), dtype=self.dtype)
        self._check("planned_inputs", self._fn["planned_inputs"](self._storage, self._p(us)))
        return us

    def predicted_states(self) -> np.ndarray:
        """The current plan's states x_0 … x_N, ``(N + 1, nx)``."""
        xs = np.zeros((self.horizon + 1, self.nx), dtype=self.dtype)
        self._check("predicted_states", self._fn["predicted_states"](self._storage, self._p(xs)))
        return xs

    def discrete_dynamics(self, x, u) -> np.ndarray:
        """The model over one sample, x⁺ = F(x, u) (the crate's RK4 with its substeps)."""
        xa = self._array("x", x, (self.nx,))
        ua = self._array("u", u, (self.nu,))
        out = np.zeros(self.nx, dtype=self.dtype)
        self._check("discrete_dynamics", self._fn["discrete_dynamics"](self._p(xa), self._p(ua), self._p(out)))
        return out


# --------------------------------------------------------------------------- reference
def trajectory_state(name: str, t: float, nx: int) -> np.ndarray:
    """The paper's trajectories as uavgen-runtime's ``Trajectory::state`` writes them: position in
    states 0..3, the analytic velocity in 6..9 if nx ≥ 9, 0 elsewhere (docs/track.md)."""
    s, c, e = math.sin, math.cos, math.exp
    if name in ("sinusoid", "sinusoidal"):
        p = [4.0 * s(0.32 * t) + 3.0, 4.0 * s(0.64 * t), 2.0 * s(0.64 * t) + 6.0]
        v = [(4.0 * 0.32) * c(0.32 * t), (4.0 * 0.64) * c(0.64 * t), (2.0 * 0.64) * c(0.64 * t)]
    elif name in ("circle", "circular"):
        p = [5.0 * c(t), 5.0 * s(t), 6.0]
        v = [-5.0 * s(t), 5.0 * c(t), 0.0]
    elif name == "spiral":
        g = e(0.06 * t)
        p = [g * c(t), g * s(t), 0.1 * t + 5.0]
        v = [g * (0.06 * c(t) - s(t)), g * (0.06 * s(t) + c(t)), 0.1]
    else:
        raise ValueError(f"unknown trajectory '{name}' (sinusoid, circle, spiral)")
    x = np.zeros(nx)
    x[: min(3, nx)] = p[: min(3, nx)]
    if nx >= 9:
        x[6:9] = v
    return x


# --------------------------------------------------------------------------- Controller
MAX_GAP = 4  # uavgen-runtime's disturbance::MAX_GAP
MAX_DELAY = 32  # the track harness's DelayCompensator capacity


class _Observer:
    """uavgen-runtime's DisturbanceObserver (runtime/src/disturbance.rs), same arithmetic."""

    def __init__(self, gain: float, bound: np.ndarray):
        gain = min(max(gain, 0.0), 1.0) if math.isfinite(gain) else 0.0
        self.gain = gain
        self.bound = np.array([b if (b == b and b > 0.0) else 0.0 for b in bound], dtype=float)
        n = len(bound)
        self.estimate = np.zeros(n)
        self.predicted = np.zeros(n)
        self.last = np.zeros(n)
        self.measured = False
        self.gap = 0

    def active(self) -> bool:
        return self.gain > 0.0 and bool(np.any(self.bound > 0.0))

    def measure(self, x: np.ndarray) -> None:
        if not np.all(np.isfinite(x)) or (self.measured and np.array_equal(x, self.last)):
            return
        if self.measured and 0 < self.gap <= MAX_GAP:
            m = float(self.gap)
            for i in range(len(x)):
                step = self.gain * (x[i] - self.predicted[i]) / m
                b = self.bound[i]
                if b > 0.0 and math.isfinite(step):
                    self.estimate[i] = min(max(self.estimate[i] + step, -b), b)
        self.last = x.copy()
        self.predicted = x.copy()
        self.measured = True
        self.gap = 0

    def advance(self, dynamics, u: np.ndarray) -> None:
        if not self.measured or self.gap > MAX_GAP:
            return
        self.predicted = dynamics(self.predicted, u) + self.estimate
        self.gap += 1


class Controller:
    """uavgen-runtime's ``Controller`` + ``DelayCompensator`` (with the disturbance observer) over an
    :class:`Mpc`, as runtime/track-harness builds them for ``uavgen track``.

    ``reference`` is one of the paper's trajectories (``"circle"``, ``"sinusoid"``, ``"spiral"``) or a
    function ``t -> state`` (``(nx,)``). Each sample: ``u, status = c.feedback(x)`` (observer update,
    the state predicted over the shared input delay, the solver's feedback, the input sanitised), apply
    ``u``, then ``c.prepare_next()`` (record the input, shift, the reference window from
    t + (k + D)·dt, the disturbance estimate handed to the solver, prepare). ``step(x)`` does both.
    The input is the runtime's bit for bit (``tests/test_compile.py`` compares it with the harness).
    The runtime's supervisor (stale measurement, not converging) changes no input and is not
    reproduced.
    """

    def __init__(self, mpc: Mpc, reference: Union[str, Callable[[float], Sequence[float]]] = "circle", *,
                 disturbance_observer: bool = True):
        self.mpc = mpc
        if isinstance(reference, str):
            name = reference
            trajectory_state(name, 0.0, mpc.nx)  # validates the name
            self._reference = lambda t: trajectory_state(name, t, mpc.nx)
        else:
            self._reference = reference
        self.delays = list(mpc.input_delay_samples)
        if any(d > MAX_DELAY for d in self.delays):
            raise ValueError(f"input delays {self.delays} samples: more than the {MAX_DELAY} compensated")
        hover = np.clip(np.zeros(mpc.nu), mpc.u_min, mpc.u_max).astype(float)
        self.last_input = hover.copy()
        self.history = [hover.copy() for _ in range(MAX_DELAY)]
        obs = _Observer(mpc.disturbance_gain, mpc.disturbance_bound) if disturbance_observer else None
        self.observer = obs if obs is not None and obs.active() else None
        self.window = np.zeros((mpc.horizon + 1, mpc.nx))
        self.window_valid = False
        self.prepared = False
        self.started = False
        self.t0 = 0.0
        self.steps = 0
        self.predicted = np.zeros(mpc.nx)

    # DelayCompensator
    @property
    def lookahead(self) -> int:
        """D: the input delay every channel shares (samples)."""
        return min(self.delays) if self.delays else 0

    def _model_step(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        nxt = self.mpc.discrete_dynamics(x, u).astype(float)
        if self.observer is not None:
            nxt = nxt + self.observer.estimate
        return nxt

    def _predict(self, x: np.ndarray) -> np.ndarray:
        xm = x.copy()
        for m in range(self.lookahead):
            u = np.array([self.history[d - m - 1][i] for i, d in enumerate(self.delays)])
            xm = self._model_step(xm, u)
        return xm

    def _record(self, u: np.ndarray) -> None:
        self.history = [u.copy()] + self.history[:-1]
        if self.observer is not None:
            acted = np.array([
                (self.history[d] if d < len(self.history) else self.history[-1])[i]
                for i, d in enumerate(self.delays)
            ])
            self.observer.advance(lambda x, uu: self.mpc.discrete_dynamics(x, uu).astype(float), acted)

    # Controller
    def initialize(self, x0, u=None) -> Status:
        """Reset the guess to the constant ``x0``, ``u`` and the input history to ``u``."""
        u = np.clip(np.zeros(self.mpc.nu), self.mpc.u_min, self.mpc.u_max) if u is None else np.asarray(u, float)
        self.history = [np.array(u, dtype=float) for _ in range(MAX_DELAY)]
        if self.observer is not None:
            self.observer = _Observer(self.mpc.disturbance_gain, self.mpc.disturbance_bound)
        self.prepared = False
        return self.mpc.initialize(x0, u)

    def time(self) -> float:
        return self.t0 + float(self.steps) * self.mpc.dt

    def reference_time(self) -> float:
        return self.t0 + float(self.steps + self.lookahead) * self.mpc.dt

    def start(self, t0: float = 0.0) -> Status:
        """Set the time and prepare the first QP (the first call does not shift)."""
        shifts = 0
        if self.started:
            samples = (t0 - self.time()) / self.mpc.dt
            if math.isfinite(samples) and 0.5 <= samples < self.mpc.horizon + 2.5:
                shifts = int(samples + 0.5)
        self.t0 = float(t0)
        self.steps = 0
        self.started = True
        return self._prepare(shifts, 0)

    def _prepare(self, shifts: int, steps: int) -> Optional[Status]:
        for _ in range(shifts):
            self._record(self.last_input)
            self.mpc.shift()
        self.steps += steps
        t = self.reference_time()
        dt = self.mpc.dt
        window = np.array([self._reference(t + float(k) * dt) for k in range(self.mpc.horizon + 1)], dtype=float)
        if np.all(np.isfinite(window)):
            self.window = window
            self.window_valid = True
        elif not self.window_valid:
            self.prepared = False
            return None
        elif shifts > 0:
            self.window = np.vstack([self.window[1:], self.window[-1:]])
        if self.observer is not None:
            self.mpc.set_disturbance(self.observer.estimate)
        status = self.mpc.prepare(self.window)
        self.prepared = True
        return status

    def feedback(self, x) -> Tuple[np.ndarray, Status]:
        """The measurement step: ``(u, status)``, u finite and within the bounds."""
        x = np.asarray(x, dtype=float)
        if not self.prepared:
            self._prepare(0, 0)
        if not self.prepared:
            return self.last_input.copy(), Status.INVALID_INPUT
        if self.observer is not None:
            self.observer.measure(x)
        self.predicted = self._predict(x)
        u, status = self.mpc.feedback(self.predicted)
        self.prepared = False
        u = np.where(np.isfinite(u), u, self.last_input)
        u = np.minimum(np.maximum(u, self.mpc.u_min), self.mpc.u_max).astype(float)
        self.last_input = u
        return u.copy(), status

    def prepare_next(self) -> Optional[Status]:
        """Shift, advance the time by dt, build the next window, prepare."""
        self.started = True
        return self._prepare(1, 1)

    def step(self, x) -> Tuple[np.ndarray, Status]:
        """``feedback(x)`` then ``prepare_next()``."""
        out = self.feedback(x)
        self.prepare_next()
        return out


# --------------------------------------------------------------------------- compile
def default_cache_dir() -> Path:
    """``$UAVGEN_CACHE_DIR``, else ``$XDG_CACHE_HOME/uavgen/compile``, else ``~/.cache/uavgen/compile``."""
    if os.environ.get("UAVGEN_CACHE_DIR"):
        return Path(os.environ["UAVGEN_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "uavgen" / "compile"


def _model_json(model) -> str:
    if hasattr(model, "to_json"):
        return model.to_json()
    if isinstance(model, (str, os.PathLike)):
        text = str(model)
        if text.lstrip().startswith("{"):
            return text
        return Path(model).read_text()
    raise TypeError(f"compile: expected a uavgen.Model (or a model file's path or JSON text), got {type(model).__name__}")


def _uavgen_version() -> str:
    try:
        from . import __version__  # type: ignore

        return str(__version__)
    except ImportError:
        return "unknown"


def _jsonable(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    return v


def _shared_library_name(package: str) -> str:
    if sys.platform == "darwin":
        return f"lib{package}.dylib"
    if sys.platform == "win32":
        return f"{package}.dll"
    return f"lib{package}.so"


def _generate(model_json: str, horizon: int, out: Path, mpc_options_json: Optional[str], **codegen) -> None:
    from . import _uavgen  # the compiled extension (uavgen/_uavgen)

    # c_api = True, force = True (the cache entry's crate directory is ours to overwrite).
    _uavgen.generate(model_json, horizon, str(out), True, mpc_options_json, True, **codegen)


def compile(model, horizon: int = 30, *, cache_dir: Optional[Union[str, Path]] = None, quiet: bool = True,
            rate_hz: float = 30.0, substeps: Optional[int] = None, float: str = "f64", qp: str = "auto",
            **mpc_options) -> Mpc:
    """Generate ``model``'s MPC crate with its C ABI, build it with cargo and load it: an :class:`Mpc`.

    ``horizon`` is N (samples); ``rate_hz``, ``substeps``, ``float`` (``"f64"``/``"f32"``) and ``qp``
    (``"auto"``/``"condensed"``/``"riccati"``) are the generator's ``--rate``, ``--substeps``,
    ``--float`` and ``--qp`` (docs/cli.md); ``mpc_options`` are the MPC options of docs/mpc.md (``q``, ``r``,
    ``r_delta``, ``u_min``, ``u_max``, ``max_qp_iterations``, ``disturbance_gain``, …; what ``--mpc``
    reads). The result is cached in ``cache_dir`` (default :func:`default_cache_dir`) under the
    SHA-256 of the model JSON, the horizon, the options, the uavgen version and the platform: a
    second call with the same arguments loads the library without cargo. ``quiet=False`` shows
    cargo's output.

    Raises :class:`CargoNotFoundError` if the library must be built and cargo is not installed,
    :class:`CompileError` if the build fails, and the generator's error (the message ``uavgen``
    prints) for an invalid model or options.
    """
    model_json = _model_json(model)
    options = {k: _jsonable(v) for k, v in sorted(mpc_options.items())}
    options_json = json.dumps(options, sort_keys=True) if options else None
    if not isinstance(horizon, int) or horizon < 1:
        raise ValueError(f"compile: horizon must be a positive number of samples, got {horizon!r}")
    # Only what differs from the generator's defaults is passed (and hashed).
    codegen = {k: v for k, v in (("rate_hz", rate_hz), ("substeps", substeps), ("float", float), ("qp", qp))
               if v != {"rate_hz": 30.0, "substeps": None, "float": "f64", "qp": "auto"}[k]}
    key = json.dumps(
        {
            "model": model_json,
            "horizon": horizon,
            "codegen": codegen,
            "mpc_options": options,
            "uavgen": _uavgen_version(),
            "abi": ABI_VERSION,
            "platform": [sys.platform, platform.machine()],
        },
        sort_keys=True,
    )
    digest = hashlib.sha256(key.encode()).hexdigest()[:20]
    cache = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    entry = cache / digest
    meta_path = entry / "uavgen-compile.json"
    if meta_path.is_file():
        meta = json.loads(meta_path.read_text())
        lib, header = entry / meta["library"], entry / meta["header"]
        if lib.is_file() and header.is_file():
            return Mpc(lib, header, entry / "crate")

    cargo = os.environ.get("CARGO") or "cargo"
    cargo_path = shutil.which(cargo)
    if cargo_path is None:
        where = f" (CARGO={cargo!r})" if os.environ.get("CARGO") else " on PATH"
        raise CargoNotFoundError(CARGO_HINT.format(where=where))

    entry.mkdir(parents=True, exist_ok=True)
    with _EntryLock(entry / ".lock"):
        # Another process may have built the entry while this one waited for the lock.
        if meta_path.is_file():
            meta = json.loads(meta_path.read_text())
            lib, header = entry / meta["library"], entry / meta["header"]
            if lib.is_file() and header.is_file():
                return Mpc(lib, header, entry / "crate")
        return _build(entry, meta_path, cache, cargo_path, model_json, horizon, options, options_json, codegen, quiet)


class _EntryLock:
    """An exclusive lock on a cache entry (POSIX flock; no lock where fcntl is missing)."""

    def __init__(self, path: Path):
        self.path = path
        self.fh = None

    def __enter__(self):
        try:
            import fcntl
        except ImportError:  # Windows: builds of one entry by two processes at once are not guarded
            return self
        self.fh = open(self.path, "w")
        fcntl.flock(self.fh, fcntl.LOCK_EX)
        return self

    def __exit__(self, *exc):
        if self.fh is not None:
            self.fh.close()  # releases the lock
        return False


def _build(entry: Path, meta_path: Path, cache: Path, cargo_path: str, model_json: str, horizon: int,
           options: Dict, options_json: Optional[str], codegen: Dict, quiet: bool) -> Mpc:
    crate = entry / "crate"
    _generate(model_json, horizon, crate, options_json, **codegen)
    headers = sorted((crate / "include").glob("*.h"))
    if len(headers) != 1:
        raise CompileError(f"{crate}: expected one header in include/, found {len(headers)}")
    manifest = (crate / "capi" / "Cargo.toml").read_text()
    m = re.search(r'^name = "([^"]+)"', manifest, re.MULTILINE)
    if m is None:
        raise CompileError(f"{crate / 'capi' / 'Cargo.toml'}: no package name")
    package = m.group(1)
    target = cache / "target"  # shared by every entry: libm and the toolchain's std build once
    cmd = [
        cargo_path, "rustc", "--release", "--lib", "--crate-type", "cdylib",
        "--manifest-path", str(crate / "capi" / "Cargo.toml"), "--target-dir", str(target),
    ]
    if quiet:
        cmd.append("--quiet")
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if not quiet:
        sys.stderr.write(proc.stdout + proc.stderr)
    if proc.returncode != 0:
        raise CompileError(
            f"building {package} failed (exit status {proc.returncode}): {' '.join(cmd)}\n{proc.stderr[-4000:]}"
        )
    built = target / "release" / _shared_library_name(package)
    if not built.is_file():
        raise CompileError(f"cargo succeeded but {built} is missing")
    # One file per cache entry (dlopen caches by path), written atomically.
    lib = entry / _shared_library_name(package)
    fd, tmp = tempfile.mkstemp(dir=entry, suffix=".part")
    os.close(fd)
    shutil.copyfile(built, tmp)
    os.replace(tmp, lib)
    header = headers[0]
    meta = {
        "library": lib.name,
        "header": str(header.relative_to(entry)),
        "package": package,
        "horizon": horizon,
        "mpc_options": options,
        "uavgen": _uavgen_version(),
    }
    tmp_meta = entry / "uavgen-compile.json.part"
    tmp_meta.write_text(json.dumps(meta, indent=2) + "\n")
    os.replace(tmp_meta, meta_path)
    return Mpc(lib, header, crate)
